"""Result rows: one atomic file per cell; failed rows are kept but not finished."""

from __future__ import annotations

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
