"""The split's design picks the comparison's t: rows record it (``split_design``), a
plugin split declaring ``fixed`` gets the plain paired t, an undeclared one the corrected
t, old rows read as before; runs of ``sklearn:GroupKFold`` and of plugin splits end to end,
and a split that leaks a user fails its cell naming the rule."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from tactbench.data.splits import DESIGN_FIELD
from tactbench.errors import ContractError
from tactbench.runner import run
from tactbench.runner.analysis.comparisons import comparisons, plain_t
from tactbench.runner.execution.planning import plan
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

PRIMARY = ["encoder=raw..encoder=farneback"]
N, SEEDS = 200, range(6)


def _rows(**fields):
    """Two encoders × 6 seeds over one test set of N recordings (n_train 4 N), each row
    with ``fields`` (a design, folds ...); and each run's accuracies."""
    rng = np.random.default_rng(7)
    truth = [i % 2 for i in range(N)]
    rows, acc = [], {}
    for seed in SEEDS:
        for enc, p in (("raw", 0.7), ("farneback", 0.76)):
            right = rng.random(N) < p
            pred = [t if ok else 1 - t for t, ok in zip(truth, right)]
            rows.append(prediction_row(enc, seed, truth, pred, split="mine", **fields))
            acc[enc, seed] = float(np.mean(right))
    return rows, acc


def _runs(acc, enc):
    return np.array([acc[enc, s] for s in SEEDS])


def test_a_fixed_design_gets_the_plain_paired_t_and_an_undeclared_one_the_corrected():
    rows, acc = _rows(**{DESIGN_FIELD: "fixed"})
    (fixed,) = comparisons(rows, primary=PRIMARY)
    plain = stats.ttest_rel(_runs(acc, "farneback"), _runs(acc, "raw"))
    assert fixed.ratio == 0.0 and fixed.run_ratio == 0.0 and plain_t(fixed)
    assert fixed.method.startswith("paired t over runs of one fixed split")
    assert (fixed.low, fixed.high) == pytest.approx(plain.confidence_interval(0.95))
    assert fixed.t_p == pytest.approx(plain.pvalue)
    for undeclared in (_rows()[0], _rows(**{DESIGN_FIELD: "resampled"})[0]):
        (c,) = comparisons(undeclared, primary=PRIMARY)  # rows made before designs: as ever
        assert c.ratio == pytest.approx(1 / 4) and not plain_t(c)
        assert c.method == "corrected resampled t (Nadeau–Bengio)"
        assert c.high - c.low > fixed.high - fixed.low
    (ind,) = comparisons(_rows(**{DESIGN_FIELD: "independent"})[0], primary=PRIMARY)
    assert ind.ratio == 0.0 and plain_t(ind) and "independent" in ind.method


def test_rows_that_disagree_on_their_design_keep_the_correction():
    rows, _ = _rows(**{DESIGN_FIELD: "fixed"})
    del rows[0][DESIGN_FIELD]
    (c,) = comparisons(rows, primary=PRIMARY)
    assert c.ratio == pytest.approx(1 / 4) and not plain_t(c)


def _fold_rows(design, k=4):
    """Rows whose test recordings are dealt into ``k`` folds (recorded), with ``design``."""
    rows, _ = _rows(folds=k, **{DESIGN_FIELD: design})
    for r in rows:
        r["test_predictions"]["folds"] = [i % k for i in range(N)]
    return rows


def test_a_kfold_design_gets_the_k_fold_correction_and_a_fixed_one_of_folds_the_plain_t():
    (c,) = comparisons(_fold_rows("kfold"), primary=PRIMARY)
    assert c.ratio == pytest.approx(1 / 3) and c.run_ratio == pytest.approx(4 / 3)
    assert c.method == "corrected repeated 4-fold t (Bouckaert–Frank) over 24 fold differences"
    (f,) = comparisons(_fold_rows("fixed"), primary=PRIMARY)  # folds every seed the same
    assert f.ratio == 0.0 and f.run_ratio == 0.0 and plain_t(f) and f.runs == len(SEEDS)


@pytest.fixture
def design_registry(monkeypatch):
    """Built-ins plus the split plugins of tests/runner/design_splits.py."""
    import sys

    from tactbench.plugins import collect_registry, make_plugin_manager

    sys.modules.pop("design_splits", None)
    import design_splits

    return collect_registry(make_plugin_manager(entry_points=False,
                                                extra=[("designs", design_splits)]))


def _stored(scene):
    return [json.loads(p.read_text()) for p in sorted((Path(scene.out) / "cells").glob("*.json"))]


