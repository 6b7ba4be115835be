"""run(): plan, encode once, run unfinished cells, keep going past a failing cell."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tactbench.runner import run

pytestmark = pytest.mark.usefixtures("one_torch_thread")

#: A fast real classifier for grids whose point is not the model.
FAST_CLF = "logreg:max_iter=20"


def test_run_reports_and_resumes_without_recomputing(tiny_scene, cache):
    scene = tiny_scene()
    first = run(scene, progress=False, cache=cache)
    assert (first.computed, first.skipped) == (4, 0)
    assert len(first.rows) == 4 and first.failed == [] and len(first.ok) == 4
    row = first.rows[0]
    for key in ("status", "accuracy", "per_class_accuracy", "confusion",
                "encode_ms_per_frame", "train_s", "inference_ms_per_sequence", "peak_rss_mb",
                "peak_step", "versions", "split", "split_seed", "device", "run"):
        assert key in row, key
    # a cell's own step, a step of this run, or (here, where earlier tests ran in this
    # process) a peak from before the run
    cell_steps = {"load encoding", "windows", "fit", "predict", "save model",
                  "before this cell"}
    for r in first.rows:
        assert r["peak_step"] in cell_steps or r["peak_step"].endswith(
            "(earlier in this run)"), r["peak_step"]
    assert row["status"] == "ok" and 0.0 <= row["accuracy"] <= 1.0
    assert np.asarray(row["confusion"]).sum() == row["n_test"]
    entries = cache.entries()
    assert sorted(e["encoder"] for e in entries) == ["frame-diff", "raw"]  # once each
    created = {e["key"]: e["created"] for e in entries}

    second = run(scene, progress=False, cache=cache)
    assert (second.computed, second.skipped) == (0, 4)
    assert [r["accuracy"] for r in second.rows] == [r["accuracy"] for r in first.rows]
    assert {e["key"]: e["created"] for e in cache.entries()} == created

    # --rerun recomputes every cell from the cached encodings; same seeds, same numbers
    again = run(replace(scene, rerun=True), progress=False, cache=cache)
    assert again.computed == 4
    assert [r["confusion"] for r in again.rows] == [r["confusion"] for r in first.rows]
    assert {e["key"]: e["created"] for e in cache.entries()} == created


def test_a_failing_cell_does_not_end_the_grid_and_a_rerun_retries_only_it(
        tiny_scene, cache, fake_registry, monkeypatch):
    scene = tiny_scene(encoders=["raw"], classifiers=[FAST_CLF, "failing"], seeds=[0, 1])
    monkeypatch.setenv("TACTBENCH_TEST_FAIL", "1")
    seen = []
    first = run(scene, registry=fake_registry, progress=False, cache=cache,
                on_row=lambda row: seen.append(row["status"]))
    assert (first.computed, len(first.rows)) == (4, 4) and len(seen) == 4
    assert sorted(r["classifier"].split(":")[0] for r in first.failed) == ["failing"] * 2
    assert all(r["classifier"].startswith("logreg") for r in first.ok) and len(first.ok) == 2
    assert {r["error"]["message"] for r in first.failed} == {"deliberate failure in fit"}

    monkeypatch.delenv("TACTBENCH_TEST_FAIL")
    second = run(scene, registry=fake_registry, progress=False, cache=cache)
    assert (second.computed, second.skipped) == (2, 2)  # only the failed cells ran
    assert second.failed == [] and len(second.ok) == 4
    # the finished cells were not touched
    assert [r["finished"] for r in second.rows if r["classifier"].startswith("logreg")] == \
           [r["finished"] for r in first.ok]


def test_run_returns_the_report_it_writes(tiny_scene, cache):
    scene = tiny_scene(encoders=["raw"], classifiers=[FAST_CLF], seeds=[0, 1])
    report = run(scene, progress=False, cache=cache, plots=False)
    doc = json.loads(report.paths["json"].read_text())
    assert doc["rows"] == report.rows and doc["summary"] == report.summaries
    assert doc["comparisons"] == report.comparisons and doc["runs"] == report.runs
    assert [r["cells"] for r in report.runs] == [2] and report.runs[0]["git"]
    assert report.runs[0]["command"] == report.rows[0]["run"]["command"]
    assert sorted(report.paths) == ["csv", "json", "markdown"]
    table = report.table()
    assert [t["key"] for t in table] == [r["key"] for r in report.rows]
    assert table[0]["accuracy"] == report.rows[0]["accuracy"] and "acc_Grasp" in table[0]


def test_results_json_edited_or_deleted_changes_nothing_a_run_computes(
        tiny_scene, cache):
    """The cells are the one store: a results.json edited (another row, another
    accuracy) or deleted is neither read nor trusted; the run resumes from cells/ and
    writes results.json again from them."""
    scene = tiny_scene(encoders=["raw"], classifiers=[FAST_CLF], seeds=[0, 1])
    first = run(scene, progress=False, cache=cache, plots=False)
    path = Path(scene.out) / "results.json"
    doc = json.loads(path.read_text())
    doc["rows"][0]["accuracy"] = 0.0
    doc["rows"].append({**doc["rows"][1], "key": "0123456789abcdef", "seed": 7})
    path.write_text(json.dumps(doc))
    again = run(scene, progress=False, cache=cache, plots=False)
    assert (again.computed, again.skipped) == (0, 2) and again.rows == first.rows
    assert json.loads(path.read_text())["rows"] == first.rows
    path.unlink()
    (Path(scene.out) / "report.md").unlink()
    again = run(scene, progress=False, cache=cache, plots=False)
    assert (again.computed, again.skipped) == (0, 2) and again.rows == first.rows
    assert json.loads(path.read_text())["rows"] == first.rows


def test_one_grid_per_folder_is_decided_by_its_cells_alone(tmp_path, tiny_scene, cache):
    """Cells of another grid refuse a run before any work; a results.json without
    cells (rows no cell holds) is another run's output to replace, not a grid."""
    import shutil

    from tactbench.errors import InputError

    scene = tiny_scene(encoders=["raw"], classifiers=[FAST_CLF], seeds=[0])
    run(scene, progress=False, cache=cache, plots=False)
    report = (Path(scene.out) / "results.json").read_bytes()
    with pytest.raises(InputError, match=r"holds 1 cell\(s\) of another grid "
                                         r"\(raw × logreg L=3 seed=0"):
        run(replace(scene, seeds=[1]), progress=False, cache=cache)
    assert (Path(scene.out) / "results.json").read_bytes() == report
    # a grid that includes the stored cell extends the folder
    assert run(replace(scene, seeds=[0, 1]), progress=False, cache=cache,
               plots=False).computed == 1
    shutil.rmtree(Path(scene.out) / "cells")
    other = run(replace(scene, seeds=[2]), progress=False, cache=cache, plots=False)
    assert other.computed == 1 and [r["seed"] for r in other.rows] == [2]
    assert [r["seed"] for r in json.loads((Path(scene.out) / "results.json")
                                          .read_text())["rows"]] == [2]


