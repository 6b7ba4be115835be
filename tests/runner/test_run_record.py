"""The resolved record of a run (tactbench/runner/execution/record.py): made once, before
the first cell, from the scene and the machine; stored with the run, verified when read
back; read — never made again — by every look, the report, the event hooks and
``reproduce``."""

from __future__ import annotations

import dataclasses
import json
import types
from pathlib import Path

import pytest

from tactbench import hookimpl
from tactbench.errors import InputError
from tactbench.plugins import collect_registry, make_plugin_manager
from tactbench.runner import Scene, render_folder, run, run_until
from tactbench.runner.execution import record as record_module
from tactbench.runner.execution import workers as workers_module
from tactbench.runner.execution.record import (RECORD_FILE, Compute, RunRecord, read_record,
                                               record_of_rows, write_record)
from tactbench.runner.execution.identity import IDENTITY_DEFAULTS

PRIMARY = "encoder=raw..encoder=frame-diff"


def _scene(out: Path, **kw) -> Scene:
    fields = dict(dataset="synthetic-forearm:users=2,repetitions=1",
                  encoders=["raw", "frame-diff"], classifiers=["logreg:max_iter=20"],
                  L=[3], seeds=[0], pixel_mm=10, test_per_class=1, out=str(out), workers=1)
    return Scene(**{**fields, **kw})


def _listening(seen: list):
    plugin = types.SimpleNamespace(
        look_finished=hookimpl(lambda look, out: seen.append(("look", look))),
        run_finished=hookimpl(lambda summary, out: seen.append(("run", summary))))
    return collect_registry(make_plugin_manager(entry_points=False,
                                                extra=[("events", plugin)]))


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))


def test_an_until_run_makes_its_record_once_and_every_look_and_hook_reads_it(
        tmp_path, monkeypatch, private_cache):
    made, decided = [], []
    real_resolve, real_workers = record_module.resolve_record, workers_module.decide_workers
    monkeypatch.setattr("tactbench.runner.orchestrate.resolve_record",
                        lambda *a, **k: made.append(1) or real_resolve(*a, **k))
    monkeypatch.setattr(workers_module, "decide_workers",
                        lambda *a, **k: decided.append(1) or real_workers(*a, **k))
    seen: list = []
    out = tmp_path / "out"
    scene = _scene(out, until="answered", primary=[PRIMARY], max_runs=7, look_every=1)
    report = run_until(scene, registry=_listening(seen), progress=False, plots=False)
    looks = [r for kind, r in seen if kind == "look"]
    [summary] = [r for kind, r in seen if kind == "run"]
    assert len(looks) == len(report.looks["looks"]) >= 1
    assert made == [1] and decided == [1]  # one record, one worker decision, all looks
    stored = json.loads((out / RECORD_FILE).read_text())
    assert all(look["record"]["made"] == stored["made"] for look in looks)
    assert summary["record"] == {k: v for k, v in stored.items() if k != "checksum"}
    record = read_record(out)
    assert record.primary == (PRIMARY,) and record.seed_order == tuple(range(7))
    assert record.looks == (5, 6, 7) and record.workers.count == 1
    # the family named before any cell, as the looks name its comparisons after them
    assert list(record.families) == [PRIMARY]
    assert list(record.families[PRIMARY]) == list(report.looks["looks"][-1]["comparisons"])
    assert record.compute == Compute(1, record.compute.cpu_kernels, "cpu")
    assert record.identity_defaults == IDENTITY_DEFAULTS
    assert record.scene["max_runs"] == 7 and record.paired_test == "corrected-t"


def test_a_stored_record_is_verified_when_read_back(tmp_path, private_cache, caplog):
    out = tmp_path / "out"
    run(_scene(out), progress=False, plots=False)
    record = read_record(out)
    assert isinstance(record, RunRecord) and record.looks == ()
    assert RunRecord.from_json(record.to_json()).to_json() == record.to_json()
    path = out / RECORD_FILE
    doc = json.loads(path.read_text())
    doc["compute"]["threads"] = 4  # edited: its checksum no longer matches
    path.write_text(json.dumps(doc))
    assert read_record(out) is None
    assert "does not match its checksum" in caplog.text
    # the folder's report goes on from its rows' record (the scene its rows stored)
    report = render_folder(out, plots=False)
    assert len(report.rows) == 2
    rows = report.rows
    assert record_of_rows(rows).compute == record.compute
    assert record_of_rows(rows).design == record.design
    # sealed again after an edit, a design that is not its scene's is still refused
    edited = dataclasses.replace(record, design=dataclasses.replace(record.design,
                                                                    looks=(5, 6)))
    write_record(out, edited)
    assert read_record(out) is None and "its design is not its scene's" in caplog.text
    path.write_text("[" * 100_000)  # nested past the parser's depth: one line
    assert read_record(out) is None
    path.write_text("[1, 2]")  # not a record at all
    assert read_record(out) is None
    with pytest.raises(InputError, match="not a run record"):
        RunRecord.from_json({"design": {}})


def test_a_report_rendered_again_takes_its_statistics_from_the_record(tmp_path,
                                                                     private_cache):
    out = tmp_path / "out"
    run(_scene(out, seeds=[0, 1]), progress=False, plots=False)
    before = render_folder(out, plots=False, write=False)
    assert not [c for c in before.comparisons if c.family == "primary"]  # none asked
    record = read_record(out)
    asked = dataclasses.replace(record, design=dataclasses.replace(
        record.design, primary=(PRIMARY,)), scene={**record.scene, "primary": [PRIMARY]})
    write_record(out, asked)
    again = render_folder(out, plots=False, write=False)
    [primary] = [c for c in again.comparisons if c.family == "primary"]
    assert (primary.a, primary.b) == ("raw", "frame-diff")


def test_until_only_fields_are_refused_by_the_scene_itself(tmp_path):
    with pytest.raises(InputError, match="'max_runs' only means something with --until"):
        _scene(tmp_path, max_runs=9)
    with pytest.raises(InputError, match="--budget only means something with --until"):
        Scene.of({"budget": "1h"}, labels={"budget": "--budget"})
    assert _scene(tmp_path, until="answered", primary=[PRIMARY], budget="1h").design.budget == "1h"


def test_the_records_default_paired_test_is_the_analysiss():
    """execution does not import analysis, so the default is written twice: kept equal."""
    from tactbench.runner.analysis.paired_tests import DEFAULT_PAIRED_TEST

    assert record_module.DEFAULT_PAIRED_TEST == DEFAULT_PAIRED_TEST
