"""Where cells run: in turn in this process, in local worker processes, or on dask.

By default as many cells run side by side as the machine's cores, GPUs and memory allow,
one torch thread each (:func:`~tactbench.runner.execution.workers.run_workers`): the thread
count is part of a cell's identity, so parallelism comes from cells, not threads. Spawned workers
inherit the pinned CPU kernels (:func:`~tactbench.machine.pin_cpu_kernels`) from this
process's environment.

Each executor calls ``finish(row)`` in this process as soon as a cell's row is back, in
the order cells finish. A cell never raises here (:func:`~tactbench.runner.execution.cell.run_cell`
returns a failed row instead). Local worker processes that cannot start (a script's main
module that cannot be imported again) or one that dies (killed for memory, a crashed
interpreter) stop the run with a :class:`~tactbench.errors.WorkerError` naming the cause
and the fix, the finished cells stored; a script that calls tactbench at its top level
without ``if __name__ == "__main__":``, or one read from standard input, runs its cells in
this process instead, said in one warning line (:func:`~tactbench.runner.execution.system.main_reimport_problem`).
A local worker ends soon after its parent dies, however it dies
(:func:`~tactbench.runner.execution.system.end_with_parent`), removing what it was writing.
On dask, a worker that dies gives its cell a failed row. Ctrl-C stops at once: cells not started are
dropped, finished ones were already handed to ``finish``.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
import logging
import multiprocessing
import os
import pickle
import sys
import time
from typing import TYPE_CHECKING, Any, Callable, Iterable

from tactbench.errors import InputError, WorkerError
from tactbench.runner.execution.cell import CellJob, failed_row, run_cell
from tactbench.runner.execution.devices import own_device, start_owning
from tactbench.runner.execution.questions import spec_labels
from tactbench.runner.execution.system import (BEFORE, MemoryTracker, main_reimport_problem,
                                               start_worker, stop_workers)
from tactbench.runner.execution.workers import Workers

if TYPE_CHECKING:
    from tactbench.runner.execution.scene import Scene
    from tactbench.ui import Progress

Finish = Callable[[dict[str, Any]], None]

log = logging.getLogger("tactbench.runner.execution.executors")


def execute(scene: "Scene", jobs: list[CellJob], finish: Finish, bars: "Progress",
            memory: "MemoryTracker | None", workers: "Workers") -> None:
    """Run ``jobs`` on the scene's executor, with an overall bar in ``bars``, on
    ``workers`` (the run's record's, decided once by
    :func:`~tactbench.runner.execution.workers.run_workers`); ``memory`` has the run's
    steps so far in this process (see :func:`run_serial`)."""
    overall = bars.add("cells", total=len(jobs))
    done = 0

    def finished(row: dict[str, Any]) -> None:
        nonlocal done
        finish(row)
        done += 1
        bars.update(overall, done)

    decided = workers
    workers, devices = decided.count, decided.devices
    problem = main_reimport_problem()  # before the bootstrapping of a spawned worker
    if scene.executor == "dask":
        if problem and not scene.scheduler:  # a local cluster spawns its workers too
            raise InputError(f"the local dask cluster cannot start its workers: {problem} "
                             f"(or give --scheduler)")
        run_dask(jobs, finished, workers=workers, scheduler=scene.scheduler,
                 devices=None if devices is None else list(devices))
    elif min(workers, len(jobs)) == 1:
        run_serial(jobs, finished, bars, memory)
    elif problem or (problem := unsendable_problem(jobs)):  # a job no worker could take
        log.warning("tactbench: warning: the %d cells run one at a time in this process, "
                    "not %d at once: %s", len(jobs), min(workers, len(jobs)), problem)
        run_serial(jobs, finished, bars, memory)
    else:
        run_processes(jobs, finished, workers=min(workers, len(jobs)),
                      devices=None if devices is None else list(devices))


def unsendable_problem(jobs: Iterable[CellJob]) -> str | None:
    """Why a job cannot go to a spawned worker process, or None: it does not pickle, or
    it names an object of a main module the worker cannot import (a class or function
    defined in a notebook, at a prompt or in ``python -c``: a worker imports a main
    module only from its file)."""
    main_file = getattr(sys.modules.get("__main__"), "__file__", None)
    for job in jobs:
        try:
            data = pickle.dumps(job)
        except Exception as exc:  # noqa: BLE001 — what cannot be pickled varies
            return (f"cell {job.cell.label()} cannot be sent to a worker process "
                    f"({type(exc).__name__}: {str(exc)[:120]}); a component that pickles "
                    f"(defined in a module) runs in workers")
        if main_file is None and b"__main__" in data:
            return (f"cell {job.cell.label()} uses something defined in this notebook or "
                    f"prompt, which a worker process cannot import; define it in a module "
                    f"to run cells side by side")
    return None


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


def _start_local_worker(devices: Any) -> None:
    """Initializer of a local worker: :func:`start_worker`, then the next device of the
    run's queue ``devices`` is this worker's own (none for CPU workers)."""
    start_worker()
    start_owning(devices)


def run_processes(jobs: list[CellJob], finish: Finish, *, workers: int,
                  devices: list[str] | None = None) -> None:
    """``workers`` cells at once in local processes (spawned: torch and fork do not mix),
    each owning one of ``devices`` (one each: never more workers than devices) where
    given."""
    context = multiprocessing.get_context("spawn")
    queue = None
    if devices is not None:
        if workers > len(devices):
            raise ValueError(f"{workers} workers for {len(devices)} devices")
        queue = context.Queue()
        for device in devices[:workers]:
            queue.put(device)
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_start_local_worker,
                               initargs=(queue,), mp_context=context)
    stored = 0
    try:
        probe = pool.submit(os.getpid)  # one worker started, before any cell is sent
        started = dict(getattr(pool, "_processes", None) or {})  # known after a break
        try:
            probe.result()
        except BrokenProcessPool:
            raise WorkerError(f"worker processes cannot start here ({_deaths(started)}); "
                              f"the worker's own error, if any, is printed above; run with workers=1 (--workers "
                              f"1) to compute the cells in this process") from None
        futures = {pool.submit(run_cell, job): job for job in jobs}
        started.update(getattr(pool, "_processes", None) or {})
        for fut in as_completed(futures):
            if isinstance(fut.exception(), BrokenProcessPool):
                raise WorkerError(
                    f"a worker process died while cells ran ({_deaths(started)}); the "
                    f"{stored} cell(s) finished are stored, {len(jobs) - stored} are not: "
                    f"run again to compute them, with fewer workers (--workers) or more "
                    f"memory if it was killed for memory") from None
            finish(_row(fut, futures[fut]))
            stored += 1
    except BaseException:  # Ctrl-C or a failing finish(): do not wait for the queue
        stop_workers(pool)  # Ctrl-C is the parent's: it ends the workers, whose running
        # cells are lost (a resumed run trains them again); finished cells are stored
        raise
    pool.shutdown()


def _deaths(processes: dict[int, Any]) -> str:
    """How a pool's worker ``processes`` (pid → process) ended, as far as it can be told."""
    deadline = time.monotonic() + 2
    for p in processes.values():  # a dead worker's status is known once it is reaped
        # (by the pool's own thread, maybe: then it shows once that thread has it)
        while p.exitcode is None and time.monotonic() < deadline:
            p.join(timeout=0.05)
    codes = sorted({p.exitcode for p in processes.values() if p.exitcode not in (None, 0)})
    said = [f"killed by signal {-c}" + (" (SIGKILL: the out-of-memory killer?)" if c == -9
                                        else "") if c < 0 else f"exit status {c}"
            for c in codes]
    return "a worker " + ", ".join(said) if said else "a worker ended abruptly"


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


def _dask_cell(job: CellJob, devices: list[str] | None) -> dict[str, Any]:
    """:func:`run_cell` in a worker of the run's local dask cluster, on the device of
    ``devices`` that the worker owns (its name is its place: 0, 1 ...)."""
    if devices:
        from distributed import get_worker

        name = get_worker().name
        own_device(devices[name % len(devices)] if isinstance(name, int) else None)
    return run_cell(job)


def run_dask(jobs: list[CellJob], finish: Finish, *, workers: int,
             scheduler: str | None, devices: list[str] | None = None) -> None:
    """Cells on a dask cluster: the one at ``scheduler`` (each of its workers computes on
    the device its cluster gave it: start one per GPU), else a local one of ``workers``
    single-threaded processes bound to 127.0.0.1, each owning one of ``devices`` where
    given."""
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
        futures = client.map(_dask_cell, jobs, devices=devices, pure=False)
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
