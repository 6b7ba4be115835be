"""Hardening, round four (issue 40), the second half: ``plan`` refuses what ``run``
refuses (another grid's folder, a missing or damaged weights file) in the same line, a
tiny ``--effect`` and a pilot of one difference are said, ``report`` verifies each row's
key and refuses cells of two grids, uint8 clipping is said, paths are named as what they
are."""

from __future__ import annotations

import json
import logging
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.encoders.encoding import Storage
from tactbench.runner.analysis.answering import History
from tactbench.runner.analysis.comparisons import comparisons
from tactbench.runner.analysis.forecast import _primary
from tactbench.runner.execution.planning import digest, mixed_grids, row_identity, row_key_problem
from tactbench.runner.analysis.power import recordings_for
from tactbench.runner.execution.results import ResultStore

sys.path.insert(0, str(Path(__file__).parent / "runner"))
from prediction_rows import prediction_row  # noqa: E402

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = ["--dataset", "synthetic-forearm:users=2,repetitions=1", "--encoder", "raw",
        "--encoder", "frame-diff", "--classifier", "logreg:max_iter=20", "-L", "3",
        "--threads", "1", "--primary", "encoder=raw..encoder=frame-diff", "--seed", "0"]


def _invoke(root: Path, *args: str, env: dict | None = None):
    scene = root / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    return CliRunner().invoke(cli, [*args, str(scene)], catch_exceptions=False,
                              env={"TACTBENCH_CACHE": str(root / "cache"), **(env or {})})


@pytest.fixture(scope="module")
def two_grids(tmp_path_factory):
    """Two run folders of one grid but for the pixel size (10 and 5 mm)."""
    root = tmp_path_factory.mktemp("grids")
    for name, pixel in (("a", "10"), ("b", "5")):
        res = _invoke(root, "run", *TINY, "--pixel-mm", pixel, "--out", str(root / name),
                      "--no-plots")
        assert res.exit_code == 0, res.output
    return root


def _error_line(output: str) -> str:
    return next(line for line in output.splitlines() if line.startswith("Error:"))


# ------------------------------------------------------ plan refuses what run refuses


def test_plan_refuses_another_grids_folder_in_runs_words_writing_nothing(two_grids):
    out = two_grids / "a"
    before = sorted(p.name for p in (out / "cells").iterdir())
    plan = _invoke(two_grids, "plan", *TINY, "--pixel-mm", "5", "--out", str(out))
    run = _invoke(two_grids, "run", *TINY, "--pixel-mm", "5", "--out", str(out))
    assert plan.exit_code == run.exit_code == 2
    assert _error_line(plan.output) == _error_line(run.output)
    assert "of another grid" in plan.output
    assert "imaging" in _error_line(plan.output)  # how the stored cell differs
    assert sorted(p.name for p in (out / "cells").iterdir()) == before  # no claim left
    same = _invoke(two_grids, "plan", *TINY, "--pixel-mm", "10", "--out", str(out))
    assert same.exit_code == 0, same.output  # the folder's own grid is planned


def _fake_weights(root: Path, content: bytes | None) -> Path:
    """An installed-looking weights package whose file is ``content`` (None: a folder)."""
    from tactbench.classifiers import pretrained

    pkg = root / "site" / pretrained.PACKAGE
    (pkg / "models").mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text("")
    path = pkg.joinpath(*pretrained.WEIGHTS_FILE)
    if path.is_dir():
        path.rmdir()
    elif path.exists():
        path.unlink()
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    return root / "site"


@pytest.mark.parametrize("content, said", [(b"not the weights", "SHA-256"),
                                           (None, "is a folder")])
def test_a_damaged_weights_file_is_refused_by_plan_and_run_before_any_work(
        tmp_path, content, said):
    site = _fake_weights(tmp_path, content)
    clf = "cnn-lstm:pretrained=imagenet,backbone=efficientnet-lite0"
    args = [*TINY[:6], "--classifier", clf, "-L", "3", "--seed", "0",
            "--out", str(tmp_path / "out")]
    env = {"PYTHONPATH": str(site)}
    sys.path.insert(0, str(site))  # find_spec reads sys.path in this process
    try:
        plan = _invoke(tmp_path, "plan", *args, env=env)
        run = _invoke(tmp_path, "run", *args, env=env)
    finally:
        sys.path.remove(str(site))
    assert plan.exit_code == run.exit_code == 2, run.output
    assert said in _error_line(plan.output) and _error_line(plan.output) == \
        _error_line(run.output)
    assert not (tmp_path / "out").exists()  # nothing encoded, nothing stored
    assert not list((tmp_path / "cache").rglob("meta.json"))


@pytest.mark.parametrize("kind", ["folder", "fifo", "missing"])
def test_a_weights_path_is_named_as_what_it_is_at_planning(tmp_path, kind):
    path = tmp_path / "w.pth"
    if kind == "folder":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    res = _invoke(tmp_path, "plan", *TINY[:6], "--classifier", f"cnn-lstm:weights={path}",
                  "-L", "3", "--seed", "0", "--out", str(tmp_path / "out"))
    assert res.exit_code == 2
    line = _error_line(res.output)
    assert {"folder": "is a folder", "fifo": "is a FIFO",
            "missing": "does not exist"}[kind] in line, line


@pytest.mark.parametrize("effect", ["1e-9", "1e-300", "5e-324"])
def test_a_tiny_effect_is_planned_and_said_not_a_traceback(tmp_path, effect):
    res = _invoke(tmp_path, "plan", *TINY, "--pixel-mm", "10", "--out",
                  str(tmp_path / "out"), "--effect", effect)
    if effect == "5e-324":  # 0 as a fraction of the recordings: one line
        assert res.exit_code == 2 and "not vanish" in res.output
        return
    assert res.exit_code == 0, res.output
    assert "+0.0 points" not in res.output and "power" in res.output
    assert "e+" not in res.output.split("recordings (now")[0][-30:]  # no 1e22 recordings


