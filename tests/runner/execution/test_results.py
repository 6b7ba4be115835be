"""Result rows: one atomic file per cell; failed rows are kept but not finished."""

from __future__ import annotations

import pytest

from tactbench.errors import CorruptArtefactError
from tactbench.runner import ResultStore, failed_rows, ok_rows, row_status

CELL = {"encoder": "raw", "classifier": "logreg", "L": 3, "seed": 0}
RESULT = {**CELL, "classes": ["a", "b"], "confusion": [[1, 0], [1, 0]],
          "per_class_accuracy": {"a": 1.0, "b": 0.0}}


def test_rows_round_trip_and_failed_rows_are_not_finished(tmp_path):
    store = ResultStore(tmp_path)
    assert store.get("a") is None and not store.finished("a")
    store.put({**RESULT, "key": "a", "status": "ok", "accuracy": 0.5})
    store.put({**CELL, "key": "b", "status": "failed", "error": {"type": "RuntimeError"}})
    store.put({**RESULT, "key": "c", "accuracy": 0.7})  # a row from before status existed
    assert store.finished("a") and not store.finished("b") and store.finished("c")
    rows = store.rows(["c", "x", "b", "a"])
    assert [r["key"] for r in rows] == ["c", "b", "a"]
    assert [row_status(r) for r in rows] == ["ok", "failed", "ok"]
    assert [r["key"] for r in ok_rows(rows)] == ["c", "a"]
    assert [r["key"] for r in failed_rows(rows)] == ["b"]
    assert sorted(p.name for p in (tmp_path / "cells").iterdir()) == \
        ["a.json", "b.json", "c.json"]


def test_a_damaged_row_counts_as_missing(tmp_path):
    store = ResultStore(tmp_path)
    store.path("a").parent.mkdir(parents=True)
    store.path("a").write_text('{"key": "a", "acc')
    assert store.get("a") is None and not store.finished("a")


def test_each_row_records_its_key_and_a_checksum_checked_on_read(tmp_path, caplog):
    import json

    store = ResultStore(tmp_path)
    store.put({**RESULT, "key": "a", "status": "ok", "accuracy": 0.5, "test_users": ("u", 2)})
    row = json.loads(store.path("a").read_text())
    assert row["key"] == "a" and len(row["checksum"]) == 64
    assert store.get("a", {"test_users": ["u", 2]})["accuracy"] == 0.5
    good = store.path("a").read_text()
    for text, problem in ((good.replace('"accuracy": 0.5', '"accuracy": 0.6'),
                           "does not match its checksum"),
                          (json.dumps({**row, "key": "b"}), "is the row of cell 'b'")):
        store.path("a").write_text(text)
        caplog.clear()
        assert store.get("a") is None and not store.finished("a")
        assert problem in caplog.text and str(store.path("a")) in caplog.text, problem
    store.path("a").write_text(good)
    with pytest.raises(CorruptArtefactError, match="records seed"):
        store.read("a", {"seed": 1})  # a row of another identity under this key


def _row(**over):
    import json

    return json.dumps({**RESULT, "key": "a", "status": "ok", "accuracy": 0.5, **over})


@pytest.mark.parametrize("text, problem", [
    ("{}", "is the row of cell 'None'"), ("[1]", "holds a JSON list"),
    ("null", "holds a JSON NoneType"), ('"x"', "holds a JSON str"),
    ('{"key": "a"', "is not valid JSON"), ("[" * 100_000, "is not valid JSON"),
    (_row(accuracy=None), "no accuracy"), (_row(accuracy=float("nan")), "no accuracy"),
    (_row(accuracy=True), "no accuracy"), (_row(accuracy=1.5), "no accuracy"),
    (_row(status="failed"), "without its error"), (_row(status=3), "unknown status"),
    (_row(seed=1.5), "has no seed"), (_row(L=True), "has no L"),
    (_row(encoder=None), "has no encoder"), (_row(classes="ab"), "class names"),
    (_row(confusion=[[1, 0]]), "2 × 2 confusion"),
    (_row(confusion=[[1, -1], [0, 0]]), "2 × 2 confusion"),
    (_row(per_class_accuracy=[]), "per-class"),
])
def test_anything_but_a_sound_row_is_a_damaged_row(tmp_path, text, problem):
    store = ResultStore(tmp_path)
    store.path("a").parent.mkdir(parents=True)
    store.path("a").write_text(text)
    with pytest.raises(CorruptArtefactError, match=problem) as info:
        store.read("a")
    assert "\n" not in str(info.value)
    assert store.get("a") is None


def test_rows_written_before_checksums_are_still_read(tmp_path):
    import json

    store = ResultStore(tmp_path)
    store.path("a").parent.mkdir(parents=True)
    store.path("a").write_text(json.dumps({**RESULT, "key": "a", "accuracy": 0.7}))
    assert store.finished("a") and store.get("a")["accuracy"] == 0.7


def test_temporary_row_files_of_dead_processes_are_removed(tmp_path):
    import os
    import subprocess
    import sys

    from tactbench.paths import host_tag

    store = ResultStore(tmp_path)
    store.put({**RESULT, "key": "a", "status": "ok", "accuracy": 0.5})
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    dead = store.cells / f".b.json.tmp-{proc.pid}-{host_tag()}-0a0a0a0a"
    alive = store.cells / f".c.json.tmp-{os.getpid()}-{host_tag()}-0a0a0a0a"
    dead.write_text("{")
    alive.write_text("{")
    assert [t.path for t in store.clean()] == [dead]
    assert sorted(p.name for p in store.cells.iterdir()) == [alive.name, "a.json"]


