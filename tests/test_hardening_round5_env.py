"""Hardening, round five: hostile environment values and paths are one line each, before
anything is planned or rewritten (a run folder's results stay as they were)."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from tactbench.cli import cli


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run folder and the command that made it."""
    root = tmp_path_factory.mktemp("env")
    args = ["run", "--dataset", "synthetic-forearm:users=2,repetitions=1,positions=1",
            "--encoder", "raw", "--classifier", "logreg:max_iter=20", "-L", "3",
            "--seed", "0", "--pixel-mm", "15", "--workers", "1", "--out", str(root / "out")]
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TACTBENCH_CACHE", str(root / "cache"))
        done = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert done.exit_code == 0, done.output
    return root, args


HOSTILE = [
    ("TACTBENCH_BANK_MIB", "inf", "TACTBENCH_BANK_MIB must be a finite number"),
    ("TACTBENCH_BANK_MIB", "nan", "TACTBENCH_BANK_MIB must be a finite number"),
    ("TACTBENCH_BANK_MIB", "1e400", "TACTBENCH_BANK_MIB must be a finite number"),
    ("TACTBENCH_BANK_MIB", "-5", "TACTBENCH_BANK_MIB must be a finite number"),
    ("TACTBENCH_MEMORY_MIB", "inf", "TACTBENCH_MEMORY_MIB must be a positive number"),
    ("TACTBENCH_LOADER_WORKERS", "1000000", "TACTBENCH_LOADER_WORKERS must be ≤ 64"),
    ("TACTBENCH_LOADER_WORKERS", "two", "TACTBENCH_LOADER_WORKERS must be an integer"),
    ("TACTBENCH_CPU_KERNELS", "sse9", "TACTBENCH_CPU_KERNELS"),
    ("ATEN_CPU_CAPABILITY", "AVX-2", "ATEN_CPU_CAPABILITY='AVX-2' is not a level"),
    ("TACTBENCH_CACHE", "$TB_ROUND5_UNSET/c", "TB_ROUND5_UNSET, which is not set"),
    ("TACTBENCH_CACHE", "{file}", "cannot be used"),
    ("XDG_CACHE_HOME", "${{TB_ROUND5_UNSET}}", "TB_ROUND5_UNSET, which is not set"),
]


@pytest.mark.parametrize("name, value, says", HOSTILE)
def test_a_hostile_value_is_one_line_before_anything_is_rewritten(finished, monkeypatch,
                                                                   name, value, says):
    root, args = finished
    out = root / "out"
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    (root / "a-file").write_text("not a folder")
    monkeypatch.setenv("TACTBENCH_CACHE", str(root / "cache"))
    if name == "XDG_CACHE_HOME":
        monkeypatch.delenv("TACTBENCH_CACHE")
    monkeypatch.setenv(name, value.format(file=root / "a-file"))
    result = CliRunner().invoke(cli, [*args, "--rerun"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()  # a progress line may come first
    assert [line for line in lines if line.startswith("Error")] == [lines[-1]]
    assert says in lines[-1] and "Traceback" not in result.output
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_no_home_folder_is_one_line(monkeypatch):
    from pathlib import Path

    from tactbench.errors import InputError
    from tactbench.paths import cache_root

    for name in ("TACTBENCH_CACHE", "XDG_CACHE_HOME"):
        monkeypatch.delenv(name, raising=False)

    def no_home():
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", staticmethod(no_home))
    with pytest.raises(InputError, match="set TACTBENCH_CACHE to a folder"):
        cache_root()
