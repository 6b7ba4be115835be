"""The memory budget: a step above it is refused in one line naming how to raise it."""

from __future__ import annotations

import pytest

from tactbench.budget import check_budget, human_bytes, memory_budget_bytes
from tactbench.errors import BudgetError, InputError


def test_the_budget_refuses_in_one_line_naming_the_variable(monkeypatch):
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "1")
    assert memory_budget_bytes() == 1 << 20
    check_budget(1 << 20, "a step")
    with pytest.raises(BudgetError, match=r"a step would need about 2\.0 MiB, more than the "
                                          r"memory budget of 1\.0 MiB; set TACTBENCH_MEMORY_MIB"):
        check_budget(2 << 20, "a step")
    for bad in ("0", "-3", "nan", "inf", "lots"):
        monkeypatch.setenv("TACTBENCH_MEMORY_MIB", bad)
        with pytest.raises(InputError, match="TACTBENCH_MEMORY_MIB must be a positive number"):
            memory_budget_bytes()


def test_sizes_read_as_people_read_them():
    assert human_bytes(512) == "512 B"
    assert human_bytes(1536) == "1.5 KiB"
    assert human_bytes(3 << 30) == "3.0 GiB"
