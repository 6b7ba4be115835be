"""The runner: grid checks, cached encodings, resumable results, reports, executors."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.errors import UnknownComponentError
from tactbench.runner import EncodingCache, Scene, load_scene_file, parse_lengths, run

# A tiny but real grid: the simulator at 2 users, coarse 10 mm images, a small CNN
# trained for one short epoch. Seconds per cell, not minutes.
TINY_DATASET = "synthetic-forearm:users=2,repetitions=1"
TINY_CLF = "small-cnn-lstm:epochs=1,windows_per_epoch=64,batch_size=16,input_size=16"


def tiny_scene(tmp_path: Path, **over) -> Scene:
    fields = dict(dataset=TINY_DATASET, encoders=["raw", "frame-diff"],
                  classifiers=[TINY_CLF], lengths=[3], seeds=[0, 1], test_per_class=1,
                  pixel_mm=10.0, threads=1, out=str(tmp_path / "out"))
    fields.update(over)
    return Scene(**fields)


@pytest.fixture
def cache(tmp_path):
    return EncodingCache(tmp_path / "cache")


def test_parse_lengths():
    assert parse_lengths(["5"]) == [5]
    assert parse_lengths(["1-3", "6", "2"]) == [1, 2, 3, 6]
    for bad in ("x", "4-2", "1-"):
        with pytest.raises(ValueError, match="bad window length"):
            parse_lengths([bad])


def test_scene_file_fields_and_typos(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('dataset = "x"\nencoder = "raw"\nL = ["1-3"]\nseeds = [4]\n')
    assert load_scene_file(path) == {"dataset": "x", "encoders": ["raw"], "lengths": [1, 2, 3],
                                     "seeds": [4]}
    path.write_text('encoderz = ["raw"]\n')
    with pytest.raises(ValueError, match="unknown field 'encoderz'; did you mean 'encoders'"):
        load_scene_file(path)


@pytest.mark.parametrize("over, error, match", [
    ({"encoders": ["farnback"]}, UnknownComponentError, "did you mean 'farneback'"),
    ({"classifiers": ["small-cnn"]}, UnknownComponentError, "unknown classifier"),
    ({"lengths": [0, 5]}, ValueError, "L must be ≥ 1"),
    ({"encoders": ["raw:winsize=3"]}, ValueError, "no option 'winsize'"),
    ({"split": "random"}, ValueError, "unknown split"),
])
def test_the_whole_grid_is_checked_before_any_work(tmp_path, cache, over, error, match):
    scene = tiny_scene(tmp_path, **over)
    with pytest.raises(error, match=match):
        run(scene, progress=False, cache=cache)
    assert not (tmp_path / "out").exists() and not any(cache.root.iterdir())


def test_image_encoder_on_a_dataset_without_layout_is_refused(tmp_path, cache):
    from tactbench.data.recording import Dataset, Recording, Sample

    rec = Recording(np.zeros((4, 3), np.float32), np.arange(4) * 0.1, np.arange(3))
    samples = [Sample(rec, label=i % 2, user=f"u{i}", position="front", repetition=0,
                      source="test") for i in range(4)]
    Dataset(name="nolayout", samples=samples, classes=("a", "b"), layout=None).save(
        tmp_path / "nolayout")
    scene = tiny_scene(tmp_path, dataset=str(tmp_path / "nolayout"), encoders=["raw"])
    with pytest.raises(ValueError, match="has no taxel layout"):
        run(scene, progress=False, cache=cache)


def test_run_reports_and_resumes_without_recomputing(tmp_path, cache):
    scene = tiny_scene(tmp_path)
    first = run(scene, progress=False, cache=cache)
    assert (first.computed, first.skipped) == (4, 0)
    assert len(first.rows) == 4
    row = first.rows[0]
    for key in ("accuracy", "per_class_accuracy", "confusion", "encode_ms_per_frame",
                "train_s", "inference_ms_per_sequence", "peak_rss_mb", "versions",
                "split", "split_seed", "device", "run"):
        assert key in row, key
    assert 0.0 <= row["accuracy"] <= 1.0
    assert np.asarray(row["confusion"]).sum() == row["n_test"]
    entries = cache.entries()
    assert sorted(e["encoder"] for e in entries) == ["frame-diff", "raw"]  # once each
    created = {e["key"]: e["created"] for e in entries}

    second = run(scene, progress=False, cache=cache)
    assert (second.computed, second.skipped) == (0, 4)
    assert [r["accuracy"] for r in second.rows] == [r["accuracy"] for r in first.rows]
    assert {e["key"]: e["created"] for e in cache.entries()} == created

    # --rerun recomputes every cell from the cached encodings; same seeds, same numbers
    again = run(Scene(**{**scene.__dict__, "rerun": True}), progress=False, cache=cache)
    assert again.computed == 4
    assert [r["confusion"] for r in again.rows] == [r["confusion"] for r in first.rows]
    assert {e["key"]: e["created"] for e in cache.entries()} == created


def test_reports_are_written(tmp_path, cache):
    from tactbench.runner.reports import summarise, write_reports

    result = run(tiny_scene(tmp_path, seeds=[0]), progress=False, cache=cache)
    paths = write_reports(tmp_path / "out", result.rows, meta={"command": "test"})
    for name in ("results.json", "results.csv", "report.md", "accuracy_vs_L.png",
                 "cost_vs_accuracy.png"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    assert len(list((tmp_path / "out").glob("confusion_*.png"))) == 2
    doc = json.loads(paths["json"].read_text())
    assert len(doc["rows"]) == 2 and len(doc["summary"]) == 2
    csv_lines = paths["csv"].read_text().splitlines()
    assert len(csv_lines) == 3 and "acc_" in csv_lines[0]
    summary = summarise(result.rows)[0]
    assert abs(sum(summary["confusion_normalised"][0]) - 1.0) < 1e-9


def test_cli_run_json_and_cache_commands(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    args = ["run", "--dataset", TINY_DATASET, "--encoder", "raw", "--classifier", TINY_CLF,
            "-L", "2", "--seed", "0", "--pixel-mm", "10", "--threads", "1",
            "--out", str(tmp_path / "out"), "--json", "--no-plots"]
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    result = CliRunner().invoke(cli, [*args, str(scene)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["meta"]["computed"] == 1 and doc["summary"][0]["L"] == 2
    listed = json.loads(CliRunner().invoke(cli, ["cache", "ls", "--json"]).stdout)
    assert [e["encoder"] for e in listed["entries"]] == ["raw"]
    cleared = CliRunner().invoke(cli, ["cache", "clear", "--yes"])
    assert "removed 1" in cleared.output
    bad = CliRunner().invoke(cli, ["run", "--encoder", "farnebak", "--out",
                                   str(tmp_path / "o2")])
    assert bad.exit_code != 0 and "did you mean 'farneback'" in bad.output


@pytest.mark.slow
def test_a_killed_run_loses_only_the_cell_in_progress(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "TACTBENCH_CACHE": str(tmp_path / "cache")}
    clf = "small-cnn-lstm:epochs=2,windows_per_epoch=256,batch_size=16,input_size=16"
    args = [sys.executable, "-m", "tactbench", "run", "--dataset", TINY_DATASET,
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


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_results_as_local(tmp_path, cache):
    pytest.importorskip("distributed")
    local = run(tiny_scene(tmp_path, out=str(tmp_path / "a")), progress=False, cache=cache)
    dask = run(tiny_scene(tmp_path, out=str(tmp_path / "b"), executor="dask", workers=2),
               progress=False, cache=cache)
    assert dask.computed == 4
    key = lambda r: (r["encoder"], r["L"], r["seed"])  # noqa: E731
    assert [(key(r), r["confusion"]) for r in sorted(local.rows, key=key)] == \
           [(key(r), r["confusion"]) for r in sorted(dask.rows, key=key)]


def test_saved_models_work_with_live(tmp_path, cache):
    from tactbench.classifiers.io import load_model

    scene = tiny_scene(tmp_path, encoders=["frame-diff"], seeds=[0], save_models=True)
    result = run(scene, progress=False, cache=cache)
    (row,) = result.rows
    path = tmp_path / "out" / "models" / f"{row['key']}.safetensors"
    clf, meta = load_model(path)
    assert meta["encoder"] == "frame-diff" and meta["length"] == 3
    assert meta["classes"] == row["classes"] and "layout" in meta
    assert meta["test_accuracy"] == row["accuracy"]
    # a finished run asked for models later computes only the cells without one
    path.unlink()
    again = run(scene, progress=False, cache=cache)
    assert again.computed == 1 and path.exists()
