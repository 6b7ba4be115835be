"""``tactbench plan``: what a run will cost and what it can answer, before any training.

:func:`forecast` plans the scene (the dataset loaded, the grid checked: no encoding, no
training) and says, for every cell, its estimated time and where the estimate comes
from, the peak memory, the workers, the cache the run fills and the room on its disk,
the run's wall time, and for each primary comparison its power at the planned runs
(:mod:`tactbench.runner.analysis.forecast`). Timings and spreads come from a *pilot*:
rows already stored in the scene's out folder (a run of a seed or two), said so.

This module composes the runner's rooms the way :mod:`tactbench.runner.orchestrate`
composes a run, and decides nothing itself: execution does the work — the plan
(:func:`~tactbench.runner.execution.planning.plan_runs`), the encoding cache and the
bytes it will hold (:mod:`tactbench.runner.execution.cache`), the wall time
(:mod:`tactbench.runner.execution.estimate`), the workers
(:func:`~tactbench.runner.execution.workers.run_workers`) and the stored pilot
(:class:`~tactbench.runner.execution.results.ResultStore`) —, and analysis decides from
what it found — each cell's time from the pilot, the primary family
(:func:`~tactbench.runner.analysis.family.primary_family`), each comparison's power
(:mod:`tactbench.runner.analysis.power`), the family's chance of being answered and the
warnings (:mod:`tactbench.runner.analysis.forecast`, the records and pure rules).
"""

from __future__ import annotations

import dataclasses
import shutil
import time
from pathlib import Path
from typing import Any

from tactbench.data.splits import SplitData, split_design
from tactbench.machine import memory_mb
from tactbench.plugins import load_registry
from tactbench.runner.analysis.forecast import (
    CellForecast,
    Forecast,
    _cells,
    _family,
    _primary,
    family_answered,
)
from tactbench.runner.analysis.paired_tests import choose_paired_test
from tactbench.runner.analysis.power import seed_mean_ratio
from tactbench.runner.execution.cache import EncodingCache, entries_bytes
from tactbench.runner.execution.estimate import estimate_run, missing_entries
from tactbench.runner.execution.planning import (
    Cell,
    Plan,
    digest,
    imaging_identity,
    other_run_identity,
    plan_runs,
    run_datasets,
)
from tactbench.runner.execution.results import ResultStore, ok_rows
from tactbench.runner.execution.scene import Scene
from tactbench.runner.analysis.family import family_names, grid_cells
from tactbench.runner.execution.record import resolve_compute, resolve_record


