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
