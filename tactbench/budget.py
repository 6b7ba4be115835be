"""The memory budget: a step that allocates in proportion to its inputs asks first.

A step that allocates in proportion to its inputs (images × frames, windows × L,
ids × rows) first asks :func:`check_budget` with its estimate; an estimate above the
budget is refused in one line naming the step, the estimate and how to raise the budget
(``TACTBENCH_MEMORY_MIB``; by default half this machine's memory).
"""

from __future__ import annotations

import os

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