def forecast(scene: Scene, registry=None, *, effect: float = 5.0, alpha: float = 0.05,
             progress=None) -> Forecast:
    """The forecast of ``scene`` (see the module docstring); ``effect`` in points.

    With ``until``, the cells of every seed the looks may reach (the most the run
    costs). Where every run draws its own data set, only the first run's is made (the
    split's sizes and every check come from it): the other runs' cells are derived from
    the first's (:func:`_other_runs`)."""
    registry = registry or load_registry()
    asked = scene  # the run's own scene, whose record the plan makes as the run would
    compute = resolve_compute(asked)
    if scene.until:
        scene = dataclasses.replace(scene, seeds=list(scene.design.seed_order))
    made: list[int] = []  # the dataset was made while planning: its load is not timed

    def making(done: int, total: int | None = None) -> None:
        made.append(done)
        if progress is not None:
            progress(done, total)

    t0 = time.perf_counter()
    [p] = plan_runs(scene, registry, progress=making, first_only=True, compute=compute)
    planned_s = time.perf_counter() - t0
    pilot = ok_rows(ResultStore(scene.out).stored_rows())  # none: no folder yet
    runs = len(scene.seeds)
    data = SplitData.of(p.dataset, test_per_class=scene.test_per_class)
    splits = p.split.split(data, seed=scene.seeds[0])
    n_test = sum(len(s.test) for s in splits)
    n_train = len(splits[0].train)
    independent = p.run_dataset is not None  # each run its own data set: no overlap
    design = "independent" if independent else split_design(p.split, splits)
    # what run refuses, refused here in its words (its power is still the corrected t's)
    paired = choose_paired_test(scene.paired_test, registry)
    paired.check(design, sequential=bool(scene.until))
    ratio = 0.0 if design in ("independent", "fixed") else \
        seed_mean_ratio(len(splits)) if design == "kfold" else n_test / n_train
    others = _other_runs(p, run_datasets(scene, registry), pilot) if independent else []
    # what run's claim refuses, refused here in its words (nothing written)
    ResultStore(scene.out).check_grid([c.key for c in p.cells + others if c.key],
                                      p.identities)
    cells = _cells(p.cells + others, pilot)
    record = _record(asked, p, pilot, paired.name)  # what every number below reads
    looks = list(record.looks) or None
    cache = EncodingCache()
    missing = missing_entries(p, p.cells + others, cache)
    workers = record.workers
    wall = _walls(p, p.cells + others, cells, looks, missing, workers.count,
                  load_s=None if made and p.run_dataset is None else planned_s)
    known = [c.seconds for c in cells if c.seconds is not None]
    distinct = (_distinct_splits(p, data, scene.seeds) if design == "resampled"
                and scene.split != "paper" else runs)
    family = _family(p.cells, record.primary, pilot)
    level = alpha / max(1, len(family))  # Holm's first step over the family the run makes
    usable = min(runs, distinct)  # repeated splits add no evidence: the looks stop there
    capped = None if not looks else [x for x in looks if x < usable] + [usable]
    capped = capped if capped and capped[0] >= 2 else None
    primaries = [_primary(name, found, usable, effect / 100, ratio, n_test, level,
                          len(p.dataset.labels), margin=scene.margin, looks=capped,
                          n_train=n_train)
                 for name, found, _ in family]
    together = family_answered(primaries, [pair for _, _, pair in family], alpha=alpha,
                               looks=capped, margin=scene.margin)
    return Forecast(
        cells=cells, seconds=sum(known) if known else None,
        unknown=sum(c.seconds is None for c in cells),
        peak_mb=max((float(r["peak_rss_mb"]) for r in pilot if r.get("peak_rss_mb")),
                    default=None),
        primaries=primaries, family=together,
        family_answered=None if together is None else together["answered"],
        distinct_splits=distinct, runs_asked=runs,

        n_test=n_test, n_train=n_train, alpha=alpha, independent=independent,
        design=design,
        runs_not_made=len({c.seed for c in others}), wall_s=wall, looks=looks,
        workers=workers.count, workers_limit=workers.limit,
        worker_peak_mb=workers.worker_peak_mb, worker_peak_source=workers.peak_source,
        run_peak_mb=workers.run_peak_mb, memory_mb=workers.memory_mb,
        cache_bytes=entries_bytes(p, missing) + _other_runs_bytes(p, others, pilot, cache),
        cache_free=_free_bytes(cache.root), record=record.to_json())


def _distinct_splits(p: Plan, data: SplitData, seeds: list[int]) -> int:
    """How many distinct splits (test recordings of every fold) the planned seeds draw:
    over few groups (sessions, people) seeds repeat splits, and a run counts a repeated
    one once (:func:`tactbench.runner.analysis.pairing.distinct_splits`), so the power is
    that of the distinct splits."""
    drawn = {tuple(tuple(sorted(int(i) for i in s.test)) for s in p.split.split(data, seed=seed))
             for seed in seeds}
    return len(drawn)


def _free_bytes(root: Path) -> int | None:
    """Bytes free on the disk of ``root``; None when it cannot say."""
    try:
        return int(shutil.disk_usage(root).free)
    except OSError:
        return None


def _record(scene: Scene, p: Plan, pilot: list[dict[str, Any]], paired_test: str):
    """The record a run of ``scene`` will make (:func:`~tactbench.runner.execution.record.
    resolve_record`, as the run's first batch makes it): its design, each primary's
    family, the computation ``p`` was planned with and the workers over the ``pilot``."""
    return resolve_record(scene, plan=p, rows=pilot, parent_peak_mb=memory_mb()[1],
                          paired_test=paired_test, compute=p.compute,
                          families=family_names(grid_cells(p.cells), scene.design.primary))


