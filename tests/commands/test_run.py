"""``tactbench run``: the grid from options and a scene file, JSON output, exit status."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from tactbench.cli import cli

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY_DATASET = "synthetic-forearm:users=2,repetitions=1"
TINY_CLF = "small-cnn-lstm:epochs=1,windows_per_epoch=64,batch_size=16,input_size=16"

#: An installed-looking plugin whose classifier raises in fit while TACTBENCH_TEST_FAIL=1.
FAILING_PLUGIN = '''
import os

from tactbench import hookimpl
from tactbench.classifiers.classical import PooledLogReg


class Failing(PooledLogReg):
    name = "failing"

    def fit(self, train, val=None, **kwargs):
        if os.environ.get("TACTBENCH_TEST_FAIL") == "1":
            raise RuntimeError("deliberate failure in fit")
        return super().fit(train, val, **kwargs)


@hookimpl
def register_classifiers(register):
    register("failing", "failing_plugin:Failing", summary="fails in fit on demand")
'''


def test_run_from_options_and_a_scene_file_prints_json(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    args = ["run", "--dataset", TINY_DATASET, "--encoder", "raw", "--classifier", TINY_CLF,
            "-L", "2", "--seed", "0", "--pixel-mm", "10", "--threads", "1",
            "--out", str(tmp_path / "out"), "--json", "--no-plots", str(scene)]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["meta"]["computed"] == 1 and doc["summary"][0]["L"] == 2
    assert doc["failed"] == []


def test_a_typo_is_one_line_and_exit_2(tmp_path):
    bad = CliRunner().invoke(cli, ["run", "--encoder", "farnebak", "--out",
                                   str(tmp_path / "o2")])
    assert bad.exit_code == 2 and "did you mean 'farneback'" in bad.output
    assert "Traceback" not in bad.output and not (tmp_path / "o2").exists()


def test_a_failing_cell_is_reported_and_the_command_exits_1(tmp_path, monkeypatch,
                                                           plugin_dist):
    plugin_dist("tactbench-failing", "failing_plugin", FAILING_PLUGIN)
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("TACTBENCH_TEST_FAIL", "1")
    out = tmp_path / "out"
    args = ["run", "--dataset", TINY_DATASET, "--encoder", "raw",
            "--classifier", "logreg:max_iter=20", "--classifier", "failing", "-L", "3",
            "--seed", "0", "--pixel-mm", "10", "--threads", "1", "--out", str(out),
            "--no-plots"]
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    first = CliRunner().invoke(cli, [*args, str(scene)], catch_exceptions=False)
    assert first.exit_code == 1, first.output
    assert "2 cell(s) computed" in first.stdout  # the other cell ran and is in the table
    (line,) = [x for x in first.stderr.splitlines() if x.startswith("failed:")]
    assert "raw × failing L=3 seed=0: RuntimeError: deliberate failure in fit" in line
    assert str(out / "cells") in line
    assert "1 cell(s) failed" in first.stderr
    assert "## Failed cells" in (out / "report.md").read_text()

    monkeypatch.delenv("TACTBENCH_TEST_FAIL")
    second = CliRunner().invoke(cli, [*args, "--json", str(scene)], catch_exceptions=False)
    assert second.exit_code == 0, second.output
    doc = json.loads(second.stdout)
    assert (doc["meta"]["computed"], doc["meta"]["skipped"]) == (1, 1)  # only the failed one
    assert doc["failed"] == [] and len(doc["summary"]) == 2
