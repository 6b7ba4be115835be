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
    assert [name for name, _, _ in planned] == [comparison_name(c) for c in run]
    assert len(planned) == 3 and {c.family_size for c in run} == {3}
    assert all(found is None for _, found, _ in planned)  # no pilot
    assert len({cell for _, _, pair in planned for cell in pair}) == 6  # no cell shared
    with_pilot = _family(cells, PRIMARY, _rows())
    assert [found.runs for _, found, _ in with_pilot] == [3, 3, 3]


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


def test_comparisons_sharing_a_baseline_are_drawn_correlated():
    """raw → frame-diff and raw → flow share raw's runs: their differences correlate by
    0.5 (equal cell spreads); a comparison with no cell in common is independent, and
    one against the other's B in the other role anticorrelates."""
    from tactbench.runner.analysis.family_paths import arm_correlation, draw_family

    corr = arm_correlation([("raw", "fd"), ("raw", "flow"), ("knn", "svc"), ("fd", "x")])
    assert corr[0][1] == 0.5 and corr[0][2] == 0.0 and corr[0][3] == -0.5
    d = draw_family([0.0, 0.0, 0.0, 0.0], [0.03] * 4, [0.25] * 4, corr, 20, paths=4000,
                    seed=1)
    own = d - d.mean(axis=2, keepdims=True)  # each path's shared part removed
    got = np.corrcoef(own[:, :, 0].T)
    assert np.allclose(got, corr, atol=4 / math.sqrt(4000))
    assert np.std(d[:, 0].mean(axis=1)) == pytest.approx(
        0.03 * math.sqrt(0.25 + 1 / 20), rel=0.05)


def _run_family(d, looks, margin):
    """The run's own looks (family_look) over one path's differences, name by name."""
    from tactbench.runner.analysis.sequential import FamilyState, family_look

    names = [f"c{i}" for i in range(d.shape[0])]
    state = FamilyState(0.05, names)
    for k, j in enumerate(looks):
        family_look(state, {n: d[i, :j] for i, n in enumerate(names)},
                    dict.fromkeys(names, 0.25), looks=looks[:k + 1], max_runs=looks[-1],
                    margin=margin)
        if len(state.closed) == len(names):
            break
    return [state.closed[n].decision if n in state.closed else "continue" for n in names]


def test_the_familys_forecast_follows_the_runs_looks_path_by_path():
    """The plan's vectorised family (Holm carried over the looks, α of a rejection passed
    on) ends every path exactly as the run's family_look does, recycled α included."""
    from tactbench.runner.analysis.family_paths import arm_correlation, draw_family, family_codes
    from tactbench.runner.analysis.sequential import A_BETTER, B_BETTER, OUTCOMES

    looks = [5, 10]
    corr = arm_correlation([("raw", "fd"), ("raw", "flow"), ("raw", "far")])
    d = draw_family([0.05, 0.03, 0.0], [0.03] * 3, [0.25] * 3, corr, 10, paths=80, seed=3)
    code, _ = family_codes(d, [0.25] * 3, looks, alpha=0.05, margin=0.02)
    plain = {"last look": "futile", "no variation": "futile"}
    want = [[plain.get(OUTCOMES[int(c)], OUTCOMES[int(c)]) for c in row] for row in code]
    got = [_run_family(d[p], looks, 0.02) for p in range(len(d))]
    assert got == want
    # the α passed on mattered: some path rejected two (the second at α/2 or more)
    assert max(sum(x in (B_BETTER, A_BETTER) for x in row) for row in got) >= 2


