"""Facts about the machine, in one place: what a result was computed on and with.

The processor (:func:`cpu_model`, :func:`usable_cores`), its memory
(:func:`memory_bytes`) and this process's (:func:`memory_mb`), the GPU, the host, the
library versions and the checkout's git revision; :func:`machine`, the facts every row
records, and :func:`describe_machines`, how a report names them (the kernels themselves
are pinned by :mod:`tactbench.kernels`). Light on purpose (standard library only at
import).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterable

import tactbench
from tactbench.kernels import KERNELS_ENV, KERNEL_VARIABLES, cpu_model, torch_kernels

try:
    import resource
except ImportError:  # Windows
    resource = None


def usable_cores() -> int:
    """The cores this process may use (its CPU affinity where the OS tells it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def machine() -> dict[str, object]:
    """What decides a cell's floating-point results besides its identity: the CPU model,
    the instruction set torch's CPU kernels use (``torch.backends.cpu
    .get_cpu_capability()``, when torch is imported), and the variables that pin the
    kernels (see :func:`pin_cpu_kernels`). Recorded in every row and the report."""
    out: dict[str, object] = {"cpu": cpu_model(), "cores": os.cpu_count() or 0}
    kernels = torch_kernels()
    if kernels is not None:
        out["cpu_kernels"] = kernels
    pinned = {name: os.environ[name] for name in (KERNELS_ENV, *KERNEL_VARIABLES)
              if os.environ.get(name)}
    if pinned:
        out["pinned"] = pinned
    return out


def describe_machines(rows) -> str:
    """The machines that computed ``rows`` (their :func:`machine` facts), for a report:
    ``AMD EPYC 7B13 (torch CPU kernels AVX2)``, each distinct one once; results are
    bit-identical only on one of them at one thread count (docs/reliability.md, "Numbers
    across machines")."""
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


# ------------------------------------------------------------------------ memory

def memory_bytes() -> int:
    """Physical memory of this machine (bytes), or 8 GiB when it cannot be read."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 8 << 30


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


# ------------------------------------------------------- host, GPU, software, checkout

def host() -> str:
    """This machine's network name ("" where the OS does not say)."""
    return os.uname().nodename if hasattr(os, "uname") else ""


def operating_system() -> str:
    """The operating system and its release, as ``platform.platform()`` gives them."""
    return platform.platform()


def gpu_name() -> str:
    """The first CUDA device's name, or ``"none"`` (no torch, or no GPU). Imports torch."""
    try:
        import torch

        return torch.cuda.get_device_name(0) if torch.cuda.is_available() else "none"
    except Exception:  # noqa: BLE001 — no torch, or a broken CUDA: no GPU to use
        return "none"


def versions(libraries: Iterable[str] = ("torch", "cv2", "kornia"), *,
             load: bool = False) -> dict[str, str]:
    """Versions of tactbench, Python, numpy, and of ``libraries``: those this process has
    imported (importing them here would cost seconds), or, with ``load``, every one that
    imports (one that does not is left out)."""
    import numpy

    out = {"tactbench": tactbench.__version__, "python": sys.version.split()[0],
           "numpy": numpy.__version__}
    for name in libraries:
        module = sys.modules.get(name)
        if module is None and load:
            try:
                module = __import__(name)
            except Exception:  # noqa: BLE001 — a missing optional library is not listed
                continue
        if module is not None:
            out[name] = getattr(module, "__version__", "?")
    return out


def git_revision(*, short: bool = False) -> str | None:
    """The checkout's commit (with ``+dirty``; ``short``: the abbreviated commit alone),
    when tactbench runs from one."""
    root = Path(__file__).resolve().parents[1]
    if not (root / ".git").exists():
        return None
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse",
                              *(["--short"] if short else []), "HEAD"],
                             capture_output=True, text=True, timeout=5).stdout.strip()
        if short:
            return rev or None
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain",
                                "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return (rev + ("+dirty" if dirty else "")) or None


def benchmark_meta(script: str, argv: Iterable[str], *, private: Iterable[str] = ("--work",)
                   ) -> dict[str, str]:
    """What a benchmark records of its run: ``command`` (``python SCRIPT ARGS``, less each
    option in ``private`` and its value: a scratch folder says nothing of the numbers),
    ``machine`` (architecture, cores, Python) and ``date`` (UTC)."""
    hidden, given, shown = set(private), list(argv), [f"python {script}"]
    while given:
        arg = given.pop(0)
        if arg in hidden:
            given = given[1:]
        elif arg.split("=", 1)[0] not in hidden:
            shown.append(arg)
    return {"command": " ".join(shown),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores, "
                       f"{platform.python_implementation()} {platform.python_version()}",
            "date": datetime.now(timezone.utc).strftime("%Y-%m-%d")}
