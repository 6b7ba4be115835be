"""``tactbench plan``: cells, time and power before any training; a pilot's rows used."""

from __future__ import annotations

import json
import re

import pytest
from click.testing import CliRunner

from tactbench.cli import cli

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = ["--dataset", "synthetic-forearm:users=2,repetitions=1", "--encoder", "raw",
        "--encoder", "frame-diff", "--classifier", "logreg:max_iter=20", "-L", "3",
        "--pixel-mm", "10", "--threads", "1", "--primary", "encoder=raw..encoder=frame-diff"]


def _invoke(tmp_path, monkeypatch, *args: str):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    return CliRunner().invoke(cli, [*args, str(scene)], catch_exceptions=False)


def test_plan_trains_nothing_and_says_what_it_cannot_know(tmp_path, monkeypatch):
    out = tmp_path / "out"
    res = _invoke(tmp_path, monkeypatch, "plan", *TINY, "--seed", "0-3", "--out", str(out),
                  "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert len(doc["cells"]) == 8 and doc["seconds"] is None and doc["unknown"] == 8
    assert not (out / "cells").exists()  # nothing trained, nothing stored
    [p] = doc["primaries"]
    assert p["runs"] == 4 and "no pilot" in p["sd_source"]
    assert 0 < p["power"] < 1 and p["detectable"] > p["floor"] > 0


def test_a_pilots_rows_give_times_and_the_spread(tmp_path, monkeypatch):
    out = tmp_path / "out"
    pilot = _invoke(tmp_path, monkeypatch, "run", *TINY, "--seed", "0-2", "--out", str(out))
    assert pilot.exit_code == 0, pilot.output
    res = _invoke(tmp_path, monkeypatch, "plan", *TINY, "--seed", "0-5", "--out", str(out),
                  "--json", "--effect", "10")
    doc = json.loads(res.output)
    sources = [c["source"] for c in doc["cells"]]
    assert sources.count("finished (stored)") == 6
    assert all(s.startswith("pilot: median of 3") for s in sources if "finished" not in s)
    assert doc["unknown"] == 0 and doc["seconds"] > 0 and doc["peak_mb"] > 0
    # a worker's forecast peak is the pilot's largest; the run's adds its own process
    assert doc["worker_peak_mb"] == doc["peak_mb"] and "stored cell" in doc[
        "worker_peak_source"]
    assert doc["run_peak_mb"] > doc["worker_peak_mb"] - 406 and doc["workers"] >= 1
    [p] = doc["primaries"]
    assert p["sd_source"].startswith("pilot: 3 stored runs") and p["effect"] == 10
    # this tiny pilot's models agree on every recording: that is no spread of 0
    assert p["power"] < 1 and p["sd"] > 0
    text = _invoke(tmp_path, monkeypatch, "plan", *TINY, "--seed", "0-5", "--out", str(out))
    assert "floor: no number of runs of these" in text.output
    assert re.search(r"memory: \d+ worker\(s\) at once \(set by (cores|memory)\), each at "
                     r"about [\d.]+ GiB \(the largest of \d+ stored cell\(s\)\)", text.output)
    assert "the whole run, its own process and every worker, about" in text.output


def test_without_a_pilot_the_spread_is_an_assumption_and_warnings_come_first(tmp_path,
                                                                            monkeypatch):
    out = tmp_path / "out"
    res = _invoke(tmp_path, monkeypatch, "plan", *TINY, "--seed", "0-3", "--out", str(out),
                  "--margin", "2", "--effect", "1")
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert "lower bound" not in res.output and "upper bound" not in res.output
    assert "assumed, no pilot: the models disagree on 30% of the" in res.output
    warned = [i for i, line in enumerate(lines) if line.startswith("warning: ")]
    first = next(i for i, line in enumerate(lines) if line.startswith("primary "))
    assert warned and max(warned) < first  # said before the forecast, a line each
    assert any("inside the ±2 margin" in lines[i] for i in warned)
    assert any("short of 80 %" in lines[i] for i in warned)


def test_a_sequential_run_is_forecast_by_its_own_procedure(tmp_path, monkeypatch):
    out = tmp_path / "out"
    res = _invoke(tmp_path, monkeypatch, "plan", *TINY, "--until", "answered",
                  "--max-runs", "10", "--out", str(out), "--json")
    assert res.exit_code == 0, res.output
    [p] = json.loads(res.output)["primaries"]
    seq = p["sequential"]
    assert seq["looks"] == [5, 10] and seq["max_runs"] == 10
    assert 5 <= seq["expected_runs"] <= 10 and 0 <= seq["futile"] <= 1
    assert seq["power"] <= p["power"] + 4 * seq["mc_error"]  # looking costs power


def test_without_a_pilot_a_torch_cell_is_timed_here_and_the_wall_time_forecast(tmp_path,
                                                                              monkeypatch):
    """No stored row: the CNN's cells are estimated from a few of its own training steps,
    the encoding from a sample, and the run's wall time is forecast at every look."""
    cnn = "small-cnn-lstm:epochs=1,windows_per_epoch=64,batch_size=16,input_size=16"
    args = [a if a != "logreg:max_iter=20" else cnn for a in TINY]
    res = _invoke(tmp_path, monkeypatch, "plan", *args, "--out", str(tmp_path / "out"),
                  "--until", "answered", "--max-runs", "10", "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["unknown"] == 0 and len(doc["cells"]) == 20
    assert all(c["source"].startswith("estimated here") and c["seconds"] > 0
               for c in doc["cells"])
    first, last = doc["wall_s"]
    assert doc["looks"] == [5, 10] and 0 < first < last
    text = _invoke(tmp_path, monkeypatch, "plan", *args, "--out", str(tmp_path / "out"),
                   "--until", "answered", "--max-runs", "10")
    assert "min to the first look (5 runs)" in text.output


def test_cells_are_packed_onto_the_workers_longest_first():
    from tactbench.runner.execution.estimate import packed

    assert packed([3, 2, 2, 1], 2) == 4
    assert packed([5, 1, 1, 1], 2) == 5
    assert packed([1, 1, 1], 1) == 3 and packed([], 3) == 0


def test_plan_says_what_the_run_adds_to_the_cache_and_whether_it_fits(tmp_path, monkeypatch):
    """The bytes plan forecasts are the bytes of the frames the run then writes; once they
    are there, nothing; a disk too small for them is a warning before the run's refusal."""
    import shutil
    from collections import namedtuple

    import numpy as np

    from tactbench.runner import EncodingCache

    out = tmp_path / "out"
    args = [*TINY, "--seed", "0", "--out", str(out)]
    doc = json.loads(_invoke(tmp_path, monkeypatch, "plan", *args, "--json").output)
    assert doc["cache_bytes"] > 0 and doc["cache_free"] > 0
    assert "cache: about" in _invoke(tmp_path, monkeypatch, "plan", *args).output

    real = shutil.disk_usage
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10 ** 12, 10 ** 12 - 10, 10))
    small = _invoke(tmp_path, monkeypatch, "plan", *args).output
    assert "(10 B free on its disk)" in small and "the run would be refused" in small
    monkeypatch.setattr(shutil, "disk_usage", real)

    assert _invoke(tmp_path, monkeypatch, "run", *args).exit_code == 0
    data = sum(int(np.load(EncodingCache().path(e["key"]) / "frames.npy",
                           mmap_mode="r").nbytes) for e in EncodingCache().entries())
    assert data == doc["cache_bytes"]  # the frames, without the .npy headers
    again = _invoke(tmp_path, monkeypatch, "plan", *args)
    assert "cache: every encoding the run needs is already there" in again.output
