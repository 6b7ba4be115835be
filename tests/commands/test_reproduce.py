"""``tactbench reproduce DIR``: a folder's stored cells trained again here, compared test
prediction by test prediction."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.kernels import KERNELS_ENV
from tactbench.commands.reproduce import _line, compare
from tactbench.runner import ResultStore

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY_DATASET = "synthetic-forearm:users=2,repetitions=1"
FAST_CLF = "logreg:max_iter=20"


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A finished run of 2 encoders × 2 seeds, and its rows."""
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    out = tmp_path / "colleague"
    args = ["run", "--dataset", TINY_DATASET, "--encoder", "raw", "--encoder", "frame-diff",
            "--classifier", FAST_CLF, "-L", "3", "--seed", "0-1", "--pixel-mm", "10",
            "--out", str(out), str(scene)]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return out


def _reproduce(*args: str):
    return CliRunner().invoke(cli, ["reproduce", *args], catch_exceptions=False)


def _cells(result) -> list[dict]:
    return json.loads(result.output[result.output.index("{"):])["cells"]


def test_each_encoders_lowest_seed_trains_again_to_the_same_predictions(folder, tmp_path):
    before = {p.name: p.read_bytes() for p in (folder / "cells").iterdir()}
    result = _reproduce(str(folder), "--json")
    assert result.exit_code == 0, result.output
    cells = _cells(result)
    assert sorted((c["encoder"], c["seed"]) for c in cells) == [("frame-diff", 0), ("raw", 0)]
    for c in cells:
        assert c["outcome"] == "identical"
        assert c["key_now"] == c["key"]
        assert c["predictions_same"] == c["predictions"] > 0
    # the colleague's folder is left as it was: nothing trained or written there
    assert {p.name: p.read_bytes() for p in (folder / "cells").iterdir()} == before


def test_a_row_whose_predictions_this_machine_does_not_give_is_named(folder):
    store = ResultStore(folder)
    row = next(r for r in store.stored_rows() if r["encoder"] == "raw" and r["seed"] == 1)
    preds = row["test_predictions"]["predictions"]
    k = len(row["classes"])
    preds[0] = (preds[0] + 1) % k  # as if computed on a machine whose numerics differ
    labels = row["test_predictions"]["labels"]
    row["accuracy"] = sum(p == t for p, t in zip(preds, labels)) / len(preds)
    store.put(row)  # sealed again: a sound row, only not this machine's
    result = _reproduce(str(folder), "--cell", row["key"][:6])
    assert result.exit_code == 1, result.output
    assert f"{row['key']} raw / logreg L=3 seed 1: differs ({len(preds) - 1} of " \
           f"{len(preds)} test predictions the same" in result.output
    assert "0 of 1 cell(s)" in result.output


def test_a_cell_planned_with_other_kernels_here_says_which_field_differs(folder, monkeypatch):
    monkeypatch.setenv(KERNELS_ENV, "native")  # this process's cells: native kernels
    result = _reproduce(str(folder), "--cell", ResultStore(folder).keys()[0], "--json")
    assert result.exit_code == 1, result.output
    (cell,) = _cells(result)
    assert cell["outcome"] == "other identity"
    assert cell["key_now"] != cell["key"]
    (field,) = cell["identity_differs"]
    assert field.startswith("cpu_kernels: avx2 (the default) there, ")
    # what each side's run record resolved: the folder's, and this machine's
    assert cell["compute_there"]["cpu_kernels"] == "avx2"
    assert cell["compute_here"]["cpu_kernels"] != "avx2"


def test_every_cell_with_all_and_the_cells_kept_where_asked(folder, tmp_path):
    keep = tmp_path / "mine"
    result = _reproduce(str(folder), "--all", "--out", str(keep))
    assert result.exit_code == 0, result.output
    assert "4 of 4 cell(s)" in result.output
    kept = {p.stem for p in keep.rglob("cells/*.json")}
    assert kept == set(ResultStore(folder).keys())
    # the same --out again: every cell is trained anew, not read from the last time
    first = {p: p.read_bytes() for p in keep.rglob("cells/*.json")}
    assert _reproduce(str(folder), "--all", "--out", str(keep)).exit_code == 0
    assert all(p.read_bytes() != data for p, data in first.items())


@pytest.mark.parametrize("args, says", [
    (["--cell", "zz"], "--cell zz: no finished cell(s) of the folder match"),
    (["--cell", "a", "--all"], "--cell and --all: give one or the other"),
])
def test_a_mistake_is_one_line(folder, args, says):
    result = _reproduce(str(folder), *args)
    assert result.exit_code == 2
    assert says in result.output


def test_a_folder_without_cells_and_an_out_inside_the_folder_are_refused(folder, tmp_path):
    result = _reproduce(str(tmp_path / "nowhere"))
    assert result.exit_code == 2 and "has no cells/ folder" in result.output
    result = _reproduce(str(folder), "--out", str(folder / "again"))
    assert result.exit_code == 2 and "overlaps the input" in result.output
    assert not (folder / "again").exists()


def test_a_row_whose_scene_left_the_threads_to_the_machine_trains_with_its_own(folder):
    """Scenes of before stored ``threads: null`` ("this machine's"); the row says what
    its cell trained with, and that is what it is planned with again."""
    store = ResultStore(folder)
    row = next(r for r in store.stored_rows() if r["encoder"] == "raw" and r["seed"] == 0)
    row["run"]["scene"]["threads"] = None
    store.put(row)
    result = _reproduce(str(folder), "--cell", row["key"])
    assert result.exit_code == 0, result.output
    assert f"{row['key']} raw / logreg L=3 seed 0: identical" in result.output


def test_a_cell_that_fails_here_says_its_error():
    old = {"key": "abc", "encoder": "raw", "classifier": "logreg:max_iter=20", "L": 3,
           "seed": 0, "accuracy": 0.5}
    new = {"key": "abc", "status": "failed",
           "error": {"type": "MemoryError", "message": "out of memory", "traceback": ""}}
    result = compare(old, new)
    assert result["outcome"] == "failed"
    assert _line(result) == "abc raw / logreg L=3 seed 0: failed here: MemoryError: out of memory"


@pytest.mark.parametrize("run_meta", ["not a record", {"scene": None}])
def test_a_row_without_a_readable_scene_is_one_line(folder, run_meta):
    store = ResultStore(folder)
    row = store.stored_rows()[0]
    row["run"] = run_meta
    store.put(row)  # sealed again: sound, but no scene to plan it from
    result = _reproduce(str(folder), "--cell", row["key"])
    assert result.exit_code == 2, result.output
    assert f"cell {row['key']}: its row keeps no scene" in result.output
