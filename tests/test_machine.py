"""tactbench.machine, the one home of machine facts: what a report and a row record."""

from __future__ import annotations

import sys

from tactbench import __version__
from tactbench.machine import git_revision, gpu_name, memory_bytes, versions


def test_versions_list_what_is_imported_or_asked_to_load(monkeypatch):
    monkeypatch.delitem(sys.modules, "colorsys", raising=False)
    plain = versions(("colorsys", "no_such_module_here"))
    assert plain["tactbench"] == __version__ and "numpy" in plain
    assert "colorsys" not in plain and "no_such_module_here" not in plain
    loaded = versions(("colorsys", "no_such_module_here"), load=True)
    assert loaded["colorsys"] == "?"  # imported, without a __version__
    assert "no_such_module_here" not in loaded


def test_the_short_revision_starts_the_full_one():
    full, short = git_revision(), git_revision(short=True)
    if full is None:  # not run from a checkout
        assert short is None
        return
    assert full.startswith(short) and not short.endswith("+dirty")


def test_memory_and_gpu_are_told_plainly():
    assert memory_bytes() > 2 ** 20
    assert isinstance(gpu_name(), str) and gpu_name()


def test_a_benchmark_records_its_command_without_its_scratch_folder():
    from tactbench.machine import benchmark_meta

    meta = benchmark_meta("benchmarks/people.py",
                          ["--users", "4", "--work", "/tmp/w", "--work=/tmp/v", "--json", "x"])
    assert meta["command"] == "python benchmarks/people.py --users 4 --json x"
    assert "cores" in meta["machine"] and len(meta["date"]) == 10
