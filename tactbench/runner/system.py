"""Facts about where a cell ran: library versions, memory, host, time, git revision."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import tactbench
from tactbench.errors import InputError

try:
    import resource
except ImportError:  # Windows
    resource = None


def now() -> str:
    """Local time as ISO 8601 with its UTC offset, to the second."""
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


def host() -> str:
    """This machine's network name ("" where the OS does not say)."""
    return os.uname().nodename if hasattr(os, "uname") else ""


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, in MiB (NaN on Windows)."""
    if resource is None:  # Windows
        return float("nan")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # Linux reports KiB, macOS bytes
    return rss / 1024.0 if sys.platform != "darwin" else rss / 2 ** 20


def _status_mb(field_name: str) -> float | None:
    """A ``kB`` field of ``/proc/self/status`` (Linux) in MiB; None where there is none."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith(field_name + ":"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


def current_rss_mb() -> float:
    """Resident memory of this process now, in MiB (``VmRSS``; NaN where the OS
    does not say)."""
    value = _status_mb("VmRSS")
    return float("nan") if value is None else value


def memory_mb() -> tuple[float, float]:
    """``(current, peak)`` resident memory of this process in MiB: ``VmRSS`` and the
    larger of ``VmHWM`` and ``ru_maxrss`` (they agree unless something reset the
    high-water mark)."""
    hwm = _status_mb("VmHWM")
    peak = peak_rss_mb()
    if hwm is not None and not (hwm <= peak):
        peak = hwm
    return current_rss_mb(), peak


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


def versions() -> dict[str, str]:
    """Versions of tactbench, Python, numpy, and of torch, cv2, kornia when imported."""
    import numpy

    out = {"tactbench": tactbench.__version__, "python": sys.version.split()[0],
           "numpy": numpy.__version__}
    # Only what this process has imported: importing them here would cost seconds.
    for name in ("torch", "cv2", "kornia"):
        module = sys.modules.get(name)
        if module is not None:
            out[name] = getattr(module, "__version__", "?")
    return out


def git_revision() -> str | None:
    """The checkout's commit (with ``+dirty``), when tactbench runs from one."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return None
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"],
                             capture_output=True, text=True, timeout=5).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain",
                                "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return (rev + ("+dirty" if dirty else "")) or None


def ignore_interrupts() -> None:
    """In a worker process: leave Ctrl-C (SIGINT, sent to the whole process group) to the
    parent, which stops the workers itself (:func:`stop_workers`); a worker would
    otherwise print its own traceback of the interrupt."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def stop_workers(pool) -> None:
    """Stop a ``ProcessPoolExecutor`` now: drop its queue and end its workers, so that
    the interpreter does not wait for running cells on its way out."""
    pool.shutdown(wait=False, cancel_futures=True)
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        if process.is_alive():
            process.terminate()


# ----------------------------------------------------------- which CPU kernels computed

def describe_machines(rows) -> str:
    """The machines that computed ``rows``, for a report: ``AMD EPYC 7B13 (torch CPU
    kernels AVX2)``, each distinct one once; results are bit-identical only on one of
    them at one thread count (docs/reliability.md, "Numbers across machines")."""
    seen: dict[str, None] = {}
    for row in rows:
        facts = row.get("machine") if isinstance(row, dict) else None
        if not isinstance(facts, dict):
            seen.setdefault("not recorded (rows from before machines were recorded)")
            continue
        text = str(facts.get("cpu") or "unknown CPU")
        extra = [f"torch CPU kernels {facts['cpu_kernels']}"] if facts.get("cpu_kernels") \
            else []
        pinned = facts.get("pinned")
        if isinstance(pinned, dict) and pinned:
            extra.append("pinned: " + ", ".join(f"{k}={v}" for k, v in sorted(pinned.items())))
        seen.setdefault(text + (f" ({'; '.join(extra)})" if extra else ""))
    return "; ".join(seen) if seen else "none"


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
