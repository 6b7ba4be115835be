"""tactbench.runner.analysis.answering: looks replayed from rows, and when they stop."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.errors import InputError
from tactbench.runner.analysis.answering import replay, schedule
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
    with pytest.raises(InputError, match="max-runs"):
        schedule(3, 5)


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


def test_no_primary_is_a_clear_error():
    with pytest.raises(InputError, match="--primary"):
        replay(_rows(range(5), 0.1), seed_order=list(range(5)), looks=[5], primary=[])


def test_runs_stored_beyond_the_last_look_are_said_beside_the_looks():
    """A report whose folder holds more runs than its looks used (a batch cut short, or
    runs of an earlier stopping rule) says so: its tables use every run, its verdicts the
    looks' runs."""
    from tactbench.runner.presentation.tables import looks_markdown
    from tactbench.runner.presentation.writers import make_report

    rows = _rows(range(8), 0.2)
    sequential = {"seed_order": list(range(20)), "looks": schedule(20, 5), "budget": None}
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