def test_a_run_of_sklearn_group_kfold_tests_every_user_once_per_seed(tiny_scene, cache):
    pytest.importorskip("sklearn")
    scene = tiny_scene(split="sklearn:GroupKFold:n_splits=2", classifiers=["logreg"],
                       seeds=[0, 1, 2])
    report = run(scene, cache=cache, progress=False, plots=False)
    assert report.computed == 6 and not report.failed
    for row in _stored(scene):
        assert (row["split"], row[DESIGN_FIELD], row["folds"]) == \
            ("sklearn:GroupKFold:n_splits=2", "kfold", 2)
        tp = row["test_predictions"]
        assert sorted(set(tp["groups"])) == sorted(row["test_users"])  # every user, once
        assert len(tp["indices"]) == len(set(tp["indices"])) == row["n_test"]
        by_fold = {f: {g for g, f2 in zip(tp["groups"], tp["folds"]) if f2 == f}
                   for f in set(tp["folds"])}
        assert len(by_fold) == 2 and not by_fold[0] & by_fold[1]  # a user in one fold
    (c,) = report.comparisons
    assert c.method.startswith("corrected repeated 2-fold t") and c.ratio == 1.0


def test_a_plugin_split_declaring_fixed_is_recorded_and_compared_with_the_plain_t(
        tiny_scene, cache, design_registry):
    scene = tiny_scene(split="fixed-halves", classifiers=["logreg"], seeds=[0, 1, 2])
    report = run(scene, registry=design_registry, cache=cache, progress=False, plots=False)
    assert report.computed == 6 and not report.failed
    rows = _stored(scene)
    assert {r[DESIGN_FIELD] for r in rows} == {"fixed"}
    assert len({tuple(r["test_predictions"]["indices"]) for r in rows}) == 1
    (c,) = report.comparisons
    assert c.ratio == 0.0 and plain_t(c)


def test_a_plugin_split_that_leaks_a_user_at_a_later_seed_fails_that_cell(
        tiny_scene, cache, design_registry):
    scene = tiny_scene(split="leaky-users", encoders=["raw"], classifiers=["logreg"],
                       seeds=[0, 1])
    report = run(scene, registry=design_registry, cache=cache, progress=False, plots=False)
    assert report.computed == 2
    by_seed = {r["seed"]: r for r in _stored(scene)}
    assert by_seed[0]["status"] == "ok" and by_seed[0][DESIGN_FIELD] == "resampled"
    error = by_seed[1]["error"]
    assert error["type"] == "ContractError"
    assert error["message"].startswith("split 'leaky-users' breaks its group_key rule "
                                       "(train and test disjoint by user): fold 0 trains and "
                                       "tests user ")
    # leaking at the first seed: refused at planning, before any work
    with pytest.raises(ContractError, match="'leaky-users' breaks its group_key rule"):
        plan(tiny_scene(split="leaky-users", encoders=["raw"], classifiers=["logreg"],
                        seeds=[1], out=str(Path(scene.out).parent / "first")), design_registry)


def test_only_runs_that_drew_their_own_data_are_said_to_be_replications():
    """report.md's text above the comparisons: a fixed split's plain t is a figure about
    that split, not independent replications of a population."""
    from tactbench.runner.presentation.tables import INDEPENDENT_TEXT, comparisons_text

    fixed = comparisons(_rows(**{DESIGN_FIELD: "fixed"})[0], primary=PRIMARY)
    independent = comparisons(_rows(**{DESIGN_FIELD: "independent"})[0], primary=PRIMARY)
    assert "one fixed split" in comparisons_text(fixed)
    assert INDEPENDENT_TEXT not in comparisons_text(fixed)
    assert INDEPENDENT_TEXT in comparisons_text(independent)


def test_plan_says_a_fixed_split_has_no_floor_and_what_its_answer_speaks_of(
        tiny_scene, design_registry, monkeypatch):
    from click.testing import CliRunner

    from tactbench.cli import cli
    from tactbench.runner import forecast

    scene = tiny_scene(split="fixed-halves", classifiers=["logreg"], seeds=[0, 1, 2])
    f = forecast(scene, design_registry)
    assert f.design == "fixed" and not f.independent
    monkeypatch.setattr("tactbench.commands.plan.get_registry", lambda: design_registry)
    toml = Path(scene.out).parent / "fixed.toml"
    toml.write_text("\n".join([
        f'dataset = "{scene.dataset}"', 'encoders = ["raw", "frame-diff"]',
        'classifiers = ["logreg"]', "L = [3]", "seeds = [0, 1, 2]", "test_per_class = 1",
        f"pixel_mm = {scene.pixel_mm}", 'split = "fixed-halves"',
        'primary = ["encoder=raw..encoder=frame-diff"]',
        f'out = "{Path(scene.out).parent / "p"}"']) + "\n")
    out = CliRunner().invoke(cli, ["plan", str(toml)])
    assert out.exit_code == 0, out.output
    assert "no floor: one fixed split" in out.output and "speaks of it alone" in out.output
