"""docs/own-data.md: its worked example runs as written, and its numbers agree."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "own-data.md"


def blocks(kind: str) -> list[str]:
    return re.findall(rf"```{kind}\n(.*?)```", DOC.read_text(), re.S)


@pytest.mark.slow("runs the own-data page's worked example as written: several tactbench commands that train")
def test_the_worked_example_runs_as_written(tmp_path):
    script = blocks("python")[0]
    name = re.match(r"# (\S+\.py)\n", script).group(1)
    (tmp_path / name).write_text(script)
    commands = [line[2:] for block in blocks("console") for line in block.splitlines()
                if line.startswith("$ ")]
    assert commands[0] == f"python {name}" and len(commands) >= 6
    env = dict(os.environ, TACTBENCH_CACHE=str(tmp_path / "cache"), OMP_NUM_THREADS="1")
    for command in commands:
        argv = shlex.split(command)
        argv = ([sys.executable, *argv[1:]] if argv[0] == "python"
                else [sys.executable, "-m", "tactbench", *argv[1:]])
        done = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0, f"{command}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        assert "Error" not in done.stderr, f"{command}\n{done.stderr[-2000:]}"

    def results(out: str) -> dict:
        return json.loads((tmp_path / out / "results.json").read_text())

    direct, imported = results("mat-results"), results("mat-results-imported")
    assert {r["encoder"] for r in direct["summary"]} == {"raw", "farneback"}
    # the imported folder is the same data: the same cell gives the same accuracy
    acc = {r["encoder"]: r["accuracy_mean"] for r in direct["summary"]}
    assert imported["summary"][0]["accuracy_mean"] == pytest.approx(acc["farneback"])
    assert results("vector-results")["summary"][0]["classifier"].startswith("taxel-lstm")
    assert (tmp_path / "stroke.png").stat().st_size > 0


def test_the_option_table_lists_every_option_of_the_reader():
    import inspect

    from tactbench.datasets.folder import FolderDataset

    params = [p for p in inspect.signature(FolderDataset).parameters if p != "path"]
    table = DOC.read_text().split("## Options", 1)[1].split("##", 1)[0]
    listed = set(re.findall(r"^\| `(\w+)`(?:, `(\w+)`)?", table, re.M))
    names = {n for pair in listed for n in pair if n}
    assert names == set(params)
