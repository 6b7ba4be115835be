"""tactbench.runner.analysis.answering: looks replayed from rows, and when they stop."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tactbench.errors import InputError
from tactbench.runner.analysis.answering import replay
from tactbench.runner.execution.scene import Design, Scene, design_of, schedule
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

PRIMARY = ["encoder=raw..encoder=farneback"]


def _row(encoder, seed, truth, predicted):
    return prediction_row(encoder, seed, truth, predicted, split="paper")


def _rows(seeds, gain, n=400, rng_seed=0):
    """Two encoders per seed: raw right on ~70 % of n recordings, farneback on ~70 % +
    ``gain`` (each run draws its own errors)."""
    rng = np.random.default_rng(rng_seed)
    truth = [i % 2 for i in range(n)]
    rows = []
    for seed in seeds:
        for enc, acc in (("raw", 0.7), ("farneback", 0.7 + gain)):
            right = rng.random(n) < acc
            rows.append(_row(enc, seed, truth, [t if ok else 1 - t
                                                for t, ok in zip(truth, right)]))
    return rows


def test_schedule_starts_at_five_runs_and_ends_at_the_maximum():
    assert schedule(20, 5) == [5, 10, 15, 20]
    assert schedule(12, 5) == [5, 10, 12]
    with pytest.raises(InputError, match="max-runs"):  # the scene refuses it, once
        Scene(until="answered", max_runs=3)


def test_a_scene_is_resolved_once_into_its_design():
    """The primary questions, the seed order, the looks and the budget are decided in
    one place; a folder's stored scene gives the same design, no Scene built again."""
    scene = Scene(seeds=[3, 0], until="answered", max_runs=12, look_every=4, budget="1h30m")
    d = scene.design
    assert d is scene.design  # computed once
    assert d.seed_order == (3, 0, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13)
    assert d.looks == (5, 9, 12) and d.max_runs == 12
    assert d.primary == ("encoder=raw..encoder=farneback",)
    assert d.budget == "1h30m" and d.budget_seconds == 5400
    assert design_of(dataclasses.asdict(scene)) == d
    old = {k: v for k, v in dataclasses.asdict(scene).items() if k != "look_every"}
    assert design_of(old).looks == (5, 10, 12)  # a field older rows lack: its default
    assert design_of({}).primary == () and design_of({}).looks == ()  # rows of no scene
    plain = Scene(seeds=[2, 1], encoders=["raw"])
    assert plain.design.looks == () and plain.design.seed_order == (2, 1)
    assert plain.design.primary == () and plain.design.budget_seconds is None


@pytest.mark.parametrize("stored, says", [
    ({"seeds": []}, "scene field 'seeds' is empty"),
    ({"until": "answered", "max_runs": 10 ** 9}, "'max_runs' must be from 5 (the first look) to 1000"),
    ({"until": "answered", "budget": "1h30"}, "bad duration '1h30'"),
    ({"look_every": 0, "until": "answered"}, "'look_every' must be ≥ 1"),
    ({"primary": [3]}, "'primary' entry 1 must be text"),
    ([1], "must be a table"),
])
def test_a_damaged_stored_scene_is_one_line_not_a_traceback_or_a_hang(stored, says):
    """A row's stored scene is read back: the fields its design needs are checked as a
    scene checks them (a huge max_runs would otherwise expand a billion seeds)."""
    with pytest.raises(InputError, match="the rows' stored scene") as err:
        design_of(stored)
    assert says in str(err.value)


def test_a_look_goes_on_from_the_earlier_looks_without_computing_them_again(monkeypatch):
    """Resumed from an earlier history, replay computes only the new look's comparisons:
    the work of a look does not grow with the looks before it; the result is the same."""
    from tactbench.runner.analysis import answering

    rows = _rows(range(10), 0.03)  # open at both looks (a null would stop futile at 5)
    looks = schedule(20, 5)
    first = replay(rows[:10], seed_order=list(range(20)), looks=looks, primary=PRIMARY)
    calls = []
    real = answering.comparisons
    monkeypatch.setattr(answering, "comparisons",
                        lambda subset, **kw: calls.append(len(subset)) or real(subset, **kw))
    again = replay(rows, seed_order=list(range(20)), looks=looks, primary=PRIMARY,
                   resume=first)
    whole = replay(rows, seed_order=list(range(20)), looks=looks, primary=PRIMARY)
    assert calls[:1] == [20] and len(calls) == 1 + 2  # resumed: look 2 only; whole: 1, 2
    assert again.as_dict() == whole.as_dict() and len(first.seen) == 1