def test_the_fixed_familys_forecast_is_the_runs_verdicts():
    from tactbench.runner.analysis.family_paths import (arm_correlation, draw_family,
                                                        fixed_family_codes)
    from tactbench.runner.analysis.sequential import OUTCOMES
    from tactbench.runner.analysis.statistics import corrected_t, holm, tost_p, verdict

    corr = arm_correlation([("raw", "fd"), ("raw", "flow")])
    d = draw_family([0.06, 0.0], [0.03] * 2, [0.25] * 2, corr, 8, paths=60, seed=4)
    code = fixed_family_codes(d, [0.25] * 2, alpha=0.05, margin=0.02)
    for p in range(len(d)):
        t = [corrected_t(d[p, i], 0.25) for i in range(2)]
        p_holm = holm([float(x["p"]) for x in t])
        eq = holm([float(tost_p(d[p, i], 0.25, 0.02)) for i in range(2)])
        said = [verdict(float(x["low"]), float(x["high"]), float(ph), 8,
                        equivalence_p_adjusted=float(e))[0] for x, ph, e in zip(t, p_holm, eq)]
        assert [{"last look": "unresolved"}.get(OUTCOMES[int(c)], OUTCOMES[int(c)])
                for c in code[p]] == said


@pytest.mark.slow("the boundaries of three Holm levels at four looks take about 3 s")
def test_the_familys_forecast_agrees_with_the_benchmarks_simulation():
    """Each stored scene of benchmarks/statistics_checks.py --part family (the run's own
    looks path by path over drawn cells) against the plan's forecast, within four
    standard errors of the two simulations' difference."""
    import json
    from pathlib import Path

    from tactbench.runner.analysis.family_paths import family_forecast

    doc = json.loads((Path(__file__).parents[3] / "docs" / "benchmarks"
                      / "statistics-checks.json").read_text())["family"]
    for s in doc["results"]:
        m = len(s["pairs"])
        f = family_forecast([e / 100 for e in s["effects_points"]], [s["sd_points"] / 100] * m,
                            [s["ratio"]] * m, [tuple(x) for x in s["pairs"]], runs=s["runs"],
                            looks=s["looks"], alpha=s["alpha"],
                            margin=None if s["margin_points"] is None
                            else s["margin_points"] / 100)
        bench = s["answered"]["rate"]
        p = (bench + f.answered) / 2
        se = math.sqrt(p * (1 - p) * (1 / doc["paths"] + 1 / f.paths))
        assert abs(f.answered - bench) <= 4 * se + 1e-9, (s["scene"], f.answered, bench)
        assert f.answered == pytest.approx(s["plan_answered"], abs=1e-4)  # deterministic


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


def test_the_part_more_runs_cannot_remove_is_the_docs_sd_root_ratio():
    """On the issue's CySkin numbers (pilot sd 3.40 points, 165 test and 208 training
    recordings of 373): the corrected standard error sd·√(1/J + ratio) tends to
    sd·√(165/208) = 3.03 points — what docs/statistics.md defines and the floor rests
    on — not the issue's sd·√(1 − 165/373) = 2.54; plan says it with its formula."""
    from scipy import stats

    from tactbench.runner.analysis.forecast import PrimaryForecast, _primary, persistent_text
    from tactbench.runner.analysis.power import effect_floor, persistent_sd, se_factor

    ratio = 165 / 208
    assert persistent_sd(0.034, ratio) == pytest.approx(0.03028, abs=1e-5)
    assert 0.034 * se_factor(10 ** 6, ratio) == pytest.approx(persistent_sd(0.034, ratio),
                                                             rel=1e-5)
    assert abs(persistent_sd(0.034, ratio) - 0.034 * math.sqrt(1 - 165 / 373)) > 0.004
    z = stats.norm.ppf(1 - 0.05 / 6) + stats.norm.ppf(0.8)
    assert effect_floor(0.034, ratio, alpha=0.05 / 3) == pytest.approx(
        z * persistent_sd(0.034, ratio))
    f = PrimaryForecast(name="q", runs=5, effect=5, sd=3.40, sd_source="", ratio=ratio,
                        power=0.5, detectable=1, floor=1, recordings=373,
                        recordings_for_effect=None, persistent=100 * persistent_sd(0.034, ratio))
    assert "sd·√(n_test/n_train) = 3.40·√(165/208) = 3.03 points" in persistent_text(f, 165, 208)
    got = _primary("q", None, 5, 0.05, ratio, 165, 0.05 / 3, 373, n_train=208)
    assert got.persistent == pytest.approx(got.sd * math.sqrt(ratio))
    assert got.floor == pytest.approx(z * got.persistent)
    assert f"= {got.persistent:.2f} points" in got.persistent_said
