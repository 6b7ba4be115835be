"""Result rows: one atomic file per cell; failed rows are kept but not finished."""

from __future__ import annotations

import pytest

from tactbench.errors import CorruptArtefactError
from tactbench.runner import ResultStore, failed_rows, ok_rows, row_status


def test_rows_round_trip_and_failed_rows_are_not_finished(tmp_path):
    store = ResultStore(tmp_path)
    assert store.get("a") is None and not store.finished("a")
    store.put({"key": "a", "status": "ok", "accuracy": 0.5})
    store.put({"key": "b", "status": "failed", "error": {"type": "RuntimeError"}})
    store.put({"key": "c", "accuracy": 0.7})  # a row from before status existed
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
    store.put({"key": "a", "status": "ok", "accuracy": 0.5, "seed": (1, 2)})
    row = json.loads(store.path("a").read_text())
    assert row["key"] == "a" and len(row["checksum"]) == 64
    assert store.get("a", {"seed": [1, 2]})["accuracy"] == 0.5
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
        store.read("a", {"seed": [1, 3]})  # a row of another identity under this key


@pytest.mark.parametrize("text, problem", [
    ("{}", "is the row of cell 'None'"), ("[1]", "holds a JSON list"),
    ("null", "holds a JSON NoneType"), ('"x"', "holds a JSON str"),
    ('{"key": "a"', "is not valid JSON"), ("[" * 100_000, "is not valid JSON"),
    ('{"key": "a", "status": "ok"}', "no accuracy"),
    ('{"key": "a", "status": "ok", "accuracy": NaN}', "no accuracy"),
    ('{"key": "a", "status": "ok", "accuracy": true}', "no accuracy"),
    ('{"key": "a", "status": "failed"}', "without its error"),
    ('{"key": "a", "status": 3, "accuracy": 1}', "unknown status"),
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
    store.path("a").write_text(json.dumps({"key": "a", "accuracy": 0.7}))
    assert store.finished("a") and store.get("a")["accuracy"] == 0.7


def test_temporary_row_files_of_dead_processes_are_removed(tmp_path):
    import os
    import subprocess
    import sys

    from tactbench.paths import host_tag

    store = ResultStore(tmp_path)
    store.put({"key": "a", "status": "ok", "accuracy": 0.5})
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    dead = store.cells / f".b.json.tmp-{proc.pid}-{host_tag()}-0a0a0a0a"
    alive = store.cells / f".c.json.tmp-{os.getpid()}-{host_tag()}-0a0a0a0a"
    dead.write_text("{")
    alive.write_text("{")
    assert [t.path for t in store.clean()] == [dead]
    assert sorted(p.name for p in store.cells.iterdir()) == [alive.name, "a.json"]
