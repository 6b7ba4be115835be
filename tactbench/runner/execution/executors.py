"""Where cells run: in turn in this process, in local worker processes, or on dask.

By default as many cells run side by side as the machine has cores, one torch thread
each (:meth:`~tactbench.runner.execution.scene.Scene.resolved_workers`): the thread count is part
of a cell's identity, so parallelism comes from cells, not threads. Spawned workers
inherit the pinned CPU kernels (:func:`~tactbench.machine.pin_cpu_kernels`) from this
process's environment.

Each executor calls ``finish(row)`` in this process as soon as a cell's row is back, in
the order cells finish. A cell never raises here (:func:`~tactbench.runner.execution.cell.run_cell`
returns a failed row instead); when a worker itself dies (killed for memory, a crashed
interpreter), its cell gets a failed row too. Ctrl-C stops at once: cells not started are
dropped, finished ones were already handed to ``finish``.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
import multiprocessing
from typing import TYPE_CHECKING, Any, Callable, Iterable

from tactbench.errors import InputError
from tactbench.runner.execution.cell import CellJob, failed_row, run_cell
from tactbench.runner.execution.questions import spec_labels
from tactbench.runner.execution.system import BEFORE, MemoryTracker, ignore_interrupts, stop_workers

if TYPE_CHECKING:
    from tactbench.runner.execution.scene import Scene
    from tactbench.ui import Progress

Finish = Callable[[dict[str, Any]], None]


def execute(scene: "Scene", jobs: list[CellJob], finish: Finish, bars: "Progress",
            memory: "MemoryTracker | None" = None) -> None:
    """Run ``jobs`` on the scene's executor, with an overall bar in ``bars``; ``memory``
    has the run's steps so far in this process (see :func:`run_serial`)."""
    overall = bars.add("cells", total=len(jobs))
    done = 0

    def finished(row: dict[str, Any]) -> None:
        nonlocal done
        finish(row)
        done += 1
        bars.update(overall, done)

    workers = scene.resolved_workers()
    if scene.executor == "dask":
        run_dask(jobs, finished, workers=workers, scheduler=scene.scheduler)
    elif min(workers, len(jobs)) == 1:
        run_serial(jobs, finished, bars, memory)
    else:
        run_processes(jobs, finished, workers=min(workers, len(jobs)))


def run_serial(jobs: Iterable[CellJob], finish: Finish, bars: "Progress",
               memory: "MemoryTracker | None" = None) -> None:
    """One cell after another in this process, each with its training bar.

    ``memory`` follows the run's own steps in this process (planning, encoding, each
    cell): a cell whose peak was set before it started names the step that set it.
    """
    memory = memory if memory is not None else MemoryTracker()
    jobs = list(jobs)
    labels = spec_labels(job.cell.classifier for job in jobs)  # variants told apart
    for job in jobs:
        earlier = memory.peak_step
        row = run_cell(job, bars.callback(f"train {job.cell.label(labels)}"))
        if row.get("peak_step") == BEFORE and earlier != BEFORE:
            row["peak_step"] = f"{earlier} (earlier in this run)"
        memory.step(f"cell {job.cell.label(labels)}")
        finish(row)


def run_processes(jobs: list[CellJob], finish: Finish, *, workers: int) -> None:
    """``workers`` cells at once in local processes (spawned: torch and fork do not mix)."""
    pool = ProcessPoolExecutor(max_workers=workers, initializer=ignore_interrupts,
                               mp_context=multiprocessing.get_context("spawn"))
    try:
        futures = {pool.submit(run_cell, job): job for job in jobs}
        for fut in as_completed(futures):
            finish(_row(fut, futures[fut]))
    except BaseException:  # Ctrl-C or a failing finish(): do not wait for the queue
        stop_workers(pool)  # Ctrl-C is the parent's: it ends the workers, whose running
        # cells are lost (a resumed run trains them again); finished cells are stored
        raise
    pool.shutdown()


#: Seconds to wait for a dask scheduler to answer before saying it cannot be reached.
SCHEDULER_TIMEOUT_S = 15


def _connect(client_class: Any, scheduler: str) -> Any:
    """A client of the scheduler at ``scheduler``; one line (an :class:`InputError`) when
    it cannot be reached (nothing listens there, a wrong host, a firewall), not a
    traceback."""
    try:
        return client_class(scheduler, timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:  # distributed raises OSError on a timeout
        text = " ".join(str(exc).split())[:160]
        raise InputError(f"--scheduler {scheduler}: the dask scheduler cannot be reached "
                         f"({type(exc).__name__}: {text}); start it, or check the "
                         f"address") from None


def run_dask(jobs: list[CellJob], finish: Finish, *, workers: int,
             scheduler: str | None) -> None:
    """Cells on a dask cluster: the one at ``scheduler``, else a local one of ``workers``
    single-threaded processes bound to 127.0.0.1."""
    from distributed import Client, LocalCluster
    from distributed import as_completed as dask_completed

    if scheduler:
        client = _connect(Client, scheduler)
        cluster = None
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None)
        client = Client(cluster)
    try:
        futures = client.map(run_cell, jobs, pure=False)
        by_key = {fut.key: job for fut, job in zip(futures, jobs)}
        for fut in dask_completed(futures):
            finish(_row(fut, by_key[fut.key]))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _row(future: Any, job: CellJob) -> dict[str, Any]:
    """The future's row; a failed row when the worker could not return one."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 — the worker died (BrokenProcessPool, KilledWorker)
        return failed_row(job, exc)
