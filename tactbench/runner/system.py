"""Facts about where a cell ran: library versions, peak memory, host, time, git revision."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path


def now() -> str:
    """Local time as ISO 8601 with its UTC offset, to the second."""
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


def host() -> str:
    """This machine's network name ("" where the OS does not say)."""
    return os.uname().nodename if hasattr(os, "uname") else ""


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, in MiB (NaN on Windows)."""
    try:
        import resource

        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        # Linux reports KiB, macOS bytes
        return rss / 1024.0 if sys.platform != "darwin" else rss / 2 ** 20
    except ImportError:  # Windows
        return float("nan")


def versions() -> dict[str, str]:
    """Versions of tactbench, Python, numpy, and of torch, cv2, kornia when imported."""
    import numpy

    import tactbench

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
    import subprocess

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
