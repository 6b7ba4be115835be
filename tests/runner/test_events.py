"""The runner's event hooks: ``cell_finished`` for every stored row, ``look_finished`` for
every look and ``run_finished`` once per run, from ``run`` and ``run --until answered``
alike, each with a record of plain values (tactbench/hookspecs.py,
tactbench/runner/analysis/records.py)."""

from __future__ import annotations

import json
import types
from pathlib import Path

from tactbench import hookimpl
from tactbench.plugins import collect_registry, make_plugin_manager
from tactbench.runner import Scene, comparison_record, run, run_until


def _listening(seen: list) -> object:
    plugin = types.SimpleNamespace(
        cell_finished=hookimpl(lambda row, out: seen.append(("cell", row, out))),
        look_finished=hookimpl(lambda look, out: seen.append(("look", look, out))),
        run_finished=hookimpl(lambda summary, out: seen.append(("run", summary, out))))
    return collect_registry(make_plugin_manager(entry_points=False,
                                                extra=[("events", plugin)]))


def _scene(out: Path, **kw) -> Scene:
    return Scene(dataset="synthetic-forearm:users=2,repetitions=1",
                 encoders=["raw", "frame-diff"], classifiers=["logreg:max_iter=20"],
                 L=[3], seeds=[0], pixel_mm=10, test_per_class=1, out=str(out), workers=1,
                 **kw)


def _plain(value) -> bool:
    """Whether ``value`` is made of JSON values only (it survives a round trip)."""
    return json.loads(json.dumps(value)) == value


def test_every_stored_row_every_look_and_the_run_end_reach_the_plugins(tmp_path):
    seen: list[tuple[str, object, Path]] = []
    out = tmp_path / "out"
    scene = _scene(out, until="answered", primary=["encoder=raw..encoder=frame-diff"],
                   max_runs=5, look_every=5)
    report = run_until(scene, registry=_listening(seen), progress=False, plots=False)
    cells = [(row, where) for kind, row, where in seen if kind == "cell"]
    looks = [(r, where) for kind, r, where in seen if kind == "look"]
    runs = [(r, where) for kind, r, where in seen if kind == "run"]
    assert len(cells) == len(report.rows) == 10
    for row, where in cells:  # the row as stored, after verification
        assert where == out
        assert row == json.loads((out / "cells" / f"{row['key']}.json").read_text())
    # the look's record: plain values, the rows as stored and each comparison's record
    [(look, where)] = looks
    assert where == out and _plain(look)
    assert look["look"] == 1 and look["runs"] == 5 and look["rows"] == report.rows
    assert look["comparisons"] == [comparison_record(c, report.rows)
                                   for c in report.comparisons]
    assert look["answered"] == report.looks["answered"]
    # one run_finished for the whole --until run, after its last look
    assert [kind for kind, _, _ in seen][-2:] == ["look", "run"]
    [(summary, where)] = runs
    assert where == out and _plain(summary)
    assert summary["rows"] == report.rows and summary["comparisons"] == look["comparisons"]
    assert summary["computed"] == report.computed == 10 and summary["skipped"] == 0
    assert sorted(summary["ok"]) == sorted(r["key"] for r in report.ok)
    assert summary["failed"] == []
    assert summary["until"]["look"] == 1 and summary["until"]["runs"] == 5


def test_a_plain_run_ends_with_one_run_finished_and_no_look(tmp_path):
    seen: list[tuple[str, object, Path]] = []
    report = run(_scene(tmp_path / "out"), registry=_listening(seen), progress=False,
                 plots=False)
    assert [kind for kind, _, _ in seen] == ["cell", "cell", "run"]
    summary = seen[-1][1]
    assert _plain(summary) and summary["until"] is None
    assert summary["rows"] == report.rows and summary["computed"] == 2
    assert summary["comparisons"] == [comparison_record(c, report.rows)
                                      for c in report.comparisons]
