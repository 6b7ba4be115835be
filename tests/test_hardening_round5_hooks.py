"""Hardening, round five (issue 51): a plugin's event hook cannot end, stall or corrupt a
run (tactbench/events.py). Each hook gets its own copy of the stored row, on its own
thread; sys.exit and exceptions are said once; a hook over TACTBENCH_HOOK_TIMEOUT is
abandoned without holding back the storing of rows; a file a hook leaves in the run folder
does not block the folder's next run."""

from __future__ import annotations

import json
import logging
import sys
import threading
import time
import types

import pytest

from tactbench import hookimpl
from tactbench.errors import InputError
from tactbench.events import HOOK_TIMEOUT_ENV, hook_timeout
from tactbench.plugins import collect_registry, make_plugin_manager
from tactbench.runner import Scene, run


def registry_with(*plugins):
    return collect_registry(make_plugin_manager(entry_points=False, strict=False,
                                                extra=list(plugins)))


def plugin(**hooks):
    return types.SimpleNamespace(**{name: hookimpl(f) for name, f in hooks.items()})


def warnings_of(caplog):
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_a_hook_calling_sys_exit_is_contained_and_said_once(tmp_path, caplog):
    heard = []
    registry = registry_with(
        ("quitter", plugin(cell_finished=lambda row, out: sys.exit(0))),
        ("listener", plugin(cell_finished=lambda row, out: heard.append(row["key"]))))
    for key in ("a", "b", "c"):
        registry.notify("cell_finished", row={"key": key}, out=tmp_path)
    registry.settle()
    assert heard == ["a", "b", "c"]  # the plugin after it still hears every cell
    said = [w for w in warnings_of(caplog) if "quitter" in w]
    assert len(said) == 2, said
    assert "called sys.exit (0)" in said[0] and "the run goes on" in said[0]
    assert "failed 3 time(s) in all" in said[1]
    lanes = [t for t in threading.enumerate()
             if t.name in ("tactbench-hooks-quitter", "tactbench-hooks-listener")]
    for thread in lanes:  # settled: the lanes' threads end
        thread.join(2)
    assert not any(t.is_alive() for t in lanes)


def test_each_hook_gets_its_own_copy_of_the_row(tmp_path):
    row = {"key": "k", "accuracy": 0.75, "per_class_accuracy": {"tap": 0.5}}
    seen = []

    def editor(row, out):
        row["accuracy"] = 0.0
        row["per_class_accuracy"]["tap"] = 1.0

    registry = registry_with(("editor", plugin(cell_finished=editor)),
                             ("exporter", plugin(cell_finished=lambda row, out:
                                                 seen.append(json.dumps(row)))))
    registry.notify("cell_finished", row=row, out=tmp_path)
    registry.settle()
    assert json.loads(seen[0]) == {"key": "k", "accuracy": 0.75,
                                   "per_class_accuracy": {"tap": 0.5}}
    assert row == {"key": "k", "accuracy": 0.75, "per_class_accuracy": {"tap": 0.5}}


def test_a_hung_hook_is_abandoned_and_holds_nothing_back(tmp_path, caplog, monkeypatch):
    monkeypatch.setenv(HOOK_TIMEOUT_ENV, "0.2")
    release, calls, heard = threading.Event(), [], []

    def hang(row, out):
        calls.append(row["key"])
        release.wait(30)

    registry = registry_with(("hang", plugin(cell_finished=hang)),
                             ("listener", plugin(cell_finished=lambda row, out:
                                                 heard.append(row["key"]))))
    try:
        start = time.monotonic()
        registry.notify("cell_finished", row={"key": "a"}, out=tmp_path)
        registry.notify("cell_finished", row={"key": "b"}, out=tmp_path)
        assert time.monotonic() - start < 0.15  # the caller (the store) never waits
        registry.settle()
        assert time.monotonic() - start < 2
        registry.notify("cell_finished", row={"key": "c"}, out=tmp_path)
        registry.settle()
    finally:
        release.set()
    assert heard == ["a", "b", "c"] and calls == ["a"]  # abandoned: never called again
    said = [w for w in warnings_of(caplog) if "hang" in w]
    assert len(said) == 1 and "did not return within 0.2 s and is abandoned" in said[0]
    assert HOOK_TIMEOUT_ENV in said[0]


@pytest.mark.parametrize("value", ["abc", "0", "-3", "inf", "nan"])
def test_a_bad_hook_timeout_is_one_line_before_any_work(tmp_path, monkeypatch, value):
    monkeypatch.setenv(HOOK_TIMEOUT_ENV, value)
    with pytest.raises(InputError, match=f"{HOOK_TIMEOUT_ENV}=.*positive number"):
        hook_timeout()
    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
                  classifiers=["logreg:max_iter=20"], L=[3], seeds=[0], pixel_mm=10,
                  test_per_class=1, threads=1, workers=1, out=str(tmp_path / "out"))
    with pytest.raises(InputError, match=HOOK_TIMEOUT_ENV):
        run(scene, progress=False, plots=False)
    assert not (tmp_path / "out").exists()


def test_hostile_hooks_lose_no_row_and_leave_the_folder_runnable(tmp_path, caplog,
                                                                monkeypatch):
    """One run with four hostile plugins (one exits, one edits the row, one hangs, one
    keeps a state file in the run folder): every cell is stored as computed, the report
    is written, the exporter after the editor logs the true row, and the folder runs
    again."""
    monkeypatch.setenv(HOOK_TIMEOUT_ENV, "0.3")
    release, exported = threading.Event(), []

    def edit(row, out):
        row["accuracy"] = -1.0

    def keep_state(row, out):
        (out / "my-plugin-state.json").write_text(json.dumps({"last": row["key"]}))

    registry = registry_with(
        ("quitter", plugin(cell_finished=lambda row, out: sys.exit(0))),
        ("editor", plugin(cell_finished=edit)),
        ("hang", plugin(cell_finished=lambda row, out: release.wait(30))),
        ("state", plugin(cell_finished=keep_state)),
        ("exporter", plugin(cell_finished=lambda row, out: exported.append(row))))
    out = tmp_path / "out"
    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
                  classifiers=["logreg:max_iter=20"], L=[3], seeds=[0, 1], pixel_mm=10,
                  test_per_class=1, threads=1, workers=1, out=str(out))
    try:
        report = run(scene, registry=registry, progress=False, plots=False)
        assert report.computed == 2 and len(report.ok) == 2
        assert (out / "report.md").is_file() and (out / "my-plugin-state.json").is_file()
        stored = {p.stem: json.loads(p.read_text()) for p in (out / "cells").glob("*.json")}
        assert {r["key"]: r for r in exported} == stored  # the true rows, not the edit
        assert all(r["accuracy"] >= 0 for r in stored.values())
        again = run(scene, registry=registry, progress=False, plots=False)
    finally:
        release.set()
    assert again.computed == 0 and again.skipped == 2
    said = warnings_of(caplog)
    assert sum("did not return within" in w for w in said) == 1
    assert sum("called sys.exit" in w for w in said) == 1
