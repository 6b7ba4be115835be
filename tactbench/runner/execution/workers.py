"""How many cells run at once: decided once, here, from the cores, the GPUs and the memory.

Cells run side by side in worker processes, one torch thread each by default (the thread
count is part of a cell's identity, so parallelism comes from cells, not threads). The
count is the scene's ``workers`` where given, else the smallest of:

- **cores**: this process's usable cores ÷ the torch threads of each cell (CPU cells);
- **GPUs**: one worker per GPU it owns (``--device cuda``: every GPU here;
  ``cuda:N``: one; :func:`~tactbench.runner.execution.devices.owned_devices`);
- **memory**: as many workers as fit in this machine's memory (or the run's
  ``--memory``, all its processes together) beside the run's own
  process, each at its forecast peak (:func:`worker_peak`): the largest peak a stored
  cell of the grid measured (a pilot, an earlier look or run), else an estimate from the
  plan (a worker's imports, the training frame bank, a batch of windows): a floor, since
  a network's activations are not in it (most of the paper profile's cnn-lstm peak),
  so a pilot's rows are what make the bound sure.

:func:`decide_workers` is the rule (no machine read where its caller says the facts);
:func:`run_workers` reads the machine and the plan and applies it. The executors, the
look loop, the wall-time estimate and ``tactbench plan`` all read one :class:`Workers`.
On a remote dask cluster (``--scheduler``) the cluster decides where cells run and how
much memory each has: the count there is the scene's or the cores' rule, for estimates.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Iterable, Mapping

from tactbench.classifiers.batching import bank_budget_bytes
from tactbench.errors import InputError
from tactbench.machine import memory_bytes, usable_cores
from tactbench.runner.execution.devices import owned_devices, resolve_kind

if TYPE_CHECKING:
    from tactbench.runner.execution.planning import Plan
    from tactbench.runner.execution.scene import Scene

MIB = float(1 << 20)
#: A worker process's resident memory before its first cell (MiB): Python with torch,
#: numpy, scikit-learn and the runner imported; the smallest peak any committed cell row
#: recorded (a logreg cell, quick profile: docs/results, 406 MiB on the project's VM).
WORKER_BASE_MB = 406.0
#: The source of a worker's peak estimated from the plan: a floor, not a measurement.
ESTIMATED = ("at least: estimated from the plan, no stored cell measured one (a pilot of "
             "one seed measures it)")


@dataclass(frozen=True)
class Workers:
    """A run's worker count and why: ``limit`` names what set it (``--workers``,
    ``cores``, ``GPUs``, ``memory``); ``devices`` the device each worker owns (None:
    none of its own); the peaks (MiB) are forecasts: one worker's, with its source, and
    the run's own process's; ``memory_mb`` the machine's."""

    count: int
    limit: str
    devices: tuple[str, ...] | None = None
    worker_peak_mb: float | None = None
    peak_source: str = "not forecast"
    parent_peak_mb: float = 0.0
    memory_mb: float | None = None
    memory_source: str = "this machine"  # or "--memory": the run's cap

    @property
    def run_peak_mb(self) -> float | None:
        """The whole run's forecast peak, every process together (MiB): the run's own
        process and each worker at its peak; with one worker the cells run in the run's
        own process, adding what a cell takes beyond a worker's imports."""
        if self.worker_peak_mb is None:
            return None
        if self.count == 1:
            return self.parent_peak_mb + max(0.0, self.worker_peak_mb - WORKER_BASE_MB)
        return self.parent_peak_mb + self.count * self.worker_peak_mb


