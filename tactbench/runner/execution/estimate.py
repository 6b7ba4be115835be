"""What a run will take on this machine, before any of it runs and without a pilot.

``tactbench plan`` forecasts a run's wall time from three measurements made here, on the
plan's own dataset and components, in a few seconds:

- **encoding** (only the entries the cache lacks): a handful of recordings spread over
  the dataset are imaged and encoded, one thread each; the per-frame times scale to
  every frame of the dataset, spread over the encoding's worker threads;
- **cells** (only those not stored): each classifier that can say so times a few of its
  own training steps and predictions (``estimate_seconds`` of the classifier contract,
  :mod:`tactbench.classifiers.costs`), scaled to the cell's steps, frames and windows;
  a classifier that cannot is timed by a pilot row, or is unknown;
- **the run around them**: loading the dataset again (the run plans once more), starting
  the worker processes, writing the report.

Cells run side by side on the run's worker processes
(:func:`~tactbench.runner.execution.workers.run_workers`): the forecast packs their times
onto the workers (longest first, as a pool hands them out), each slowed by :data:`SIDE_BY_SIDE` when two or more share the
machine's cores (measured by ``benchmarks/first_run.py``). How far the estimate lands
from the measured wall time, cold and warm cache, is in docs/runner.md.
"""

from __future__ import annotations

import heapq
import logging
import time
from dataclasses import dataclass
from typing import Any, Sequence

from tactbench.contracts import CLASSIFIER, ENCODER
from tactbench.data.splits import SplitData
from tactbench.datasets.loading import load_dataset
from tactbench.encoders.encoding import vector_width
from tactbench.encoders.parallel import default_workers
from tactbench.machine import usable_cores
from tactbench.runner.execution.cache import EncodingCache, entry_key
from tactbench.runner.execution.planning import Cell, Plan

#: Recordings imaged and encoded to time the encoding.
SAMPLE_RECORDINGS = 8
#: How much slower a one-thread cell runs beside another on the next core than alone
#: (shared memory bandwidth and caches; benchmarks/first_run.py, docs/runner.md).
SIDE_BY_SIDE = 1.1
#: Seconds to start one spawned worker process (a Python with torch imported).
WORKER_START_S = 3.0
#: Seconds to write a run's report: tables, results files and its four figures.
REPORT_S = 4.0


@dataclass
class RunEstimate:
    """A run's forecast wall time and its parts (seconds); ``cells`` per cell key, None
    where unknown."""

    encode_s: float
    cells: dict[str, float | None]
    cells_wall_s: float
    overhead_s: float
    workers: int

    @property
    def seconds(self) -> float:
        return self.encode_s + self.cells_wall_s + self.overhead_s

    @property
    def unknown(self) -> int:
        return sum(v is None for v in self.cells.values())


def estimate_run(p: Plan, pending: Sequence[Cell], missing: Sequence[tuple[str, str]], *,
                 known: dict[str, float] | None = None,
                 memo: dict[Any, Any] | None = None, workers: int,
                 ) -> RunEstimate:
    """The forecast of running ``pending`` cells of ``p`` after encoding the ``missing``
    (encoder, input kind) entries; ``known`` (cell key → seconds, from a pilot) is taken
    as given for those cells. ``memo`` keeps what was measured for the next call (the
    next look's batch of the same run); its ``"load"``, when given, is the seconds the
    run's planning takes (the dataset loaded and hashed), else timed here. ``workers``:
    the run's worker count (its record's, decided once by
    :func:`~tactbench.runner.execution.workers.run_workers`)."""
    memo = {} if memo is None else memo
    if "load" not in memo:  # the caller did not time the plan's own load: time one
        said = logging.getLogger("tactbench.datasets")  # planning said its notes once
        level = said.level
        said.setLevel(logging.ERROR)
        try:
            t0 = time.perf_counter()
            load_dataset(p.scene.dataset if p.run_dataset is None else p.run_dataset,
                         registry=p.registry)
            memo["load"] = time.perf_counter() - t0
        finally:
            said.setLevel(level)
    if "counts" not in memo:
        memo["counts"] = _window_counts(p)
    cells: dict[str, float | None] = {}
    for cell in pending:
        cells[cell.key] = (known or {}).get(cell.key)
        combo = (cell.encoder, cell.classifier, cell.L)
        if cells[cell.key] is None:
            if combo not in memo:
                memo[combo] = cell_seconds(p, cell, memo["counts"])
            cells[cell.key] = memo[combo]
    overhead = memo["load"] + REPORT_S
    # the encoding is timed only when every cell's time is known (else no total is said)
    encode = encode_seconds(p, missing) if None not in cells.values() else 0.0
    workers = max(1, min(workers, len(pending)))
    if workers > 1 or p.scene.executor != "local":
        overhead += WORKER_START_S
    times = [t for t in cells.values() if t is not None]
    slow = SIDE_BY_SIDE if workers > 1 and usable_cores() > 1 else 1.0
    return RunEstimate(encode, cells, packed(times, workers) * slow, overhead, workers)