def _scene_row(key, encoder, classifier, L, seed, finished, scene=None, **over):
    row = {**RESULT, "key": key, "status": "ok", "accuracy": 0.5, "encoder": encoder,
           "classifier": classifier, "L": L, "seed": seed, "finished": finished, **over}
    if scene is not None:
        row["run"] = {"command": "tactbench run", "git": "abc", "scene": scene}
    return row


def test_stored_rows_come_from_cells_in_the_order_the_scene_lists_them(tmp_path, caplog):
    from tactbench.runner.execution.results import scene_order

    scene = {"encoders": ["raw", "farneback:winsize=9"],
             "classifiers": ["cnn:width=8", "cnn", "sklearn:SVC"],
             "L": [6, 3], "seeds": [1, 0], "init_seeds": None}
    store = ResultStore(tmp_path)
    made = [  # in the plan's order: encoder, classifier, L, seed as the scene lists them
        ("k1", "raw", "cnn:epochs=4,width=8", 6, 1), ("k2", "raw", "cnn:epochs=4,width=8", 3, 0),
        ("k3", "raw", "cnn:epochs=4,width=16", 6, 1), ("k4", "raw", "sklearn:C=1,estimator=SVC", 6, 1),
        ("k5", "farneback:winsize=9", "cnn:epochs=4,width=8", 6, 1)]
    for i, (key, enc, clf, length, seed) in enumerate(reversed(made)):
        store.put(_scene_row(key, enc, clf, length, seed, f"2026-01-01T00:00:0{i}",
                             scene if i == 4 else {"encoders": ["farneback:winsize=9"]}))
    store.put(_scene_row("k0", "dis", "logreg", 5, 0, "2025-01-01"))  # no scene names it
    assert [r["key"] for r in store.stored_rows()] == [m[0] for m in made] + ["k0"]
    assert [r["key"] for r in scene_order([])] == []
    store.path("k3").write_text(store.path("k3").read_text().replace('"seed": 1', '"seed": 2'))
    assert "k3" not in [r["key"] for r in store.stored_rows()]  # verified on read
    assert "does not match its checksum" in caplog.text


def test_results_json_is_never_read_to_decide_anything(tmp_path):
    """The one-grid rule counts cells/ only: a results.json of rows no cell holds (edited,
    copied, another grid's) neither refuses a grid nor gives a row."""
    import json

    store = ResultStore(tmp_path)
    other = {**RESULT, "key": "other", "status": "ok", "accuracy": 0.5}
    (tmp_path / "results.json").write_text(json.dumps({"rows": [other]}))
    assert store.stored_rows() == [] and store.get("other") is None
    store.claim(["mine"]).unlink()  # another grid's row in results.json: not a cell
    store.put({**RESULT, "key": "mine", "status": "ok", "accuracy": 0.5})
    from tactbench.errors import InputError

    with pytest.raises(InputError, match=r"holds 1 cell\(s\) of another grid"):
        store.claim(["new"])


@pytest.mark.parametrize("argv, line", [
    (["/venv/bin/tactbench", "run", "--seed", "0-4"], "tactbench run --seed 0-4"),
    (["/src/tactbench/__main__.py", "report", "out dir"], "tactbench report 'out dir'"),
    (["benchmarks/reports.py", "study"], "reports.py study"),
    ([], "python"),
])
def test_the_command_line_is_written_one_way(argv, line):
    from tactbench.runner.execution.results import command_line

    assert command_line(argv) == line


def test_a_refused_grid_is_told_how_the_stored_cells_differ(tmp_path):
    from tactbench.errors import InputError

    store = ResultStore(tmp_path)
    stored = {"dataset_hash": "h1", "L": 3, "seed": 0}  # made with test window "first"
    store.put({**RESULT, **stored, "key": "old", "status": "ok", "accuracy": 0.5,
               "test_window": "first"})
    planned = {"new": {**stored, "test_window": "vote"},
               "far": {**stored, "dataset_hash": "h2", "seed": 1, "test_window": "vote"}}
    with pytest.raises(InputError, match=r"1 cell\(s\) of another grid \(raw × logreg L=3 "
                                         r"seed=0; its test_window is 'first', this run's "
                                         r"'vote'\)"):
        store.claim(planned, planned)
    with pytest.raises(InputError, match=r"its dataset_hash is 'h1', this run's 'h2'"):
        store.claim(["x"], {"x": {**stored, "dataset_hash": "h2"}})


def test_a_row_trained_with_other_threads_or_kernels_is_not_the_default_cell():
    """Rows record their threads; a cell's identity leaves 1 thread and avx2 kernels out:
    a 2-thread row must not pass for the 1-thread cell of the same other fields."""
    from tactbench.runner.execution.results import check_row

    row = {"key": "k", "encoder": "raw", "classifier": "c", "L": 1, "seed": 0,
           "status": "failed", "error": {"type": "E", "message": "m"}}
    identity = {"encoder": "raw"}
    assert check_row({**row, "threads": 1}, "k", identity) is None
    assert "threads = '2', the cell has 1" in check_row({**row, "threads": 2}, "k", identity)
    assert "cpu_kernels" in check_row({**row, "cpu_kernels": "native X (avx512)"}, "k",
                                      identity)
    assert check_row({**row, "threads": 2}, "k", {**identity, "threads": 2}) is None
