"""Hardening, round five: ``tactbench reproduce`` judges by predictions whatever a row's
format, reuses its own ``--out`` for other cells, and finds a relative data set from
another working folder (or says exactly why not)."""

from __future__ import annotations

import json
import shutil

import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.commands.reproduce import compare, same_predictions
from tactbench.runner import ResultStore

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A finished run of 2 seeds of one cell on a data set folder given by a relative
    path from ``tmp_path/lab`` (the working folder it was run in)."""
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    lab = tmp_path / "lab"
    lab.mkdir()
    monkeypatch.chdir(lab)
    made = CliRunner().invoke(cli, ["data", "synth", "--users", "2", "--repetitions", "1",
                                    "--positions", "1", "--out", "data/forearm"], catch_exceptions=False)
    assert made.exit_code == 0, made.output
    (lab / "scene.toml").write_text("test_per_class = 1\n")
    args = ["run", "--dataset", "data/forearm", "--encoder", "raw",
            "--classifier", "logreg:max_iter=20", "-L", "3", "--seed", "0-1", "--workers", "1",
            "--pixel-mm", "10", "--out", "colleague", "scene.toml"]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return lab / "colleague"


def _reproduce(*args: str):
    return CliRunner().invoke(cli, ["reproduce", *args], catch_exceptions=False)


def test_a_row_of_the_older_format_with_the_same_predictions_is_identical():
    """Rows stored before folds and groups were kept with the predictions."""
    old_lists = {"indices": [3, 1, 2], "labels": [0, 1, 1], "predictions": [0, 1, 0]}
    new_lists = {**old_lists, "folds": [0, 0, 0], "groups": ["u1", "u2", "u1"]}
    assert same_predictions(old_lists, new_lists)
    assert not same_predictions(old_lists, {**new_lists, "predictions": [0, 1, 1]})
    assert not same_predictions({"indices": [3, 1, 2]}, new_lists)
    old = {"key": "k", "encoder": "raw", "classifier": "logreg", "L": 3, "seed": 0,
           "accuracy": 2 / 3, "test_predictions": old_lists}
    new = {**old, "status": "ok", "test_predictions": new_lists}
    assert compare(old, new)["outcome"] == "identical"


def test_reproduce_on_an_older_rows_folder_exits_0(folder):
    store = ResultStore(folder)
    for row in store.stored_rows():  # as rows were stored before folds and groups
        for name in ("folds", "groups"):
            row["test_predictions"].pop(name, None)
        store.put(row)
    result = _reproduce(str(folder), "--cell", store.keys()[0])
    assert result.exit_code == 0, result.output
    assert ": identical (" in result.output and "1 of 1 cell(s)" in result.output


def test_its_own_out_is_reused_for_other_cells(folder, tmp_path):
    keys = ResultStore(folder).keys()
    out = tmp_path / "mine"
    first = _reproduce(str(folder), "--cell", keys[0], "--out", str(out))
    assert first.exit_code == 0, first.output
    second = _reproduce(str(folder), "--cell", keys[1], "--out", str(out))
    assert second.exit_code == 0, second.output  # was: refused, another grid in part1
    again = _reproduce(str(folder), "--all", "--out", str(out))
    assert again.exit_code == 0, again.output
    kept = {p.stem for p in out.rglob("cells/*.json")}
    assert kept == set(keys)


def test_a_relative_data_set_is_found_from_another_working_folder(folder, tmp_path,
                                                                 monkeypatch):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    result = _reproduce(str(folder), "--json")
    assert result.exit_code == 0, result.output
    cells = json.loads(result.output[result.output.index("{"):])["cells"]
    assert [c["outcome"] for c in cells] == ["identical"]


def test_a_relative_data_set_that_cannot_be_found_says_exactly_why(folder, tmp_path,
                                                                  monkeypatch):
    shutil.move(str(tmp_path / "lab" / "data"), str(tmp_path / "moved"))
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, ["reproduce", str(folder)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    line = result.output.strip().splitlines()[-1]
    assert "data/forearm is a path relative to the folder its run was started in, " \
           f"{tmp_path / 'lab'}, and is found neither there nor from here ({tmp_path})" in line
