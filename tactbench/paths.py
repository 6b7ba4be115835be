"""Where tactbench keeps files it can recompute (caches) by default."""

from __future__ import annotations

import os
from pathlib import Path

CACHE_ENV = "TACTBENCH_CACHE"


def cache_dir(*parts: str) -> Path:
    """``$TACTBENCH_CACHE`` or ``~/.cache/tactbench`` (``$XDG_CACHE_HOME`` respected), joined
    with ``parts``; created on first use."""
    root = os.environ.get(CACHE_ENV)
    if root:
        base = Path(root)
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = (Path(xdg) if xdg else Path.home() / ".cache") / "tactbench"
    path = base.joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path