def decide_workers(scene: "Scene", *, worker_peak_mb: float | None = None,
                   peak_source: str = "not forecast", parent_peak_mb: float = 0.0,
                   memory_mb: float | None = None, cores: int | None = None,
                   devices: list[str] | None = None) -> Workers:
    """The rule of the module docstring, from the facts given (``cores``: this process's
    usable cores, read where None; ``devices``: those the workers own, one each)."""
    here = dict(worker_peak_mb=worker_peak_mb, peak_source=peak_source,
                parent_peak_mb=parent_peak_mb, memory_mb=memory_mb,
                devices=None if devices is None else tuple(devices))
    if scene.workers is not None:
        count = int(scene.workers)
        if devices is not None and count > len(devices):
            raise InputError(f"--workers {count}: each worker owns one GPU, and device "
                             f"{scene.device!r} gives {len(devices)} here; use --workers "
                             f"{len(devices)} or fewer")
        return Workers(count, "--workers", **here)
    if devices is not None:
        count, limit = len(devices), "GPUs"
    else:
        count = max(1, (usable_cores() if cores is None else cores) // max(1, scene.threads))
        limit = "cores"
    if worker_peak_mb and memory_mb and scene.scheduler is None:
        fit = int((memory_mb - parent_peak_mb) // worker_peak_mb)
        if fit < count:
            count, limit = max(1, fit), "memory"
    return Workers(count, limit, **here)


def worker_peak(rows: Iterable[Mapping[str, Any]] = (), p: "Plan | None" = None,
                ) -> tuple[float | None, str]:
    """One worker's forecast peak resident memory (MiB) and where it comes from: the
    largest ``peak_rss_mb`` that a stored ``ok`` row (of the plan's classifiers, given
    ``p``) measured, else, given ``p``, :data:`WORKER_BASE_MB` + the training frame bank
    (:func:`~tactbench.classifiers.batching.bank_budget_bytes`) + two batches of windows
    of the longest L (one being trained on, one being made); else None."""
    classifiers = None if p is None else set(p.classifier_specs)
    measured = [float(r["peak_rss_mb"]) for r in rows
                if r.get("status", "ok") == "ok"
                and (classifiers is None or r.get("classifier") in classifiers)
                and isinstance(r.get("peak_rss_mb"), (int, float))
                and r["peak_rss_mb"] == r["peak_rss_mb"]]
    if measured:
        return max(measured), f"the largest of {len(measured)} stored cell(s)"
    if p is None:
        return None, "not forecast"
    estimate = WORKER_BASE_MB + (bank_budget_bytes() + 2 * p.batch_bytes) / MIB
    return estimate, ESTIMATED


def run_devices(scene: "Scene") -> list[str] | None:
    """The devices a run's workers own, one each (:func:`~tactbench.runner.execution.
    devices.owned_devices`); None on a remote dask cluster, whose workers own what their
    cluster gave them."""
    if scene.executor == "dask" and scene.scheduler:
        resolve_kind(scene.device, scene.executor)  # auto refused there too
        return None
    return owned_devices(scene.device, scene.executor)


def run_workers(scene: "Scene", rows: Iterable[Mapping[str, Any]] = (), *,
                plan: "Plan | None" = None, parent_peak_mb: float = 0.0) -> Workers:
    """The worker count of a run of ``scene`` on this machine (:func:`decide_workers`):
    its cores, its GPUs, its memory (the machine's, or the scene's ``memory`` where it
    is less) and a worker's forecast peak (:func:`worker_peak` from ``rows``, the stored
    rows of the run's folder, and the ``plan``) beside the run's own process at
    ``parent_peak_mb``. The one place the count is worked out: the run's record holds it
    (:mod:`~tactbench.runner.execution.record`), and the executors, the looks, the
    estimate and ``tactbench plan`` read it there. With ``memory`` a run whose forecast
    peak, all processes together, is above it is refused in one line (:func:`check_room`)."""
    peak, source = worker_peak(rows, plan)
    machine, cap = memory_bytes() / MIB, scene.memory_mb()
    workers = decide_workers(scene, worker_peak_mb=peak, peak_source=source,
                             parent_peak_mb=parent_peak_mb,
                             memory_mb=machine if cap is None else min(machine, cap),
                             devices=run_devices(scene))
    if cap is not None and cap < machine:
        workers = replace(workers, memory_source="--memory")
        if workers.count > 1 and scene.workers is None and not measured(workers):
            # a forecast from the plan is a floor (no network's activations): under a
            # cap, cells side by side need a measured peak; one at a time until then
            workers = replace(workers, count=1, limit="--memory without a measured peak")
        check_room(workers, scene.memory)
    return workers


def measured(workers: Workers) -> bool:
    """Whether a worker's forecast peak was measured (a stored cell's), not a floor
    estimated from the plan."""
    return workers.worker_peak_mb is not None and workers.peak_source != ESTIMATED


def check_room(workers: Workers, memory: str) -> None:
    """Refuse a run whose forecast peak (all its processes) is above its ``--memory``,
    in one line with the numbers and what lowers the peak."""
    peak = workers.run_peak_mb
    if peak is None or workers.memory_mb is None or peak <= workers.memory_mb:
        return
    raise InputError(
        f"--memory {memory}: the run's forecast peak is {peak / 1024:.2f} GiB ({workers.count} "
        f"worker(s) at {workers.worker_peak_mb / 1024:.2f} GiB, {workers.peak_source}, beside "
        f"the run's own process at {workers.parent_peak_mb / 1024:.2f} GiB), above "
        f"{workers.memory_mb / 1024:.2f} GiB; give more memory, or lower a cell's peak (a "
        f"smaller batch_size of the classifier)")
