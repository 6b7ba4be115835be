"""``tactbench plan``: cells, time and power before any training; a pilot's rows used."""

from __future__ import annotations

import json

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
    [p] = doc["primaries"]
    assert p["sd_source"] == "pilot: 3 stored runs" and p["effect"] == 10
    text = _invoke(tmp_path, monkeypatch, "plan", *TINY, "--seed", "0-5", "--out", str(out))
    assert "floor: no number of runs of these" in text.output