def test_per_user_results_need_the_rows_dataset_and_say_when_it_is_gone(
        tmp_path, nolayout_dataset, cache, caplog):
    import shutil

    from tactbench.runner import Scene, render_folder

    scene = Scene(dataset=str(nolayout_dataset), encoders=["raw"], classifiers=[FAST_CLF],
                  L=[3], seeds=[0], test_per_class=1, threads=1, out=str(tmp_path / "out"))
    first = run(scene, progress=False, cache=cache, plots=False)
    assert first.statistics["per_user"] is True
    again = render_folder(scene.out, plots=False)
    assert again.summaries == first.summaries  # the dataset is there: per-user results
    shutil.rmtree(nolayout_dataset)
    gone = render_folder(scene.out, plots=False)
    assert gone.statistics["per_user"] is False and gone.rows == first.rows
    assert "cannot be loaded here" in caplog.text
    report = (tmp_path / "out" / "report.md").read_text()
    assert "per-user results left out: dataset" in report


def test_an_extra_plugin_trains_its_cells(tiny_scene, cache, fake_registry):
    scene = tiny_scene(encoders=["raw"], classifiers=["added-logreg:max_iter=20"], seeds=[0])
    (row,) = run(scene, registry=fake_registry, progress=False, cache=cache).rows
    assert row["status"] == "ok" and row["fit"]["classifier"] == "added-logreg"


