"""tactbench plan's forecast of a primary family (issue 48): the family the run makes,
each comparison at the family's level, the pilot's spread as the pilot gives it, and
the sequential outcomes named apart."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactbench.runner.execution.planning import Cell
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

PRIMARY = ["encoder=raw..encoder=frame-diff"]
CLASSIFIERS = ("logreg", "knn", "svc")


def _rows(seeds=range(3), n=60):
    rng = np.random.default_rng(0)
    truth = [i % 2 for i in range(n)]
    rows = []
    for seed in seeds:
        for clf in CLASSIFIERS:
            for enc, acc in (("raw", 0.7), ("frame-diff", 0.8)):
                right = rng.random(n) < acc
                rows.append(dict(prediction_row(enc, seed, truth, [
                    t if ok else 1 - t for t, ok in zip(truth, right)], classifier=clf),
                    key=f"{enc}-{clf}-{seed}"))
    return rows


def test_the_plan_forecasts_the_family_the_run_makes():
    """A question over three classifiers is three primary comparisons in the run (Holm
    over three) and three in the plan, named alike, by the one function."""
    from tactbench.runner.analysis.answering import comparison_name
    from tactbench.runner.analysis.comparisons import comparisons
    from tactbench.runner.analysis.forecast import _family

    cells = [Cell(enc, clf, 5, 0, f"{enc}{clf}") for clf in CLASSIFIERS
             for enc in ("raw", "frame-diff")]
    planned = _family(cells, PRIMARY, [])
    run = [c for c in comparisons(_rows(), primary=PRIMARY) if c.family == "primary"]
    assert [name for name, _ in planned] == [comparison_name(c) for c in run]
    assert len(planned) == 3 and {c.family_size for c in run} == {3}
    assert all(found is None for _, found in planned)  # no pilot
    with_pilot = _family(cells, PRIMARY, _rows())
    assert [found.runs for _, found in with_pilot] == [3, 3, 3]


def test_a_pilot_spread_is_given_as_the_pilot_gives_it_and_a_raise_is_named():
    from tactbench.runner.analysis.comparisons import comparisons
    from tactbench.runner.analysis.forecast import _spread

    [c] = [c for c in comparisons(_rows(), primary=PRIMARY) if c.family == "primary"][:1]
    sd = float(np.std(list(c.per_run.values()), ddof=1))
    got, high, _, said = _spread(c, 60, 0.05, 0.25)
    assert f"spread {100 * sd:.2f} points" in said
    flat = type(c)(**{**c.__dict__, "per_run": {"0": 0.10, "1": 0.1001, "2": 0.0999}})
    got, high, _, said = _spread(flat, 60, 0.05, 0.25)
    assert high is None and got > 0.01  # raised to the test sampling of its disagreement
    assert "spread 0.01 points" in said and "raised to the test sampling" in said
    assert "above the pilot's own 95 % upper limit" in said


def test_the_sequential_forecast_names_its_outcomes_apart():
    from tactbench.runner.analysis.sequential import procedure

    for effect in (0.0, 0.03):
        p = procedure(effect, 0.03, 0.8, [5, 10], alpha=0.05 / 3, paths=2000)
        parts = p.power + p.wrong_side + p.equivalent + p.stopped_futile + p.undecided_at_max
        assert parts == pytest.approx(1.0)
        assert p.futile == pytest.approx(p.stopped_futile + p.undecided_at_max)
    assert procedure(0.0, 0.03, 0.8, [5, 10], alpha=0.05 / 3, paths=2000).stopped_futile > 0.5


def test_the_familys_chance_of_being_answered_is_the_product_of_its_members():
    from tactbench.runner.analysis.forecast import PrimaryForecast, family_answered

    def one(power, seq=None):
        return PrimaryForecast(name="q", runs=5, effect=5, sd=3, sd_source="", ratio=0.25,
                               power=power, detectable=1, floor=1, recordings=100,
                               recordings_for_effect=None, sequential=seq)

    assert family_answered([one(0.5), one(0.8)]) == pytest.approx(0.4)
    seq = {"power": 0.3, "wrong_side": 0.0, "equivalent": 0.2}
    assert family_answered([one(0.9, seq), one(0.5)]) == pytest.approx(0.25)
    assert family_answered([]) is None and math.isfinite(family_answered([one(0.0)]))


def test_plan_says_when_the_data_allow_fewer_distinct_splits_than_runs(tmp_path, monkeypatch):
    """Two simulated people, one left out per run: two distinct splits for six runs. The
    plan says so and forecasts the two the run will count."""
    import json

    from click.testing import CliRunner

    from tactbench.cli import cli

    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    args = ["plan", "--dataset", "synthetic-forearm:users=2,repetitions=1", "--encoder",
            "raw", "--encoder", "frame-diff", "--classifier", "logreg:max_iter=20", "-L",
            "3", "--pixel-mm", "10", "--threads", "1", "--primary",
            "encoder=raw..encoder=frame-diff", "--split", "users", "--seed", "0-5",
            "--out", str(tmp_path / "out")]
    res = CliRunner().invoke(cli, [*args, str(scene)], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "the data allow only 2 distinct splits for 6 runs" in res.output
    doc = json.loads(CliRunner().invoke(cli, [*args, "--json", str(scene)]).output)
    assert (doc["distinct_splits"], doc["runs_asked"]) == (2, 6)
    assert [p["runs"] for p in doc["primaries"]] == [2]
