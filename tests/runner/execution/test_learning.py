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


# ------------------------------------------------------------------ a cell's runs together


def test_the_pooled_p_is_the_exact_tail_of_the_runs_guessing():
    from scipy import stats

    from tactbench.runner.execution.learning import pooled_p

    # runs guessing alike: one binomial over all their recordings
    assert pooled_p([(150, 35, 0.2), (150, 30, 0.2)]) == pytest.approx(
        stats.binom.sf(64, 300, 0.2))
    # runs guessing at different levels: the convolution, against a simulation
    runs = [(19, 12, 0.53), (157, 40, 0.2), (60, 20, 0.25)]
    rng = np.random.default_rng(0)
    draws = sum(rng.binomial(n, c, 200_000) for n, _, c in runs)
    p = pooled_p(runs)
    assert p == pytest.approx(np.mean(draws >= 72), abs=4 * np.sqrt(p * (1 - p) / 200_000))
    assert pooled_p([]) == 1.0


def _evidence_rows(accuracies, n=150, k=5, seed=0, **extra):
    """One cell's rows, one a run, of ``n`` balanced test recordings over ``k`` classes
    with ``round(a·n)`` right for each accuracy ``a``."""
    rng = np.random.default_rng(seed)
    truth = np.arange(n) % k
    rows = []
    for s, a in enumerate(accuracies):
        pred = (truth + 1) % k
        right = rng.choice(n, int(round(a * n)), replace=False)
        pred[right] = truth[right]
        rows.append(prediction_row("raw", s, truth.tolist(), pred.tolist(),
                                   **{"classes": list("abcde"[:k]), **extra}))
    return rows


def test_one_run_below_noise_does_not_mark_a_cell_that_learned_over_its_runs():
    from tactbench.runner.execution.learning import cell_learning, within_noise

    # run 2 alone (24 % against 20 %) cannot be told from guessing; all five together can
    assert within_noise(0.24, 0.2, 150) and not within_noise(0.30, 0.2, 150)
    judged = cell_learning(_evidence_rows([0.30, 0.34, 0.24, 0.31, 0.29]))
    assert judged.learned and judged.status == LEARNED and judged.p < 1e-6
    assert judged.seeds == (0, 1, 2, 3, 4) and judged.test_n == 750


def test_a_cell_at_chance_over_its_runs_is_not_learned_and_why():
    from tactbench.runner.execution.learning import (NOT_ABOVE_CHANCE, cell_learning,
                                                     describe_cell)

    rows = _evidence_rows([0.21, 0.19, 0.22, 0.20])
    judged = cell_learning(rows)  # rows made before they recorded learning: judged now
    assert judged.status == NOT_ABOVE_CHANCE and judged.train_kappa is None
    assert describe_cell("raw", judged).startswith("raw not above chance over runs 0, 1, 2, 3")
    fitted = cell_learning(_evidence_rows([0.21, 0.19, 0.22, 0.20], train_accuracy=0.95,
                                          train_chance=0.2))
    assert fitted.status == DID_NOT_TRANSFER  # fitted its training windows only
    assert "training windows 95 %" in describe_cell("raw", fitted)


def test_training_near_chance_is_not_learned_whatever_the_test_says():
    from tactbench.runner.execution.learning import TRAIN_KAPPA_MIN, cell_learning

    # the signed grid's CNN: training 14.1 % where guessing gives 6.8 % (κ 0.08)
    rows = _evidence_rows([0.30] * 3, train_accuracy=0.141, train_chance=0.068)
    judged = cell_learning(rows)
    assert judged.status == DID_NOT_LEARN and judged.p < 0.05
    assert judged.train_kappa == pytest.approx((0.141 - 0.068) / 0.932)
    assert judged.train_kappa < TRAIN_KAPPA_MIN
    ok = cell_learning(_evidence_rows([0.30] * 3, train_accuracy=0.2, train_chance=0.068))
    assert ok.learned  # κ 0.14


def test_error_rates_of_the_rule_within_monte_carlo_error():
    """A model 10 points above chance (per-run spread of its accuracy 2.3 points, twice
    what the issue's 12 % one-run flags imply) is marked in ≤ 5 % of 5-run cells at 150 test
    recordings; one at chance in ≥ 95 % (an exact test: at least 1 − 0.05). 300 draws:
    the bounds allow 3 Monte Carlo standard errors."""
    from tactbench.runner.execution.learning import pooled_p

    rng = np.random.default_rng(7)
    reps, n, chance = 300, 150, 0.2

    def marked(shift, spread):
        acc = np.clip(chance + shift + spread * rng.standard_normal((reps, 5)), 0, 1)
        right = rng.binomial(n, acc)
        return np.mean([pooled_p([(n, int(r), chance) for r in line]) > 0.05
                        for line in right])

    se = np.sqrt(0.05 * 0.95 / reps)
    assert marked(0.10, 0.023) <= 0.05 + 3 * se
    assert marked(0.0, 0.0) >= 0.95 - 3 * se


# ------------------------------------------------------------------ comparisons