def packed(times: Sequence[float], workers: int) -> float:
    """The wall time of ``times`` handed longest first to ``workers`` (a pool's order)."""
    loads = [0.0] * max(1, workers)
    for t in sorted(times, reverse=True):
        heapq.heapreplace(loads, loads[0] + t)
    return max(loads)


def encode_seconds(p: Plan, missing: Sequence[tuple[str, str]]) -> float:
    """Wall seconds to image the dataset and encode it with the ``missing`` entries'
    encoders: per-frame times on :data:`SAMPLE_RECORDINGS` recordings, scaled."""
    if not missing:
        return 0.0
    data = p.dataset
    lengths = data.lengths()
    sample = sorted({int(i) for i in _spread(len(lengths), SAMPLE_RECORDINGS)})
    frames = int(sum(lengths[i] for i in sample))
    total = float(sum(lengths))
    per_frame = 0.0
    kinds = {kind for _, kind in missing}
    if "images" in kinds:
        pixel_mm, method = p.scene.resolved_pixel_mm(), p.scene.imaging
        data.images(pixel_mm, method, indices=sample[:1])  # the imaging operator, once
        t0 = time.perf_counter()
        images = data.images(pixel_mm, method, indices=sample)
        per_frame += (time.perf_counter() - t0) / frames
    for enc, kind in missing:
        encoder = p.encoders[enc]
        if kind == "images":
            work = [lambda seq=seq: encoder.encode(seq) for seq in images]
        else:
            vectors = ENCODER.get(encoder, "encode_vectors")
            work = [lambda v=v: vectors(v) for v in data.vectors(sample)]
        t0 = time.perf_counter()
        for job in work:
            job()
        per_frame += (time.perf_counter() - t0) / frames / max(1, default_workers())
    return per_frame * total


def _spread(n: int, k: int) -> list[int]:
    """``k`` indices spread evenly over ``range(n)``."""
    return [round(i * (n - 1) / max(1, k - 1)) for i in range(min(n, k))]


def _window_counts(p: Plan) -> dict[str, int]:
    """Training windows, frames and test windows of the first seed's split, per L."""
    data = p.dataset
    lengths = data.lengths()
    splits = p.split.split(SplitData.of(data, test_per_class=p.scene.test_per_class),
                           seed=p.scene.seeds[0])
    out: dict[str, int] = {}
    for L in p.scene.L:
        train = [int(lengths[i]) for s in splits for i in s.train]
        test = [int(lengths[i]) for s in splits for i in s.test]
        out[f"train {L}"] = sum(max(1, t - L + 1) for t in train)
        out[f"test {L}"] = sum(max(1, t - L + 1) for t in test)
        out[f"frames {L}"] = sum(train) + sum(test)
    return out


def cell_seconds(p: Plan, cell: Cell, counts: dict[str, int]) -> float | None:
    """One cell's seconds by its classifier's own estimate; None when it has none."""
    clf = p.registry.build("classifier", cell.classifier,
                           classes=len(p.dataset.classes))
    estimate = CLASSIFIER.get(clf, "estimate_seconds")
    if estimate is None:
        return None
    encoder = p.encoders[cell.encoder]
    if p.input_kind[cell.classifier] == "images":
        h, w = p.dataset.image_shape(p.scene.resolved_pixel_mm(), p.scene.imaging)
        shape: tuple[int, ...] = (len(tuple(ENCODER.get(encoder, "channels"))), h, w)
    else:
        shape = (vector_width(encoder, p.dataset.n_taxels),)
    return float(estimate(frame_shape=shape, L=cell.L, n_classes=len(p.dataset.classes),
                          n_train_windows=counts[f"train {cell.L}"],
                          n_frames=counts[f"frames {cell.L}"],
                          n_test_windows=counts[f"test {cell.L}"]))


def missing_entries(p: Plan, cells: Sequence[Cell],
                    cache: EncodingCache) -> list[tuple[str, str]]:
    """The (encoder, input kind) entries ``cells`` need that ``cache`` does not hold."""
    return [pair for pair in dict.fromkeys((c.encoder, p.input_kind[c.classifier])
                                           for c in cells)
            if not cache.has(entry_key(p, cache, *pair))]
