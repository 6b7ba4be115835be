"""Runs that repeat a split already drawn are not new evidence (issue 48): a comparison
counts distinct splits, averages the runs of each, and says so; the report gives the
test-set sizes of all seeds as a range."""

from __future__ import annotations

import numpy as np

from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

PRIMARY = ["encoder=raw..encoder=farneback"]


def _rows(seeds=range(6), sessions=4, per=30):
    """Leave one of ``sessions`` sessions out: seed s tests session s % sessions."""
    rng = np.random.default_rng(1)
    rows = []
    for seed in seeds:
        session = seed % sessions
        indices = list(range(session * per, (session + 1) * per))
        truth = [i % 2 for i in indices]
        for enc, acc in (("raw", 0.6), ("farneback", 0.8)):
            right = rng.random(per) < acc
            rows.append(prediction_row(enc, seed, truth, [t if ok else 1 - t for t, ok in
                                                          zip(truth, right)],
                                       indices=indices, split="group:session"))
            rows[-1]["test_predictions"]["groups"] = [str(session)] * per
    return rows


def test_repeated_splits_count_once_and_are_named():
    from tactbench.runner.analysis.comparisons import comparisons

    [c] = comparisons(_rows())
    assert c.runs == 4 and sorted(c.per_run) == ["0", "1", "2", "3"]
    assert "4 distinct splits of 6 runs: runs 4, 5 repeat the splits of runs 0, 1" in c.method
    [c5] = comparisons(_rows(range(4)))
    assert c5.runs == 4 and "distinct" not in c5.method  # no repeat: nothing said


def test_a_look_is_made_where_its_seeds_repeat_splits():
    from tactbench.runner.analysis.answering import replay

    h = replay(_rows(range(5)), seed_order=list(range(10)), looks=[5, 10],
               primary=PRIMARY)
    assert len(h.seen) == 1  # five seeds stored: the first look is made, on 4 splits
    [look] = h.seen[0].values()
    assert look.runs == 4 and look.decision != "continue"  # no more runs can add evidence
    if look.decision == "futile":
        assert "only 4 distinct split(s) for 5 runs" in look.why


def test_the_report_gives_every_seeds_test_set_size():
    from tactbench.runner.presentation.writers import test_set_sizes

    rows = _rows(range(3))
    assert test_set_sizes(rows) == "30"
    rows[0]["n_test"] = 19
    rows[2]["n_test"] = 157
    assert test_set_sizes(rows) == "19–157"
    assert test_set_sizes([]) == ""
