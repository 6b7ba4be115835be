"""Independent replications: ``synthetic-forearm:people=per-run`` draws each run's people
with the run's seed; the runner plans, encodes and caches a data set per run, rows record
it, and comparisons over such runs are the plain paired t (ratio 0, no floor)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from tactbench.runner import forecast, run
from tactbench.runner.analysis.comparisons import comparisons
from tactbench.runner.execution.planning import plan, plan_runs
from tactbench.runner.analysis.power import detectable_effect, effect_floor, runs_for_power
from tactbench.runner.execution.results import INDEPENDENT_RUNS
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

PER_RUN = "synthetic-forearm:users=2,repetitions=1,positions=1,people=per-run"
PRIMARY = ["encoder=raw..encoder=farneback"]


def _scene(tiny_scene, **over):
    fields = dict(dataset=PER_RUN, encoders=["raw", "frame-diff"], classifiers=["logreg"],
                  seeds=[0, 1, 2], split="users", pixel_mm=15.0)
    fields.update(over)
    return tiny_scene(**fields)


def test_each_seed_plans_its_own_data_set_and_its_cells_record_it(tiny_scene):
    plans = plan_runs(_scene(tiny_scene))
    assert [p.scene.seeds for p in plans] == [[0], [1], [2]]
    assert len({p.dataset_hash for p in plans}) == 3  # new people every run
    for seed, p in enumerate(plans):
        assert p.dataset is None  # let go once planned; loaded again to encode
        assert p.run_dataset.endswith(f"seed={seed},users=2,version=2")
        for identity in p.identities.values():
            assert identity["dataset"] == "synthetic-forearm"  # runs pair across seeds
            assert identity["dataset_hash"] == p.dataset_hash
            assert identity["run_dataset"] == p.run_dataset
            assert identity[INDEPENDENT_RUNS] is True
    again = plan_runs(_scene(tiny_scene, seeds=[1]))  # the same seed: the same draw
    assert again[0].dataset_hash == plans[1].dataset_hash
    assert again[0].identities == plans[1].identities


def test_a_fixed_data_set_keeps_one_plan_and_its_cell_keys(tiny_scene):
    """Every other dataset: one plan, and identities without the new fields (the keys of
    committed cells do not change)."""
    scene = _scene(tiny_scene, dataset="synthetic-forearm:users=2,repetitions=1,positions=1")
    plans = plan_runs(scene)
    assert len(plans) == 1 and plans[0].dataset is not None
    assert plans[0].identities == plan(scene).identities
    for identity in plans[0].identities.values():
        assert "run_dataset" not in identity and INDEPENDENT_RUNS not in identity


def test_a_run_trains_on_each_seeds_people_and_resumes_without_training(tiny_scene, cache):
    scene = _scene(tiny_scene)
    report = run(scene, cache=cache, progress=False, plots=False)
    assert report.computed == 6 and not report.failed
    rows = [json.loads(p.read_text()) for p in (Path(scene.out) / "cells").glob("*.json")]
    by_seed = {}
    for r in rows:
        assert r["status"] == "ok" and r[INDEPENDENT_RUNS] is True
        assert r["run_dataset"].endswith(f"seed={r['seed']},users=2,version=2")
        by_seed.setdefault(r["seed"], set()).add(r["dataset_hash"])
    assert all(len(h) == 1 for h in by_seed.values()) and len(set.union(*by_seed.values())) == 3
    assert len(cache.entries()) == 6  # an encoding per encoder and run's data set
    (c,) = report.comparisons
    assert c.ratio == 0.0 and c.run_ratio == 0.0 and "independent" in c.method
    again = run(scene, cache=cache, progress=False, plots=False)
    assert again.computed == 0 and again.skipped == 6
    assert len(cache.entries()) == 6


def _row(encoder, seed, truth, predicted, *, independent=True):
    return prediction_row(encoder, seed, truth, predicted, split="users",
                          **({INDEPENDENT_RUNS: True} if independent else {}))


def _rows(independent=True, seeds=range(6), n=200):
    rng = np.random.default_rng(7)
    truth = [i % 2 for i in range(n)]
    rows, acc = [], {}
    for seed in seeds:
        for enc, p in (("raw", 0.7), ("farneback", 0.76)):
            right = rng.random(n) < p
            pred = [t if ok else 1 - t for t, ok in zip(truth, right)]
            rows.append(_row(enc, seed, truth, pred, independent=independent))
            acc[enc, seed] = float(np.mean(right))
    return rows, acc


def test_the_comparison_of_independent_runs_is_the_plain_paired_t():
    rows, acc = _rows()
    (c,) = comparisons(rows, primary=PRIMARY)
    assert c.ratio == 0.0 and c.run_ratio == 0.0
    a = np.array([acc["raw", s] for s in range(6)])
    b = np.array([acc["farneback", s] for s in range(6)])
    plain = stats.ttest_rel(b, a)
    low, high = plain.confidence_interval(0.95)
    assert c.low == pytest.approx(low) and c.high == pytest.approx(high)
    assert c.t_p == pytest.approx(plain.pvalue)
    # the same rows as re-splits of one data set: corrected, so wider
    (fixed,) = comparisons(_rows(independent=False)[0], primary=PRIMARY)
    assert fixed.ratio == pytest.approx(200 / 800) and fixed.high - fixed.low > high - low


def test_independent_runs_have_no_floor():
    rows, _ = _rows()
    (c,) = comparisons(rows, primary=PRIMARY)
    sd = float(np.std(list(c.per_run.values()), ddof=1))
    assert effect_floor(sd, c.run_ratio) == 0.0
    assert runs_for_power(0.2 * sd, sd, c.run_ratio) is not None  # any effect, given runs
    assert detectable_effect(sd, 0.0, 1000) < detectable_effect(sd, 0.0, 10)
    assert runs_for_power(0.2 * sd, sd, 0.25) is None  # below a fixed set's floor


def test_a_mixed_pair_keeps_the_correction():
    """Only runs that all drew their own data set are independent."""
    rows, _ = _rows()
    rows[0] = {k: v for k, v in rows[0].items() if k != INDEPENDENT_RUNS}
    (c,) = comparisons(rows, primary=PRIMARY)
    assert c.ratio > 0


def test_the_forecast_of_per_run_people_has_no_floor(tiny_scene):
    f = forecast(_scene(tiny_scene, encoders=["raw", "farneback"],
                        primary=["encoder=raw..encoder=farneback"]))
    assert f.independent
    (p,) = f.primaries
    assert p.ratio == 0.0 and p.floor == 0.0
    assert len(f.cells) == 6


def _count_loads(monkeypatch) -> list[str]:
    """The seeds of every data set of the simulator loaded (made or read from its cache)."""
    from tactbench.datasets.synthetic_forearm import SyntheticForearm

    loads, load = [], SyntheticForearm.load

    def counted(self, *args, **kwargs):
        loads.append(self.options["seed"])
        return load(self, *args, **kwargs)

    monkeypatch.setattr(SyntheticForearm, "load", counted)
    return loads


def test_a_plan_of_many_runs_makes_one_data_set(tiny_scene, monkeypatch):
    """tactbench plan makes the first run's data set only: the other runs' cells are
    derived from its plan, none finished without a stored row."""
    loads = _count_loads(monkeypatch)
    scene = _scene(tiny_scene, seeds=[0], until="answered", max_runs=20,
                   primary=["encoder=raw..encoder=frame-diff"])
    f = forecast(scene)
    assert loads == [0]
    assert f.independent and f.runs_not_made == 19
    assert len(f.cells) == 40 and f.unknown == 40
    assert [c.label for c in f.cells][-1] == "frame-diff × logreg L=3 seed=19"
    (p,) = f.primaries
    assert p.runs == 20 and p.floor == 0.0


def test_a_plan_finds_the_stored_cells_of_runs_it_did_not_make(tiny_scene, cache,
                                                             monkeypatch):
    """A later run's cell is finished where a stored row of its run's data set has the key
    the cell has with that row's content hash; the same cell as run computes it."""
    run(_scene(tiny_scene, seeds=[0, 2]), cache=cache, progress=False, plots=False)
    loads = _count_loads(monkeypatch)
    f = forecast(_scene(tiny_scene, seeds=[0, 1, 2, 3]))
    assert loads == [0] and f.runs_not_made == 3
    finished = {c.label for c in f.cells if c.source == "finished (stored)"}
    assert finished == {f"{enc} × logreg L=3 seed={s}" for enc in ("raw", "frame-diff")
                        for s in (0, 2)}
    assert all(c.seconds is not None for c in f.cells)  # the stored rows time the rest