def test_recordings_for_a_vanishing_floor_is_none_not_an_overflow():
    assert recordings_for(1e-300, 0.4, 20) is None and recordings_for(1e-11, 0.4, 20) is None
    assert recordings_for(0.02, 0.04, 750) == 3000


@pytest.mark.parametrize("worse, said", [
    ("all", "one model is right on every recording"),
    ("none", "agree on every recording"),
    ("two", "raised to"),
])
def test_a_pilot_of_one_difference_in_every_run_is_no_power_of_100(worse, said):
    truth = [0, 1] * 5
    a = {"all": [1 - t for t in truth], "none": truth, "two": [1, 0, *truth[2:]]}[worse]
    rows = [prediction_row("raw", s, truth, a) for s in range(3)] + \
        [prediction_row("farneback", s, truth, truth) for s in range(3)]
    primary = "encoder=raw..encoder=farneback"
    (found,) = [c for c in comparisons(rows, primary=[primary]) if c.family == "primary"]
    f = _primary(primary, found, 5, 0.05, 0.25, 10, 0.05, 50)
    assert said in f.sd_source and f.sd > 0 and f.power < 1 and f.detectable > 1


# ---------------------------------------------------------- report: keys and grids


def test_a_report_of_cells_of_two_grids_is_refused_naming_the_difference(two_grids,
                                                                         tmp_path):
    mixed = tmp_path / "mixed"
    shutil.copytree(two_grids / "a", mixed)
    for p in (two_grids / "b" / "cells").glob("*.json"):
        shutil.copy(p, mixed / "cells" / p.name)
    before = (mixed / "report.md").read_bytes()
    res = CliRunner().invoke(cli, ["report", str(mixed), "--no-plots"])
    assert res.exit_code == 2 and "two grids" in res.output and "imaging" in res.output
    assert (mixed / "report.md").read_bytes() == before  # nothing written
    rows = ResultStore(two_grids / "a").stored_rows()
    assert mixed_grids(rows) is None


@pytest.mark.parametrize("field, value", [("split", "users"), ("threads", 2),
                                          ("precision", "uint8"), ("profile", "paper")])
def test_rows_of_two_grids_are_told_apart_by_any_identity_field(two_grids, field, value):
    rows = ResultStore(two_grids / "a").stored_rows()
    other = {**rows[0], field: value}
    assert field in mixed_grids([*rows, other])


def test_a_row_copied_under_another_key_is_left_out_of_the_report(two_grids, tmp_path,
                                                                  caplog):
    folder = tmp_path / "copied"
    shutil.copytree(two_grids / "a", folder)
    store = ResultStore(folder)
    rows = store.stored_rows()
    assert all(row_key_problem(r) is None for r in rows)  # real rows: keyed by identity
    store.put({**rows[0], "key": "0123456789abcdef"})  # copied, checksum re-sealed
    with caplog.at_level(logging.WARNING):
        res = CliRunner().invoke(cli, ["report", str(folder), "--no-plots", "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output[res.output.index("{"):])
    seeds = [s["seeds"] for s in doc["summary"]]
    assert all(len(s) == 1 for s in seeds), seeds  # counted once, not [0, 0]
    assert "0123456789abcdef" in caplog.text and "leaves it out" in caplog.text


def test_row_identity_hashes_to_the_key_a_run_gave():
    row = prediction_row("raw", 0, [0, 1], [0, 1])
    row.update(schema=1, threads=1, test_window="first", imaging={"kind": "vectors"})
    identity = row_identity(row)
    assert "threads" not in identity and "test_window" not in identity
    assert row_key_problem({**row, "key": digest(identity)}) is None
    assert "copied" in row_key_problem({**row, "key": digest({**identity, "seed": 1})})


# ------------------------------------------------------------- precision and paths


def test_uint8_storage_counts_and_says_what_it_clipped():
    store = Storage.for_channels("uint8", 1)
    stored = store.encode(np.array([[-0.5, 0.2, 1.5, -0.001]]))
    assert stored.tolist() == [[0, 51, 255, 0]]  # -0.001: within half a quantum
    line = store.clipping("my-encoder")
    assert "encoder 'my-encoder'" in line and "2 of 4 values" in line
    assert "1 below, 1 above" in line and "--precision float16 or float32" in line
    assert "\n" not in line
    fine = Storage.for_channels("uint8", 2, [(0, 1), (-1, 1)])
    fine.encode(np.full((1, 2, 2, 2), -0.5))
    assert fine.clipped == [4, 0]  # channel 0 declares (0, 1): its -0.5 is clipped
    assert Storage.for_channels("float16", 1).clipping("x") is None


@pytest.mark.parametrize("kind", ["fifo", "file", "link"])
def test_a_run_folder_that_is_not_a_folder_is_named_as_what_it_is(tmp_path, kind):
    path = tmp_path / "out"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "file":
        path.write_text("x")
    else:
        path.symlink_to(tmp_path / "nowhere")
    from tactbench.runner import render_folder

    with pytest.raises(Exception) as err:
        render_folder(path, plots=False)
    said = {"fifo": "is a FIFO", "file": "is a regular file",
            "link": "is a dangling link"}[kind]
    assert said in str(err.value) and "does not exist" not in str(err.value)


def test_no_look_yet_is_said_as_what_the_folder_holds():
    text = History([5, 10], 10).stopped_because()
    assert "no look made yet" in text and "after 5 runs" in text and "2 runs" not in text
