"""``tactbench cache ls|clear``: the encodings kept on disk."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.runner import EncodingCache


def test_ls_and_clear(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    cache = EncodingCache()
    assert cache.root == tmp_path / "cache" / "encodings"
    key = cache.key("h", {"kind": "images", "pixel_mm": 5.0, "method": "linear"}, "raw", "1")
    cache.write(key, [np.zeros((4, 1, 2, 2), np.float32)],
                {"encoder": "raw", "dataset": "tiny", "frames": 4, "encode_seconds": 0.5,
                 "imaging": {"kind": "images", "pixel_mm": 5.0, "method": "linear"}})

    small = cache.key("h", {"kind": "images", "pixel_mm": 5.0, "method": "linear"}, "raw",
                      "1", "uint8")
    cache.write(small, [np.zeros((4, 1, 2, 2), np.float32)],
                {"encoder": "raw", "dataset": "tiny", "frames": 4,
                 "imaging": {"kind": "images", "pixel_mm": 5.0, "method": "linear"}},
                precision="uint8")

    listed = json.loads(CliRunner().invoke(cli, ["cache", "ls", "--json"]).stdout)
    assert listed["root"] == str(cache.root)
    by_key = {e["key"]: e for e in listed["entries"]}
    assert [(by_key[k]["encoder"], by_key[k]["frames"], by_key[k]["precision"])
            for k in (key, small)] == [("raw", 4, "float32"), ("raw", 4, "uint8")]
    frames = {k: (cache.path(k) / "frames.npy").stat().st_size for k in (key, small)}
    assert frames[key] - frames[small] == 16 * 3  # 4 bytes a value → 1
    table = CliRunner().invoke(cli, ["cache", "ls"], env={"COLUMNS": "200"}).output
    assert key[:12] in table and "5.0 mm linear" in table
    line = next(x for x in table.splitlines() if small[:12] in x)
    assert "uint8" in line and "0.0" in line  # precision and size (MB)

    kept = CliRunner().invoke(cli, ["cache", "clear"], input="n\n")
    assert kept.exit_code == 0 and cache.has(key)
    cleared = CliRunner().invoke(cli, ["cache", "clear", "--yes"])
    assert "removed 2" in cleared.output and not cache.has(key)


def test_ls_shows_damaged_entries_and_temporaries_and_clear_removes_orphans(tmp_path,
                                                                          monkeypatch):
    import os
    import subprocess
    import sys

    from tactbench.paths import host_tag

    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    cache = EncodingCache()
    cache.write("good", [np.zeros((4, 3), np.float32)], {"encoder": "raw"})
    cache.write("bad", [np.zeros((4, 3), np.float32)], {"encoder": "frame-diff"})
    with open(cache.path("bad") / "frames.npy", "r+b") as fh:
        fh.truncate(100)
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    orphan = cache.root / f".gone.tmp-{proc.pid}-{host_tag()}-12345678"
    running = cache.root / f".busy.tmp-{os.getpid()}-{host_tag()}-12345678"
    orphan.mkdir()
    running.mkdir()

    listed = json.loads(CliRunner().invoke(cli, ["cache", "ls", "--json"]).stdout)
    states = {e["key"]: (e["state"], e.get("problem", "")) for e in listed["entries"]}
    assert states["good"] == ("ok", "")
    assert states["bad"][0] == "damaged" and "truncated" in states["bad"][1]
    assert {t["key"]: (t["pid"], t["state"]) for t in listed["temporaries"]} == \
        {"gone": (proc.pid, "orphaned"), "busy": (os.getpid(), "in progress")}
    table = CliRunner().invoke(cli, ["cache", "ls"], env={"COLUMNS": "250"}).output
    assert "temporary (orphaned" in table and "temporary (in progress" in table
    assert "damaged" in table

    cleared = CliRunner().invoke(cli, ["cache", "clear", "--yes"])
    assert cleared.exit_code == 0 and "removed 3" in cleared.output
    assert "kept 1 being written" in cleared.output
    assert [p.name for p in cache.root.iterdir()] == [running.name]
