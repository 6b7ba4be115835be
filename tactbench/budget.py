"""The memory budget: a step that allocates in proportion to its inputs asks first.

A step that allocates in proportion to its inputs (images × frames, windows × L,
ids × rows) first asks :func:`check_budget` with its estimate; an estimate above the
budget is refused in one line naming the step, the estimate and how to raise the budget
(``TACTBENCH_MEMORY_MIB``; by default half this machine's memory).
"""

from __future__ import annotations

import os
import re

from tactbench.errors import BudgetError, InputError
from tactbench.machine import memory_bytes

#: Environment variable that sets the memory budget, in MiB.
BUDGET_ENV = "TACTBENCH_MEMORY_MIB"


def memory_budget_bytes() -> int:
    """The budget for one step: ``TACTBENCH_MEMORY_MIB`` or half this machine's memory."""
    text = os.environ.get(BUDGET_ENV)
    if text is None or text == "":
        return memory_bytes() // 2
    try:
        mib = float(text)
    except ValueError:
        mib = -1.0
    if not mib > 0 or mib != mib or mib == float("inf"):
        raise InputError(f"{BUDGET_ENV} must be a positive number of MiB, got {text!r}")
    return int(mib * (1 << 20))


def human_bytes(n: float) -> str:
    """``n`` bytes as people read them: ``"512 B"``, ``"1.5 GiB"``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} PiB"  # pragma: no cover


#: Units of :func:`parse_bytes`: decimal (kB = 1000 B) and binary (KiB = 1024 B).
_BYTE_UNITS = {"": 1, "b": 1, "kb": 10 ** 3, "mb": 10 ** 6, "gb": 10 ** 9, "tb": 10 ** 12,
               "k": 2 ** 10, "kib": 2 ** 10, "m": 2 ** 20, "mib": 2 ** 20, "g": 2 ** 30,
               "gib": 2 ** 30, "t": 2 ** 40, "tib": 2 ** 40}
_SIZE = re.compile(r"(\d{1,15}(?:\.\d+)?)\s*([a-z]*)")


def parse_bytes(text: str, what: str) -> int:
    """Bytes of a size as people write it: ``"20GB"`` (10⁹), ``"500MiB"`` (2²⁰), ``"1.5 G"``
    (a bare letter is binary, as ``du -h`` prints it), ``"0"``; ``what`` names the option in
    the one-line error for anything else."""
    m = _SIZE.fullmatch(str(text).strip().lower())
    if not m or m.group(2) not in _BYTE_UNITS:
        raise InputError(f"{what} must be a size such as 20GB, 500MiB or 0, got {text!r}")
    return int(float(m.group(1)) * _BYTE_UNITS[m.group(2)])


def check_budget(nbytes: float, what: str, *, budget: int | None = None) -> None:
    """Refuse a step whose estimated memory ``nbytes`` exceeds the budget.

    ``what`` names the step and its inputs, e.g. ``"imaging 1900 samples at 0.01 mm
    (35700×33400 px)"``. Raises :class:`BudgetError` (a :class:`TactbenchError`).
    """
    limit = memory_budget_bytes() if budget is None else budget
    if nbytes > limit:
        raise BudgetError(f"{what} would need about {human_bytes(nbytes)}, more than the "
                          f"memory budget of {human_bytes(limit)}; set {BUDGET_ENV} to "
                          f"raise it")
