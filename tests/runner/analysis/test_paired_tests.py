"""Paired tests are a seam: a registered component (``--paired-test``), the corrected t
the default and every stored report's; each test declares the designs it is valid for
and is refused for others in one line; the built-in Wilcoxon signed-rank agrees with
scipy and its interval inverts the test; a plugin's test is chosen by name."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from tactbench.data.splits import DESIGN_FIELD
from tactbench.errors import InputError, TactbenchError
from tactbench.runner.analysis.comparisons import Comparison, comparisons
from tactbench.runner.analysis.paired_builtins import (WilcoxonSignedRank,
                                                      hodges_lehmann_interval, signed_rank_cdf)
from tactbench.runner.analysis.paired_tests import DEFAULT_CHOICE, choose_paired_test
from tactbench.runner.execution.scene import Design
from tactbench.runner.presentation.tables import comparison_header, comparisons_text
from tactbench.runner.orchestrate import make_report
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

PRIMARY = ["encoder=raw..encoder=farneback"]
N, SEEDS = 200, range(8)


def _rows(**fields):
    """Two encoders × 8 seeds over one test set of N recordings, each row with
    ``fields``; and the per-run differences farneback − raw."""
    rng = np.random.default_rng(3)
    truth = [i % 2 for i in range(N)]
    rows, acc = [], {}
    for seed in SEEDS:
        for enc, p in (("raw", 0.7), ("farneback", 0.78)):
            right = rng.random(N) < p
            rows.append(prediction_row(enc, seed, truth,
                                       [t if ok else 1 - t for t, ok in zip(truth, right)],
                                       split="mine", **fields))
            acc[enc, seed] = float(np.mean(right))
    return rows, np.array([acc["farneback", s] - acc["raw", s] for s in SEEDS])


def test_the_signed_rank_distribution_and_interval_invert_scipys_exact_test():
    for n in (6, 9, 12):  # P(W+ ≤ w) against scipy's exact null distribution
        w = np.arange(n * (n + 1) // 2 + 1)
        d = np.arange(1, n + 1, dtype=float)  # W+ of d − shift sweeps every value
        assert signed_rank_cdf(n)[0] == pytest.approx(2.0 ** -n)
        assert signed_rank_cdf(n)[-1] == pytest.approx(1.0)
        assert len(w) == len(signed_rank_cdf(n))
        assert stats.wilcoxon(d, method="exact").pvalue == pytest.approx(
            min(1.0, 2 * signed_rank_cdf(n)[0]))
    d = np.array([0.031, -0.012, 0.054, 0.022, 0.047, 0.008, 0.061, 0.019, -0.004, 0.038])
    low, high = hodges_lehmann_interval(d)
    inside = [low + 1e-6, (low + high) / 2, high - 1e-6]
    outside = [low - 1e-6, high + 1e-6]
    assert all(stats.wilcoxon(d - m, method="exact").pvalue >= 0.05 for m in inside)
    assert all(stats.wilcoxon(d - m, method="exact").pvalue < 0.05 for m in outside)
    assert hodges_lehmann_interval(d[:5]) == (-1.0, 1.0)  # 5 runs: no 95 % interval


def test_wilcoxon_on_a_fixed_split_is_scipys_p_with_its_interval_and_recorded():
    rows, d = _rows(**{DESIGN_FIELD: "fixed"})
    wilcoxon = choose_paired_test("wilcoxon")
    (c,) = comparisons(rows, primary=PRIMARY, paired_test=wilcoxon)
    assert c.p == pytest.approx(stats.wilcoxon(d).pvalue)
    assert (c.low, c.high) == pytest.approx(hodges_lehmann_interval(d))
    assert c.t_p == pytest.approx(stats.ttest_1samp(d, 0).pvalue)  # the t, for reference
    assert c.paired_test == "wilcoxon" and c.method.startswith("Wilcoxon signed-rank test")
    stored = c.to_dict()
    assert stored["paired_test"] == "wilcoxon" and Comparison.from_dict(stored) == c
    assert comparison_header([c])[7] == "p (wilcoxon)"
    assert "`wilcoxon`" in comparisons_text([c]) and "the paired test's" in comparisons_text([c])
    (t,) = comparisons(rows, primary=PRIMARY)  # the default: as every stored report
    assert t.paired_test == "corrected-t" and "paired_test" not in t.to_dict()
    assert t.p == t.t_p and comparison_header([t])[7] == "p (paired t)"
    report = make_report(rows, primary=PRIMARY, paired_test=wilcoxon)
    assert report.statistics["paired_test"] == "wilcoxon"
    assert "paired_test" not in make_report(rows, primary=PRIMARY).statistics


@pytest.mark.parametrize("design", ["resampled", "kfold", None])
def test_wilcoxon_is_refused_for_runs_that_overlap(design):
    rows, _ = _rows(**({DESIGN_FIELD: design} if design else {}),
                    **({"folds": 4} if design == "kfold" else {}))
    with pytest.raises(InputError, match="paired test 'wilcoxon' is not valid for runs of a "
                                         f"{design or 'resampled'} design; it is valid for "
                                         "fixed, independent"):
        comparisons(rows, primary=PRIMARY, paired_test=choose_paired_test("wilcoxon"))


def test_the_looks_of_until_need_a_test_valid_for_them():
    rows, _ = _rows(**{DESIGN_FIELD: "fixed"})
    design = Design(primary=tuple(PRIMARY), seed_order=tuple(SEEDS), looks=(5, 8))
    with pytest.raises(InputError, match="not valid for the looks of --until"):
        make_report(rows, primary=PRIMARY, sequential=design,
                    paired_test=choose_paired_test("wilcoxon"))
    assert make_report(rows, primary=PRIMARY, sequential=design,
                       paired_test=DEFAULT_CHOICE).looks is not None


def test_a_run_refuses_a_paired_test_before_any_training(tiny_scene, cache):
    from tactbench.runner import run

    scene = tiny_scene(paired_test="wilcoxon")  # a paper split: resampled
    with pytest.raises(InputError, match="'wilcoxon' is not valid for runs of a resampled"):
        run(scene, cache=cache, progress=False, plots=False)
    assert not [p for p in cache.root.iterdir() if p.is_dir()]  # nothing encoded
    assert not list((Path(scene.out) / "cells").glob("*.json"))  # nothing trained


def test_plan_refuses_what_the_run_would_refuse(tiny_scene):
    from tactbench.runner import forecast

    with pytest.raises(InputError, match="'wilcoxon' is not valid for runs of a resampled"):
        forecast(tiny_scene(paired_test="wilcoxon"))


def test_an_unknown_paired_test_is_one_line_naming_the_known_ones():
    with pytest.raises(TactbenchError, match="unknown paired-test 'wilcox'; did you mean "
                                         "'wilcoxon'"):
        choose_paired_test("wilcox")
    assert isinstance(choose_paired_test("wilcoxon").test, WilcoxonSignedRank)


SIGN_TEST = '''
import numpy as np
from scipy import stats
from tactbench import hookimpl


class SignTest:
    label = "sign test"
    designs = {"resampled", "kfold", "fixed", "independent"}

    def test(self, d, *, ratio, confidence):
        d = np.asarray(d)
        n = int(np.sum(d != 0))
        p = stats.binomtest(int(np.sum(d > 0)), n).pvalue if n else 1.0
        return {"low": float(d.min()), "high": float(d.max()), "p": float(p), "df": None}


@hookimpl
def register_paired_tests(register):
    register("sign", "sign_paired:SignTest", summary="the sign test over runs")
'''


def test_a_plugins_paired_test_is_chosen_by_name_and_named_in_the_report(plugin_dist,
                                                                          tmp_path):
    from tactbench.plugins import load_registry
    from tactbench.runner.presentation.writers import write_report

    plugin_dist("tactbench-sign", "sign_paired", SIGN_TEST)
    registry = load_registry()
    assert "sign" in registry.names("paired-test")
    rows, d = _rows()  # resampled: the sign test declares it
    report = make_report(rows, primary=PRIMARY, paired_test=choose_paired_test("sign", registry))
    (c,) = report.comparisons
    assert c.p == pytest.approx(stats.binomtest(int(np.sum(d > 0)), len(d)).pvalue)
    assert c.method.startswith("sign test over runs (resampled design)")
    write_report(tmp_path / "out", report, plots=False)
    text = (tmp_path / "out" / "report.md").read_text()
    assert "p (sign)" in text and "paired test `sign` (--paired-test)" in text
    with pytest.raises(InputError, match="'sign' is not valid for the looks of --until"):
        make_report(rows, primary=PRIMARY, paired_test=choose_paired_test("sign", registry),
                    sequential=Design(primary=tuple(PRIMARY), seed_order=tuple(SEEDS),
                                      looks=(5, 8)))


@pytest.mark.slow("trains a tiny grid (2 encoders × 3 seeds of logreg) before re-rendering it")
def test_tactbench_report_renders_a_run_again_with_a_plugins_paired_test(plugin_dist,
                                                                         tiny_scene, cache):
    """The plugin is one module and its entry point (no file of tactbench): `tactbench
    report --paired-test sign` re-renders a finished run with it, recorded and named."""
    import json
    import subprocess
    import sys

    from tactbench.runner import run

    plugin_dist("tactbench-sign", "sign_paired", SIGN_TEST)
    scene = tiny_scene(classifiers=["logreg"], seeds=[0, 1, 2])
    run(scene, cache=cache, progress=False, plots=False)
    done = subprocess.run([sys.executable, "-m", "tactbench", "report", scene.out,
                           "--paired-test", "sign", "--no-plots"], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    doc = json.loads((Path(scene.out) / "results.json").read_text())
    assert doc["statistics"]["paired_test"] == "sign"
    assert {c["paired_test"] for c in doc["comparisons"]} == {"sign"}
    assert "paired test `sign` (--paired-test)" in (Path(scene.out) / "report.md").read_text()