def _walls(p: Plan, planned: list[Cell], cells: list[CellForecast],
           looks: list[int] | None, missing: list[tuple[str, str]], workers: int, *,
           load_s: float | None) -> list[float] | None:
    """The run's wall time (:func:`~tactbench.runner.execution.estimate.estimate_run`), cumulative
    at each look (one number without looks); cells without a pilot timing get the
    classifier's own estimate (``cells`` updated in place). None when a cell has
    neither."""
    order = list(dict.fromkeys(c.seed for c in planned))
    ends = looks or [len(order)]
    known = {c.key: f.seconds for c, f in zip(planned, cells)
             if f.seconds is not None and c.key}
    memo: dict[Any, Any] = {} if load_s is None else {"load": load_s}  # else timed there
    total, out, start = 0.0, [], 0
    for i, end in enumerate(ends):
        seeds = set(order[start:end])
        batch = [c for c, f in zip(planned, cells) if c.seed in seeds
                 and not f.source.startswith("finished")]
        est = estimate_run(p, batch, missing if i == 0 else [], known=known, memo=memo,
                           workers=workers)
        if est.unknown:
            return None
        total += est.seconds if batch or i == 0 else 0.0
        out.append(total)
        start = end
    for c, f in zip(planned, cells):
        if f.seconds is None:
            f.seconds = memo.get((c.encoder, c.classifier, c.L))
            f.source = "estimated here: a few of its training steps timed"
    return out


def _other_runs(first: Plan, specs: dict[int, str], pilot: list[dict[str, Any]]
                ) -> list[Cell]:
    """The cells of the runs after ``first`` where every run draws its own data set,
    without making their data sets: a cell's key hashes its data set's content, unknown
    until the data set is made, so each cell's key is the one it has with the content
    hash of a stored row of its run's data set (the row's ``run_dataset``) where that key
    is a stored row's — the cell is finished, as run will find it unless that data set's
    content changed since (then run computes it again) — and empty otherwise (not yet
    computed)."""
    hashes: dict[str, set[str]] = {}
    for r in pilot:
        if r.get("run_dataset") and r.get("dataset_hash"):
            hashes.setdefault(r["run_dataset"], set()).add(r["dataset_hash"])
    stored = {r["key"] for r in pilot}
    out = []
    for seed, spec in list(specs.items())[1:]:
        for cell in first.cells:
            keys = {digest(other_run_identity(first.identities[cell.key], seed, spec, h))
                    for h in sorted(hashes.get(spec, ()))}
            out.append(dataclasses.replace(cell, seed=int(seed),
                                           key=min(keys & stored, default="")))
    return out


def _other_runs_bytes(first: Plan, others: list[Cell], pilot: list[dict[str, Any]],
                      cache: EncodingCache) -> int:
    """The bytes of new encodings the runs after ``first`` add where every run draws its
    own data set (each run's entries are its own): each run's entries sized as the first
    run's (its data set is not made here), less those the cache holds for a run's data
    set a stored row names."""
    hashes: dict[int, set[str]] = {}
    for r in pilot:
        if r.get("run_dataset") and r.get("dataset_hash"):
            hashes.setdefault(int(r["seed"]), set()).add(r["dataset_hash"])
    pending: dict[int, dict[tuple[str, str], None]] = {}
    for c in others:
        if not c.key:  # not yet computed: its run needs the entry
            pending.setdefault(c.seed, {})[(c.encoder, first.input_kind[c.classifier])] = None
    precision = first.scene.resolved_precision()
    total = 0
    for seed, pairs in pending.items():
        missing = [(enc, kind) for enc, kind in pairs
                   if not any(cache.has(cache.key(h, imaging_identity(first.scene, kind), enc,
                                                  first.encoder_versions[enc], precision))
                              for h in hashes.get(seed, ()))]
        total += entries_bytes(first, missing)
    return total
