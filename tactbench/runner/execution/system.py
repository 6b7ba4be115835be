"""What a run does with its processes: time stamps, which step set a cell's memory peak,
worker processes, the dask scheduler's address. Facts about the machine itself (CPU,
memory, host, versions, git revision) are :mod:`tactbench.machine`."""

from __future__ import annotations

import ast
import ctypes
import multiprocessing
import os
import re
import signal
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator

from tactbench.errors import InputError
from tactbench.machine import memory_mb


def now() -> str:
    """Local time as ISO 8601 with its UTC offset, to the second."""
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


#: The step a peak reached before the tracker started is attributed to.
BEFORE = "before this cell"


@dataclass
class MemoryTracker:
    """Which step of a piece of work set the process's peak resident memory.

    Call :meth:`step` at the end of each named step; the peak is read then (it only
    grows), so the step whose end first shows the final peak is the one that set it.
    A peak already reached when the tracker was made (by earlier work in the same
    process: a serial run's encoding, an earlier cell of the same worker) is
    attributed to :data:`BEFORE`::

        mem = MemoryTracker()
        ...; mem.step("load encoding")
        with mem.track("fit"):
            ...
        mem.peak_mb, mem.peak_step   # e.g. 812.4, "fit"
    """

    #: ``(name, current MiB, peak MiB)`` at the end of each step, the start first
    steps: list[tuple[str, float, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.steps:
            self.steps.append((BEFORE, *memory_mb()))

    def step(self, name: str) -> float:
        """Record the end of step ``name``; returns the peak so far (MiB)."""
        current, peak = memory_mb()
        previous = self.steps[-1][2]
        if previous >= peak:  # the sources disagree by a page now and then: keep it monotone
            peak = previous
        self.steps.append((name, current, peak))
        return peak

    @contextmanager
    def track(self, name: str) -> Iterator[None]:
        """``with mem.track("fit"): ...``: :meth:`step` at the end, raised or not."""
        try:
            yield
        finally:
            self.step(name)

    @property
    def peak_mb(self) -> float:
        return self.steps[-1][2]

    @property
    def peak_step(self) -> str:
        """The first step at whose end the final peak was reached."""
        final = self.peak_mb
        for name, _current, peak in self.steps:
            if peak >= final:
                return name
        return self.steps[-1][0]  # NaN peaks (Windows): the last step

    def as_dict(self) -> dict[str, dict[str, float]]:
        """``{step: {"rss_mb": current, "peak_mb": peak}}`` in order (JSON-ready)."""
        return {name: {"rss_mb": current, "peak_mb": peak}
                for name, current, peak in self.steps}


def _main_frame():
    """The frame running the main module's top-level code, when this call is within it
    (None: the main module has finished, or this runs on another thread)."""
    main = sys.modules.get("__main__")
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "<module>" and frame.f_globals is vars(main):
            return frame
        frame = frame.f_back
    return None


def _under_main_guard(source: str, line: int) -> bool:
    """Whether ``line`` of the module ``source`` lies in the body of a top-level
    ``if __name__ == "__main__":``."""
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return False
    for node in tree.body:
        if not isinstance(node, ast.If) or not isinstance(node.test, ast.Compare):
            continue
        names = [node.test.left, *node.test.comparators]
        guard = len(names) == 2 and isinstance(node.test.ops[0], ast.Eq) and \
            {ast.dump(n) for n in names} == {ast.dump(ast.Name("__name__", ast.Load())),
                                             ast.dump(ast.Constant("__main__"))}
        if guard and node.body[0].lineno <= line <= (node.body[-1].end_lineno or line):
            return True
    return False


def main_reimport_problem() -> str | None:
    """Why a spawned worker process cannot start from this process's main module, or
    None when it can. A spawned worker imports the main module again (as
    ``__mp_main__``): a script read from standard input cannot be read again, and one
    that calls tactbench at its top level outside ``if __name__ == "__main__":`` would
    run again in every worker. A notebook, ``python -c`` or a prompt is not imported
    again; a call from a function or a guarded block is safe."""
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    name = spec.name if spec is not None else None  # a ModuleSpec always has one
    if name is not None and (name == "__main__" or name.endswith(".__main__")):
        return None  # a package's __main__ (python -m tactbench): never imported again
    path = getattr(spec, "origin", None) or getattr(main, "__file__", None)
    if path is None or os.path.splitext(os.path.basename(path))[0] == "ipython":
        return None  # nothing to import again (the ipython launcher: skipped too)
    if not os.path.isfile(path):
        return (f"the main program was read from {path} (standard input?), which a "
                f"worker process cannot read again; save it to a file, with the call "
                f"under `if __name__ == \"__main__\":`, to run cells side by side")
    frame = _main_frame()
    if frame is None:
        return None
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            source = f.read()
    except OSError:
        source = ""
    if _under_main_guard(source, frame.f_lineno):
        return None
    return (f"{path} calls tactbench at its top level, outside `if __name__ == "
            f"\"__main__\":`, so every worker process would run it again; put the call "
            f"under that guard to run cells side by side")


#: Seconds a worker whose run has died has to clean up (its temporaries) before it ends.
ENDING_GRACE_S = 2.0
#: ``prctl`` option: the signal a process gets when its parent dies (Linux).
_PR_SET_PDEATHSIG = 1


def start_worker() -> None:
    """Initializer of a local worker process: Ctrl-C is the parent's
    (:func:`ignore_interrupts`), and the worker ends soon after its parent dies
    (:func:`end_with_parent`)."""
    ignore_interrupts()
    end_with_parent()


def _ending(signum: int, frame: object) -> None:
    """SIGTERM in a worker (its parent died, or stopped it): unwind, so that what is
    being written removes its temporary, and end within :data:`ENDING_GRACE_S` however
    the unwinding goes (a pool's worker loop catches the exit and would wait on)."""
    # ignore those that follow: the parent-death signal comes again each time the dying
    # parent's threads end one by one (the kernel re-parents the worker to each)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    timer = threading.Timer(ENDING_GRACE_S, os._exit, (128 + signum,))
    timer.daemon = True
    timer.start()
    raise SystemExit(128 + signum)


def _watch_parent(parent: int) -> None:
    """Where no parent-death signal exists: SIGTERM to this process once its parent is
    gone (it is then a child of another process)."""
    while os.getppid() == parent:
        time.sleep(0.5)
    os.kill(os.getpid(), signal.SIGTERM)


def end_with_parent() -> None:
    """Make this (worker) process end soon after its parent dies, however it dies (the
    out-of-memory killer, ``kill -9``, a scheduler's preemption), instead of living on
    under init with its memory: SIGTERM on the parent's death (Linux ``prctl
    PR_SET_PDEATHSIG``; elsewhere a thread watching the parent), handled by unwinding
    (temporaries removed) and ending."""
    parent_process = multiprocessing.parent_process()
    parent = parent_process.pid if parent_process is not None else os.getppid()
    signal.signal(signal.SIGTERM, _ending)
    armed = False
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if not armed:
        threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                         name="tactbench-parent-watch").start()
    if os.getppid() != parent:  # it died before the signal was asked for
        os.kill(os.getpid(), signal.SIGTERM)


def ignore_interrupts() -> None:
    """In a worker process: leave Ctrl-C (SIGINT, sent to the whole process group) to the
    parent, which stops the workers itself (:func:`stop_workers`); a worker would
    otherwise print its own traceback of the interrupt."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def stop_workers(pool) -> None:
    """Stop a ``ProcessPoolExecutor`` now: drop its queue and end its workers, so that
    the interpreter does not wait for running cells on its way out."""
    if hasattr(pool, "terminate_workers"):  # Python ≥ 3.14 says it publicly
        pool.terminate_workers()
        return
    # before shutdown(), which forgets its processes: without them, the interpreter's
    # exit would join the pool's manager thread, which waits for every running cell
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()


def check_scheduler(address: str) -> str:
    """A dask scheduler address as dask takes it (``tcp://host:port``, ``host:port``,
    ``tls://...``), checked before any work: dask's own error comes after the encoding,
    as a traceback."""
    text = str(address).strip()
    if not re.fullmatch(r"(?:(?:tcp|tls|ws|wss|ucx|inproc)://)?[A-Za-z0-9_.\-\[\]:]+:\d{1,5}/?",
                        text):
        raise InputError(f"--scheduler {address!r} is not a dask scheduler address; give "
                         f"tcp://HOST:PORT (e.g. tcp://10.0.0.5:8786)")
    return text
