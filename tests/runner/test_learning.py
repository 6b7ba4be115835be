"""A cell whose model did not learn or did not transfer is marked, and no verdict rests
on it: the rule (tactbench.runner.execution.learning), the rows a cell writes, the comparisons,
the looks and the tables."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from tactbench.runner.execution.learning import (
    DID_NOT_LEARN,
    DID_NOT_TRANSFER,
    LEARNED,
    chance_level,
    learning_status,
    within_noise,
)
from tactbench.runner.analysis.statistics import NOT_LEARNED
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ------------------------------------------------------------------ the rule


def test_chance_is_the_larger_of_one_in_k_and_the_majority_share():
    assert chance_level([0, 1, 2, 0], 4) == 0.5  # the majority class: half the labels
    assert chance_level([0, 1, 2, 3], 4) == 0.25
    assert chance_level([0, 0], 3) == 1.0  # a one-class test set: guessing is right
    assert chance_level([], 3) == 0.0


def test_within_noise_is_the_one_sided_exact_binomial_test():
    from scipy import stats

    # 5 recordings, 5 classes: 3 right has p = P(X ≥ 3) = 0.058 > 0.05, 4 right 0.007
    assert within_noise(0.6, 0.2, 5) and not within_noise(0.8, 0.2, 5)
    assert stats.binom.sf(2, 5, 0.2) > 0.05 > stats.binom.sf(3, 5, 0.2)
    assert within_noise(0.2, 0.2, 1000) and not within_noise(0.25, 0.2, 1000)
    assert within_noise(1.0, 1.0, 50)  # no accuracy beats a one-class test set
    assert within_noise(1.0, 0.5, 0)  # nothing tested: nothing shown


def test_only_a_test_accuracy_within_noise_marks_a_cell():
    common = dict(train_chance=0.2, train_n=100, test_chance=0.2, test_n=100)
    # low per-window training accuracy, but the test (a vote over windows) learned
    assert learning_status(train_accuracy=0.2, test_accuracy=0.6, **common) == LEARNED
    assert learning_status(train_accuracy=0.22, test_accuracy=0.21, **common) == DID_NOT_LEARN
    assert learning_status(train_accuracy=0.95, test_accuracy=0.21, **common) == \
        DID_NOT_TRANSFER


# ------------------------------------------------------------------ comparisons


def _rows(flag=None, seeds=range(6), n=40):
    """B (farneback) right everywhere but one recording, A (raw) wrong on ~12 more;
    ``flag``: (encoder, seed) → the learning status its row records."""
    truth = [0, 1] * (n // 2)
    rows = []
    for seed in seeds:
        wrong = {seed % n, (seed + 3) % n, *range(10, 19 + seed % 3)}
        for enc, pred in (("raw", [1 - t if i in wrong else t for i, t in enumerate(truth)]),
                          ("farneback", [1 - t if i == seed else t
                                         for i, t in enumerate(truth)])):
            extra = {}
            if flag is not None:
                extra = {"learning": flag.get((enc, seed), LEARNED), "train_accuracy": 0.5,
                         "chance_accuracy": 0.5}
            rows.append(prediction_row(enc, seed, truth, pred, n_train=3 * n, **extra))
    return rows


def test_rows_made_before_the_fields_keep_their_verdict():
    from tactbench.runner.analysis.comparisons import comparisons

    [old] = comparisons(_rows())
    [new] = comparisons(_rows(flag={}))
    assert old.verdict == new.verdict == "B better"
    junk = _rows()
    junk[0]["learning"] = "maybe"  # not a status: unknown, never "did not learn"
    assert comparisons(junk)[0].verdict == "B better"


def test_one_run_of_one_cell_at_chance_takes_the_verdict_and_the_note_says_why():
    from tactbench.runner.analysis.comparisons import comparisons

    [c] = comparisons(_rows(flag={("raw", 3): DID_NOT_LEARN}))
    assert c.verdict == NOT_LEARNED
    assert "raw did not learn in run 3" in c.note and "farneback" not in c.note
    assert c.p_holm is not None and c.family_size == 1  # tested, in its family, undecided
    [c] = comparisons(_rows(flag={("raw", 1): DID_NOT_TRANSFER,
                                  ("farneback", 2): DID_NOT_LEARN,
                                  ("farneback", 4): DID_NOT_LEARN}))
    assert "raw did not transfer in run 1" in c.note
    assert "farneback did not learn in runs 2, 4" in c.note


def test_a_comparison_without_verdict_leaves_the_family_as_it_was():
    """Holm over the same p's: the other comparison's adjusted p and verdict are those
    it has when nothing is flagged."""
    from tactbench.runner.analysis.comparisons import comparisons

    rows = _rows() + [dict(r, encoder="flow", key=r["key"] + "f")
                      for r in _rows() if r["encoder"] == "farneback"]
    plain = {(c.a, c.b): c for c in comparisons(rows)}
    for r in rows:
        r.update(learning=DID_NOT_LEARN if r["encoder"] == "flow" else LEARNED)
    flagged = {(c.a, c.b): c for c in comparisons(rows)}
    assert flagged[("raw", "farneback")].p_holm == plain[("raw", "farneback")].p_holm
    assert flagged[("raw", "farneback")].verdict == plain[("raw", "farneback")].verdict
    assert {c.verdict for k, c in flagged.items() if "flow" in k} == {NOT_LEARNED}
    assert {c.family_size for c in flagged.values()} == {len(plain)}


def test_a_look_closes_a_question_at_chance_without_passing_its_alpha():
    from tactbench.runner.analysis.answering import replay
    from tactbench.runner.execution.scene import Design
    from tactbench.runner.presentation.writers import make_report

    rows = _rows(flag={("raw", 0): DID_NOT_LEARN}, seeds=range(5))
    h = replay(rows, seed_order=list(range(5)), looks=[5],
               primary=["encoder=raw..encoder=farneback"])
    [(name, look)] = h.seen[0].items()
    assert look.decision == NOT_LEARNED and "raw did not learn in run 0" in look.why
    assert h.answered and "a model did not learn" in h.stopped_because()
    assert h.state.shares[name] == pytest.approx(0.05)  # kept, passed to no one
    report = make_report(rows, primary=["encoder=raw..encoder=farneback"],
                         sequential=Design(primary=("encoder=raw..encoder=farneback",),
                                           seed_order=tuple(range(5)), looks=(5,)))
    [c] = report.comparisons
    assert c.verdict == NOT_LEARNED and c.note.startswith("no verdict rests on a model")


def test_the_tables_mark_the_cells_and_answer_with_the_reason():
    from tactbench.runner.analysis.comparisons import comparisons
    from tactbench.runner.analysis.summaries import summarise
    from tactbench.runner.presentation.tables import answer_text, comparison_rows, markdown_table

    rows = _rows(flag={("raw", 2): DID_NOT_TRANSFER})
    [c] = comparisons(rows, primary=["encoder=raw..encoder=farneback"])
    assert comparison_rows([c])[0][-2:] == ["-", NOT_LEARNED]  # no runs-for-power either
    assert "not learned — no verdict rests on a model at chance: raw did not transfer" in \
        answer_text(c)
    table = markdown_table(summarise(rows))
    assert table.count("†") == 1 + 2  # the raw cell's accuracy, the legend, its line
    assert "† raw / logreg L=5: did not transfer in run 2." in table
    assert "†" not in markdown_table(summarise(_rows()))  # nothing flagged: no mark


# ------------------------------------------------------------------ cells that run


@pytest.fixture
def learnable(tmp_path) -> Path:
    """3 classes × 12 recordings of 8 frames × 5 taxels, 4 users, each class pressing its
    own taxel: a task logistic regression learns, tested on 12 recordings."""
    from tactbench.data.dataset import Dataset
    from tactbench.data.recording import Recording, Sample

    rng = np.random.default_rng(1)
    samples = []
    for i in range(36):
        label = i % 3
        values = rng.uniform(0.0, 0.1, (8, 5)).astype(np.float32)
        values[:, label] += 0.8
        samples.append(Sample(Recording(values, np.arange(8) * 0.1, np.arange(5)),
                              label=label, user=f"u{i % 4}", position="front",
                              repetition=i // 3, source="test"))
    path = tmp_path / "learnable"
    Dataset(name="learnable", samples=samples, classes=("a", "b", "c"), layout=None).save(path)
    return path


def test_a_classifier_that_answers_one_class_is_marked_and_given_no_verdict(
        tiny_scene, cache, fake_registry, learnable, capsys):
    from tactbench.runner import run
    from tactbench.runner.presentation.tables import print_table

    scene = tiny_scene(dataset=str(learnable), encoders=["raw"], test_per_class=4,
                       classifiers=["logreg:max_iter=50", "added-logreg:max_iter=50",
                                    "constant:max_iter=5"], seeds=[0, 1, 2])
    report = run(scene, registry=fake_registry, progress=False, cache=cache, plots=False)
    status = {(r["classifier"].split(":")[0], r["seed"]): r["learning"] for r in report.rows}
    assert {status[("constant", s)] for s in range(3)} == {DID_NOT_LEARN}
    assert {v for (clf, _), v in status.items() if clf != "constant"} == {LEARNED}
    for r in report.rows:
        assert 0 <= r["train_accuracy"] <= 1 and r["train_windows_scored"] > 0
        assert r["chance_accuracy"] == pytest.approx(1 / 3) and r["n_test"] == 12
    verdicts = {(c.a.split(":")[0], c.b.split(":")[0]): c for c in report.comparisons}
    normal = verdicts[("logreg", "added-logreg")]
    assert normal.verdict != NOT_LEARNED and "chance" not in normal.note
    for pair in (("logreg", "constant"), ("added-logreg", "constant")):
        assert verdicts[pair].verdict == NOT_LEARNED
        assert "constant did not learn in runs 0, 1, 2" in verdicts[pair].note
    text = (Path(scene.out) / "report.md").read_text()
    assert "† raw / constant L=3: did not learn in runs 0, 1, 2." in text
    assert "| not learned |" in text and "no verdict rests on a model at chance" in text
    header = (Path(scene.out) / "results.csv").read_text().splitlines()[0].split(",")
    assert {"train_accuracy", "chance_accuracy", "learning"} <= set(header)
    doc = json.loads((Path(scene.out) / "results.json").read_text())
    marked = [s for s in doc["summary"] if s.get("learning")]
    assert [s["classifier"] for s in marked] == ["constant:max_iter=5"]
    print_table(report.summaries)
    assert "† raw / constant L=3: did not learn" in capsys.readouterr().out


def test_folds_are_scored_together(tiny_scene, cache, fake_registry, learnable):
    """A two-fold split: the training windows of both folds scored, the test recordings
    of both judged together."""
    from tactbench.runner import run

    scene = tiny_scene(dataset=str(learnable), encoders=["raw"], split="parity",
                       classifiers=["constant:max_iter=5"], seeds=[0])
    [row] = run(scene, registry=fake_registry, progress=False, cache=cache, plots=False).rows
    assert row["folds"] == 2 and row["n_test"] == 36 and row["learning"] == DID_NOT_LEARN
    assert row["train_accuracy"] == pytest.approx(1 / 3, abs=0.05)


def test_a_stored_verdict_from_looks_is_not_replaced_for_a_flagged_comparison():
    from tactbench.runner.analysis.answering import comparison_name
    from tactbench.runner.analysis.comparisons import comparisons
    from tactbench.runner.presentation.writers import sequential_verdict

    [c] = comparisons(_rows(flag={("farneback", 0): DID_NOT_LEARN}, seeds=range(5)),
                      primary=["encoder=raw..encoder=farneback"])
    name = comparison_name(c)
    looks = {"looks": [{"runs": 5, "comparisons": {name: {"decision": "B better"}}}],
             "decisions": {name: "B better"}}
    assert sequential_verdict(c, looks) == c  # the looks saw B better; a run did not learn
    unflagged = dataclasses.replace(c, verdict="unresolved")
    assert sequential_verdict(unflagged, looks).verdict == "B better"
