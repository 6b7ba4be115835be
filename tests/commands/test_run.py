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


# ------------------------------------------------------------- hardening (issue 11)


def _refused(tmp_path, monkeypatch, args, scene_text=None, scene_name="scene.toml"):
    """Run ``tactbench run`` with ``args`` on the tiny grid: it must exit 2 with one
    ``Error:`` line before any work (no encoding cached, no cell written)."""
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    base = ["run", "--dataset", TINY_DATASET, "--encoder", "raw", "--classifier", TINY_CLF,
            "-L", "2", "--seed", "0", "--pixel-mm", "10", "--threads", "1", "--no-plots"]
    if "--out" not in args:
        base += ["--out", str(tmp_path / "out")]
    if scene_text is not None:
        scene = tmp_path / scene_name
        scene.write_text(scene_text)
        args = [*args, str(scene)]
    result = CliRunner().invoke(cli, [*base, *args])
    assert result.exit_code == 2, result.output
    lines = [x for x in result.output.splitlines() if x.startswith("Error: ")]
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    cache = tmp_path / "cache"  # (a simulated dataset may be cached there: it is input)
    # the cache folder is made (and so checked) before any work; nothing is put in it
    assert not [p for p in cache.rglob("*") if p.is_file() and "datasets" not in
                p.relative_to(cache).parts]
    assert not (tmp_path / "out" / "cells").exists()
    return lines[0]


def test_an_out_that_is_a_file_is_one_line_before_any_work(tmp_path, monkeypatch):
    out = tmp_path / "taken"
    out.write_text("mine")
    line = _refused(tmp_path, monkeypatch, ["--out", str(out)])
    assert line == f"Error: out folder {out} is a file, not a folder; give a folder"
    assert out.read_text() == "mine"


def test_an_out_under_a_file_is_one_line_before_any_work(tmp_path, monkeypatch):
    (tmp_path / "f").write_text("mine")
    line = _refused(tmp_path, monkeypatch, ["--out", str(tmp_path / "f" / "out")])
    assert "cannot be made" in line and "is a file" in line


def test_an_out_folder_of_someone_else_is_not_overwritten(tmp_path, monkeypatch):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "results.csv").write_text("my data\n")
    (out / "notes.txt").write_text("notes\n")
    line = _refused(tmp_path, monkeypatch, ["--out", str(out)])
    assert "holds files tactbench did not write ('notes.txt')" in line
    assert (out / "results.csv").read_text() == "my data\n"


@pytest.mark.parametrize("args, scene_text, match", [
    (["--threads", "0"], None, "--threads must be ≥ 1, got 0"),
    (["--threads", "-4"], None, "--threads must be ≥ 1, got -4"),
    (["--encoder", "farneback:winsize=9,winsize=11"], None,
     "option 'winsize' is given twice in 'farneback:winsize=9,winsize=11'"),
    (["-L", "1-3000000"], None, "too many window lengths: '1-3000000' is 3000000 of them"),
    (["-L", "1000"], None, "window length L = 1000 is longer than every sequence"),
    (["--pixel-mm", "0.01"], None, "the imaging operator for tactile images at 0.01 mm "
                                   "(35700×33400 px) would need about"),
    ([], "seeds = [1.5]\n", "field 'seeds' must be whole numbers or ranges such as \"0-9\", got 1.5"),
    ([], "seeds = [true]\n", "field 'seeds' must be whole numbers or ranges such as \"0-9\", got True"),
    ([], "encoders = [1]\n", "field 'encoders' entry 1 must be text, got int 1"),
    ([], "threads = 0\n", "field 'threads' must be ≥ 1, got 0"),
    ([], "colour = 1\n", "unknown field 'colour'"),
])
def test_bad_options_and_scene_files_are_one_line_before_any_work(tmp_path, monkeypatch, args,
                                                                 scene_text, match):
    if "--pixel-mm" in args:
        monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "8192")
    line = _refused(tmp_path, monkeypatch, args, scene_text)
    assert match in line, line


def test_a_json_scene_file_is_checked_too(tmp_path, monkeypatch):
    line = _refused(tmp_path, monkeypatch, [], '{"seeds": [0], "seed": 1}', "scene.json")
    assert "field 'seeds' is given twice (as 'seeds' and 'seed')" in line