def test_the_tables_of_independent_runs_claim_no_correction():
    """report.md's and the terminal's tables name the p column by the t it is; the text
    above says the plain paired t, and where every t is corrected nothing changes (the
    stored reports' header and text)."""
    from tactbench.runner.presentation.tables import (
        COMPARISON_HEADER,
        COMPARISONS_TEXT,
        comparison_header,
        comparisons_section,
    )

    plain = comparisons(_rows()[0], primary=PRIMARY)
    fixed = comparisons(_rows(independent=False)[0], primary=PRIMARY)
    text = "\n".join(comparisons_section(plain))
    assert "corrected" not in text and "p (paired t)" in text
    assert "the plain paired t over runs" in text and "p is that t's" in text
    assert "p (paired t)" in comparison_header(plain)
    assert comparison_header(fixed) == COMPARISON_HEADER
    fixed_text = "\n".join(comparisons_section(fixed))
    assert COMPARISONS_TEXT in fixed_text and "p (corrected t)" in fixed_text
    assert "people=per-run" not in fixed_text
    mixed = comparison_header([*plain, *fixed])
    assert "p (t over runs)" in mixed and "p (corrected t)" not in mixed


def test_an_open_answer_says_what_holds_it_back():
    """A primary question left open by an early look's boundary, with enough runs for a
    single test already, does not ask for runs it has; a fixed design names its runs."""
    import dataclasses

    from tactbench.runner.presentation.tables import answer_text

    (c,) = comparisons(_rows()[0], primary=PRIMARY)
    assert c.runs_for_power is not None
    held = dataclasses.replace(c, verdict="unresolved", runs_for_power=c.runs - 1,
                               note="group-sequential: no boundary crossed in 1 look(s)")
    text = answer_text(held)
    assert f"it has {c.runs}" in text and "early look's boundary" in text
    assert "would answer it" not in text
    fixed = dataclasses.replace(c, verdict="unresolved", runs_for_power=c.runs + 4, note="")
    assert f"about {c.runs + 4} runs would answer it" in answer_text(fixed)
    floor = dataclasses.replace(c, verdict="unresolved", runs_for_power=None, note="")
    assert "no number of runs of these data gives 80 % power" in answer_text(floor)