def test_a_clear_gain_is_answered_at_the_first_look():
    looks = schedule(20, 5)
    h = replay(_rows(range(5), 0.2), seed_order=list(range(20)), looks=looks,
               primary=PRIMARY)
    assert h.answered and len(h.seen) == 1
    [(name, look)] = h.seen[0].items()
    assert name.startswith("raw → farneback") and look.decision == "B better"
    assert h.as_dict()["decisions"] == {name: "B better"}


def test_looks_wait_for_their_runs_and_say_why_they_stopped():
    looks = schedule(20, 5)
    h = replay(_rows(range(7), 0.0), seed_order=list(range(20)), looks=looks,
               primary=PRIMARY)
    assert len(h.seen) == 1  # the second look (10 runs) has only 7
    assert not h.answered or h.state.closed  # futile at most, never a verdict
    assert all(lk.decision not in ("A better", "B better") for lk in h.seen[0].values())
    assert "of 20 runs" in h.stopped_because() or h.answered


def test_without_a_primary_question_there_is_no_look():
    h = replay(_rows(range(5), 0.1), seed_order=list(range(5)), looks=[5], primary=[])
    assert h.seen == [] and not h.answered
    with pytest.raises(InputError, match="--primary"):  # the scene refuses --until alone
        Scene(encoders=["raw"], until="answered")


def test_runs_stored_beyond_the_last_look_are_said_beside_the_looks():
    """A report whose folder holds more runs than its looks used (a batch cut short, or
    runs of an earlier stopping rule) says so: its tables use every run, its verdicts the
    looks' runs."""
    from tactbench.runner.presentation.tables import looks_markdown
    from tactbench.runner.orchestrate import make_report

    rows = _rows(range(8), 0.2)
    sequential = Design(primary=tuple(PRIMARY), seed_order=tuple(range(20)),
                        looks=tuple(schedule(20, 5)))
    report = make_report(rows, primary=PRIMARY, sequential=sequential)
    assert report.looks["runs_stored"] == 8 and report.looks["looks"][-1]["runs"] == 5
    text = looks_markdown(report.looks)
    assert "8 runs are stored" in text and "use the first 5" in text
    exact = make_report(_rows(range(5), 0.2), primary=PRIMARY, sequential=sequential)
    assert "runs are stored" not in looks_markdown(exact.looks)


def test_questions_no_run_count_can_decide_stop_at_the_first_look_unanswered():
    """Runs of one data set whose test set is as large as the training set (ratio 1):
    at 5 runs and no difference, no number of runs up to 10 can decide the question, so
    the first look stops it (futile, no α spent) and the run says it stopped unanswered,
    not that every question is answered."""
    rng = np.random.default_rng(4)
    truth = [i % 2 for i in range(200)]
    rows = []
    for seed in range(5):
        for enc in ("raw", "farneback"):
            right = rng.random(200) < 0.7
            rows.append(prediction_row(enc, seed, truth, [t if ok else 1 - t for t, ok in
                                                          zip(truth, right)],
                                       split="paper", n_train=200))
    h = replay(rows, seed_order=list(range(10)), looks=schedule(10, 5), primary=PRIMARY)
    [look] = h.seen[0].values()
    assert look.decision == "futile" and "no number of runs up to 10" in look.why
    assert h.answered  # the run stops here
    assert "stopped unanswered" in h.stopped_because()
    assert "every primary question is answered" not in h.stopped_because()


def test_a_look_applies_the_fixed_designs_minimum_of_discordant_recordings():
    """farneback right where raw is wrong on 1–3 of the same 3 recordings in every run
    (the CySkin case: "equivalent" or "better" on 3 discordant recordings): no look
    decides it, as no fixed design would."""
    from tactbench.runner.analysis.comparisons import comparisons

    rng = np.random.default_rng(2)
    truth = [i % 2 for i in range(200)]
    rows = []
    for seed in range(10):
        wrong = set(rng.choice(3, rng.integers(1, 4), replace=False).tolist())
        rows.append(_row("raw", seed, truth, [1 - t if i in wrong else t
                                              for i, t in enumerate(truth)]))
        rows.append(_row("farneback", seed, truth, truth))
    [fixed] = comparisons(rows, primary=PRIMARY)
    assert fixed.discordant_recordings == 3 and fixed.verdict == "unresolved"
    h = replay(rows, seed_order=list(range(10)), looks=[5, 10], primary=PRIMARY,
               margin=2.0)
    decisions = [lk.decision for seen in h.seen for lk in seen.values()]
    assert decisions[-1] == "futile" and not set(decisions) & {"B better", "equivalent"}
    [last] = h.seen[-1].values()  # its boundary crossed at 10 runs: no verdict below 10
    assert last.t > last.boundary and "disagree on 3 distinct" in last.why