def test_ctrl_c_stops_the_run_and_keeps_finished_cells(tiny_scene, cache, fake_registry):
    # cells run in plan order: the logreg cell first, then the interrupted one
    scene = tiny_scene(encoders=["raw"], classifiers=[FAST_CLF, "interrupted"], seeds=[0])
    with pytest.raises(KeyboardInterrupt):
        run(scene, registry=fake_registry, progress=False, cache=cache)
    rows = [json.loads(p.read_text()) for p in (Path(scene.out) / "cells").glob("*.json")]
    assert [(r["status"], r["classifier"].split(":")[0]) for r in rows] == [("ok", "logreg")]


def test_saved_models_work_with_live(tmp_path, tiny_scene, cache):
    from tactbench.classifiers.io import load_model

    scene = tiny_scene(encoders=["frame-diff"], seeds=[0], save_models=True)
    result = run(scene, progress=False, cache=cache)
    (row,) = result.rows
    path = tmp_path / "out" / "models" / f"{row['key']}.safetensors"
    clf, meta = load_model(path)
    assert meta["encoder"] == "frame-diff" and meta["L"] == 3
    assert meta["classes"] == row["classes"] and "layout" in meta
    assert meta["test_accuracy"] == row["accuracy"]
    # a finished run asked for models later computes only the cells without one
    path.unlink()
    again = run(scene, progress=False, cache=cache)
    assert again.computed == 1 and path.exists()


def test_saved_models_of_multi_value_taxel_vectors_are_reused(tiny_scene, cache):
    """frame-diff on taxel vectors gives 2 values per taxel: its saved model reads back,
    so a rerun computes nothing (it was refused as damaged and retrained every time)."""
    scene = tiny_scene(encoders=["frame-diff"], seeds=[0], save_models=True,
                       input="vectors",
                       classifiers=["taxel-lstm:epochs=1,windows_per_epoch=16,batch_size=8"])
    first = run(scene, progress=False, cache=cache)
    assert first.computed == 1 and first.failed == []
    again = run(scene, progress=False, cache=cache)
    assert (again.computed, again.skipped) == (0, 1)


@pytest.mark.slow("a real tactbench process is killed mid-grid and resumed (two process starts)")
def test_a_killed_run_loses_only_the_cell_in_progress(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "TACTBENCH_CACHE": str(tmp_path / "cache")}
    clf = "small-cnn-lstm:epochs=2,windows_per_epoch=256,batch_size=16,input_size=16"
    args = [sys.executable, "-m", "tactbench", "run", "--dataset",
            "synthetic-forearm:users=2,repetitions=1",
            "--encoder", "raw", "--classifier", clf, "-L", "2", "-L", "3",
            "--seed", "0", "--seed", "1", "--pixel-mm", "10", "--threads", "1",
            "--out", str(out), "--no-plots"]
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    proc = subprocess.Popen([*args, str(scene)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and len(list((out / "cells").glob("*.json"))) < 1:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = list((out / "cells").glob("*.json"))
    assert 1 <= len(finished) < 4, "the run should have been killed mid-grid"
    for path in finished:
        json.loads(path.read_text())  # every stored row is whole
    resumed = subprocess.run([*args, "--json", str(scene)], env=env, capture_output=True,
                             text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    meta = json.loads(resumed.stdout)["meta"]
    assert meta["skipped"] == len(finished) and meta["computed"] == 4 - len(finished)
