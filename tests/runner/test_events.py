"""The runner's event hooks: ``cell_finished`` for every stored row and ``look_finished``
for every look, from ``run`` and ``run --until answered`` alike (tactbench/hookspecs.py)."""

from __future__ import annotations

import json
import types
from pathlib import Path

from tactbench import hookimpl
from tactbench.plugins import collect_registry, make_plugin_manager
from tactbench.runner import Scene, run_until


def test_every_stored_row_and_every_look_reach_the_plugins(tmp_path):
    seen: list[tuple[str, object, Path]] = []
    plugin = types.SimpleNamespace(
        cell_finished=hookimpl(lambda row, out: seen.append(("cell", row, out))),
        look_finished=hookimpl(lambda report, out: seen.append(("look", report, out))))
    registry = collect_registry(make_plugin_manager(entry_points=False,
                                                    extra=[("events", plugin)]))
    out = tmp_path / "out"
    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1",
                  encoders=["raw", "frame-diff"], classifiers=["logreg:max_iter=20"],
                  L=[3], seeds=[0], pixel_mm=10, test_per_class=1, out=str(out),
                  until="answered", primary=["encoder=raw..encoder=frame-diff"],
                  max_runs=5, look_every=5)
    report = run_until(scene, registry=registry, progress=False, plots=False)
    cells = [(row, where) for kind, row, where in seen if kind == "cell"]
    looks = [(r, where) for kind, r, where in seen if kind == "look"]
    assert len(cells) == len(report.rows) == 10
    for row, where in cells:  # the row as stored, after verification
        assert where == out
        assert row == json.loads((out / "cells" / f"{row['key']}.json").read_text())
    # the look's report as it was when the look ended (a copy of its own)
    assert [(r.rows, r.comparisons) for r, _ in looks] == [(report.rows, report.comparisons)]
    assert looks[0][1] == out
    assert seen[-1][0] == "look"  # after the look's cells