def test_seed_ranges_k_fold_users_and_test_windows_from_the_command_line(tmp_path,
                                                                          monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))

    def go(out, *extra):
        args = ["run", "--dataset", TINY_DATASET, "--encoder", "raw", "--classifier",
                "logreg", "-L", "2", "--pixel-mm", "10", "--threads", "1", "--out",
                str(tmp_path / out), "--json", "--no-plots", *extra]
        result = CliRunner().invoke(cli, args, catch_exceptions=False)
        assert result.exit_code == 0, result.output
        return json.loads(result.stdout)

    doc = go("a", "--seed", "0-2", "--split", "users:folds=2", "--test-window", "onset")
    assert doc["summary"][0]["seeds"] == [0, 1, 2]
    rows = json.loads((tmp_path / "a" / "results.json").read_text())["rows"]
    assert {(r["split"], r["folds"], r["test_window"]) for r in rows} == \
        {("users:folds=2", 2, "onset")}
    default = go("b", "--seed", "0")
    vote = go("c", "--seed", "0", "--test-window", "vote")
    first = go("d", "--seed", "0", "--test-window", "first")
    keys = [json.loads((tmp_path / o / "results.json").read_text())["rows"][0]
            for o in ("b", "c", "d")]
    # vote is the default; the study's window keeps the key a cell had before test windows
    # existed (no test_window in its identity), so it differs from vote's
    assert [r["test_window"] for r in keys] == ["vote", "vote", "first"]
    assert keys[0]["key"] == keys[1]["key"] != keys[2]["key"]
    assert default["summary"][0]["accuracy_mean"] == vote["summary"][0]["accuracy_mean"]
    assert first["meta"]["computed"] == 1
    bad = CliRunner().invoke(cli, ["run", "--split", "users:folds=1", "--out",
                                   str(tmp_path / "e")])
    assert bad.exit_code == 2 and "folds must be ≥ 2" in bad.output


def test_the_run_help_shows_the_scene_defaults(monkeypatch):
    """The help's ``[default: ...]`` is read from Scene's fields, not written by hand: each
    option of a Scene field shows what Scene() has, and a changed default shows."""
    from dataclasses import fields

    import click

    from tactbench.commands.run import SceneOption, run_cmd
    from tactbench.profiles import PROFILE_NAMES, get_profile
    from tactbench.runner.execution.scene import Scene

    ctx = click.Context(run_cmd, info_name="run")
    options = {p.field: p for p in run_cmd.params if isinstance(p, SceneOption)}
    # every Scene field has its option, but for the two that only scene files set
    assert set(options) == {f.name for f in fields(Scene)} - {"test_per_class", "imaging"}
    scene = Scene()
    for name, param in options.items():
        text = param.get_help_record(ctx)[1]
        value = getattr(scene, name)
        if isinstance(value, bool):  # a flag: off unless given
            assert "[default:" not in text, name
        elif value is None:  # decided later: the option says by what
            assert text.count("[default: ") == 1 and text.endswith("]"), name
        else:
            shown = ", ".join(map(str, value)) if isinstance(value, list) else str(value)
            assert text.count("[default:") == 1 and text.endswith(f"[default: {shown}]"), \
                (name, text)
    pixel = options["pixel_mm"].get_help_record(ctx)[1]
    for profile in PROFILE_NAMES:
        assert f"{profile} {get_profile(profile).pixel_mm:g}" in pixel
    monkeypatch.setattr(Scene.__dataclass_fields__["out"], "default", "elsewhere")
    help_text = CliRunner().invoke(cli, ["run", "--help"]).output
    assert "Output folder. [default: elsewhere]" in " ".join(help_text.split())
def test_statistics_options_from_the_command_line_and_a_scene_file(tmp_path, monkeypatch):
    """--margin, --contrast, --init-seed and --input (logreg takes either input) reach
    the cells and results.json; the scene file spells them as fields."""
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text('test_per_class = 1\ncontrast = "encoder=raw,L=2..encoder=frame-diff,L=3"\n'
                     'input = "vectors"\n')
    args = ["run", "--dataset", TINY_DATASET, "--encoder", "raw", "--encoder", "frame-diff",
            "--classifier", "logreg:max_iter=20", "-L", "2", "-L", "3", "--seed", "0-2",
            "--init-seed", "0-1", "--margin", "5", "--threads", "1",
            "--out", str(tmp_path / "out"), "--json", "--no-plots", str(scene)]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    doc = json.loads((tmp_path / "out" / "results.json").read_text())
    assert len(doc["rows"]) == 2 * 2 * 3 * 2  # encoders × L × split seeds × init seeds
    assert {r["init_seed"] for r in doc["rows"]} == {0, 1}
    assert {r["input"] for r in doc["rows"]} == {"vectors"}
    assert {s["input"] for s in doc["summary"]} == {"vectors"}
    contrast = [c for c in doc["comparisons"] if c["factor"] == "contrast"]
    assert [(c["a"], c["b"]) for c in contrast] == [("encoder=raw,L=2", "encoder=frame-diff,L=3")]
    assert all(c["runs"] == 3 and c["equivalence_margin"] == 5 for c in doc["comparisons"])
    assert doc["statistics"]["margin"] == 5 and doc["variance"]
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Where each cell's accuracy variance comes from" in report
    # the paired difference decomposed too: 3 split seeds × 2 init seeds
    assert all((c["variance_components"]["split_seeds"], c["variance_components"]["init_seeds"])
               == (3, 2) for c in doc["comparisons"])
    assert "### Where the difference's variance comes from" in report
