"""tactbench.runner.analysis.report: a folder's rows analysed once, everything decided
there (the verdicts, the looks and whether they answered the run); presentation only
renders the analysis it is given."""

from __future__ import annotations

import copy

import numpy as np

from tactbench.runner.analysis.report import Analysis, analyse
from tactbench.runner.execution.scene import Design, schedule
from tactbench.runner.presentation.writers import render
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

PRIMARY = ["encoder=raw..encoder=farneback"]
DESIGN = Design(primary=tuple(PRIMARY), seed_order=tuple(range(20)),
                looks=tuple(schedule(20, 5)))


def _rows(seeds, gain, n=400):
    """raw right on ~70 % of n recordings, farneback on ~70 % + ``gain``."""
    rng = np.random.default_rng(0)
    truth = [i % 2 for i in range(n)]
    rows = []
    for seed in seeds:
        for enc, acc in (("raw", 0.7), ("farneback", 0.7 + gain)):
            right = rng.random(n) < acc
            rows.append(prediction_row(enc, seed, truth, [t if ok else 1 - t for t, ok
                                                          in zip(truth, right)], split="paper"))
    return rows


def test_the_stop_decision_is_the_analysis_own():
    """A clear gain is decided at the first look: the analysis says the run is answered
    (what run_until stops on) and its primary verdict is the looks'; no gain at all is
    futile, which closes the question too; a small one leaves it open, and the run goes
    on; a fixed design has no looks and is never 'answered'."""
    decided = analyse(_rows(range(5), 0.2), primary=PRIMARY, sequential=DESIGN)
    assert isinstance(decided, Analysis) and decided.looks["answered"] is True
    assert decided.answered and decided.history is not None
    (primary,) = [c for c in decided.comparisons if c.family == "primary"]
    assert primary.verdict == "B better" and primary.note.startswith("group-sequential")
    futile = analyse(_rows(range(5), 0.0), primary=PRIMARY, sequential=DESIGN)
    assert futile.answered and set(futile.looks["decisions"].values()) == {"futile"}
    open_question = analyse(_rows(range(5), 0.04), primary=PRIMARY, sequential=DESIGN)
    assert not open_question.answered and open_question.looks["answered"] is False
    fixed = analyse(_rows(range(5), 0.2), primary=PRIMARY)
    assert fixed.looks is None and fixed.history is None and not fixed.answered


def test_rendering_shows_the_analysis_and_decides_nothing():
    """render() keeps the analysis as it is given (the same verdicts, the same records)
    and results.json's numbers are the analysis's, field by field."""
    analysis = analyse(_rows(range(5), 0.2), primary=PRIMARY, sequential=DESIGN)
    before = copy.deepcopy(analysis)
    report = render(analysis, rendered="in a test")
    assert report.analysis is analysis and analysis == before
    assert report.comparisons is analysis.comparisons and report.looks is analysis.looks
    doc = report.document()
    assert doc["comparisons"] == [c.to_dict() for c in analysis.comparisons]
    assert doc["summary"] == analysis.summaries and doc["looks"] == analysis.looks
    assert doc["rendered"]["how"] == "in a test"