def _rows(at_chance=(), seeds=range(6), n=40, train=None):
    """B (farneback) right everywhere but one recording, A (raw) wrong on ~12 more;
    ``at_chance``: (encoder, seed) whose model answers one class (50 %, what guessing
    gives); ``train``: encoder → the training accuracy its rows record (guessing 50 %;
    none recorded by default, as rows made before)."""
    truth = [0, 1] * (n // 2)
    rows = []
    for seed in seeds:
        wrong = {seed % n, (seed + 3) % n, *range(10, 19 + seed % 3)}
        for enc, pred in (("raw", [1 - t if i in wrong else t for i, t in enumerate(truth)]),
                          ("farneback", [1 - t if i == seed else t
                                         for i, t in enumerate(truth)])):
            if (enc, seed) in at_chance:
                pred = [0] * n
            extra = {}
            if train is not None:
                extra = {"train_accuracy": train.get(enc, 0.9), "train_chance": 0.5}
            rows.append(prediction_row(enc, seed, truth, pred, n_train=3 * n, **extra))
    return rows


def _all(enc, seeds=range(6)):
    return {(enc, s) for s in seeds}


def test_rows_made_before_the_fields_are_judged_when_read():
    from tactbench.runner.analysis.comparisons import comparisons

    [old] = comparisons(_rows())
    [new] = comparisons(_rows(train={}))
    assert old.verdict == new.verdict == "B better"
    junk = _rows()
    junk[0]["learning"] = "did not learn"  # one run's record: the runs together decide
    assert comparisons(junk)[0].verdict == "B better"
    [c] = comparisons(_rows(at_chance=_all("raw")))
    assert c.verdict == NOT_LEARNED
    assert "raw not above chance over runs 0, 1, 2, 3, 4, 5" in c.note


def test_one_run_at_chance_keeps_the_verdict_the_cells_runs_together_take_it():
    from tactbench.runner.analysis.comparisons import comparisons

    [c] = comparisons(_rows(at_chance={("raw", 3)}, train={}))
    assert c.verdict == "B better"
    [c] = comparisons(_rows(at_chance=_all("raw"), train={}))
    assert c.verdict == NOT_LEARNED
    assert "raw did not transfer over runs 0, 1, 2, 3, 4, 5" in c.note
    assert "farneback" not in c.note
    assert c.p_holm is not None and c.family_size == 1  # tested, in its family, undecided
    [c] = comparisons(_rows(train={"farneback": 0.52}))  # κ 0.04: training failed
    assert c.verdict == NOT_LEARNED and "farneback did not learn over runs" in c.note


def test_a_comparison_without_verdict_leaves_the_family_as_it_was():
    """Holm over the same p's: the other comparison's adjusted p and verdict are those
    it has when nothing is flagged."""
    from tactbench.runner.analysis.comparisons import comparisons

    rows = _rows() + [dict(r, encoder="flow", key=r["key"] + "f")
                      for r in _rows() if r["encoder"] == "farneback"]
    plain = {(c.a, c.b): c for c in comparisons(rows)}
    for r in rows:
        r.update(train_accuracy=0.5 if r["encoder"] == "flow" else 0.9, train_chance=0.5)
    flagged = {(c.a, c.b): c for c in comparisons(rows)}
    assert flagged[("raw", "farneback")].p_holm == plain[("raw", "farneback")].p_holm
    assert flagged[("raw", "farneback")].verdict == plain[("raw", "farneback")].verdict
    assert {c.verdict for k, c in flagged.items() if "flow" in k} == {NOT_LEARNED}
    assert {c.family_size for c in flagged.values()} == {len(plain)}


def test_a_look_closes_a_question_at_chance_without_passing_its_alpha():
    from tactbench.runner.analysis.answering import replay
    from tactbench.runner.execution.scene import Design
    from tactbench.runner.orchestrate import make_report

    rows = _rows(train={"raw": 0.5}, seeds=range(5))
    h = replay(rows, seed_order=list(range(5)), looks=[5],
               primary=["encoder=raw..encoder=farneback"])
    [(name, look)] = h.seen[0].items()
    assert look.decision == NOT_LEARNED and "raw did not learn over runs 0, 1" in look.why
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

    rows = _rows(at_chance=_all("raw"), train={})
    [c] = comparisons(rows, primary=["encoder=raw..encoder=farneback"])
    assert comparison_rows([c])[0][-2:] == ["-", NOT_LEARNED]  # no runs-for-power either
    assert "not learned — no verdict rests on a model at chance: raw did not transfer" in \
        answer_text(c)
    table = markdown_table(summarise(rows))
    assert table.count("†") == 1 + 2  # the raw cell's accuracy, the legend, its line
    assert "† raw / logreg L=5: did not transfer over runs 0, 1, 2, 3, 4, 5." in table
    assert "†" not in markdown_table(summarise(_rows(at_chance={("raw", 2)})))


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
        assert "constant did not learn over runs 0, 1, 2" in verdicts[pair].note
    text = (Path(scene.out) / "report.md").read_text()
    assert "† raw / constant L=3: did not learn over runs 0, 1, 2." in text
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
    from tactbench.runner.analysis.report import sequential_verdict

    [c] = comparisons(_rows(train={"farneback": 0.5}, seeds=range(5)),
                      primary=["encoder=raw..encoder=farneback"])
    name = comparison_name(c)
    looks = {"looks": [{"runs": 5, "comparisons": {name: {"decision": "B better"}}}],
             "decisions": {name: "B better"}}
    assert sequential_verdict(c, looks) == c  # the looks saw B better; the cell did not learn
    unflagged = dataclasses.replace(c, verdict="unresolved")
    assert sequential_verdict(unflagged, looks).verdict == "B better"
