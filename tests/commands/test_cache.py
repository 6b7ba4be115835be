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

    listed = json.loads(CliRunner().invoke(cli, ["cache", "ls", "--json"]).stdout)
    assert listed["root"] == str(cache.root)
    assert [(e["key"], e["encoder"], e["frames"]) for e in listed["entries"]] == \
           [(key, "raw", 4)]
    table = CliRunner().invoke(cli, ["cache", "ls"]).output
    assert key[:12] in table and "5.0 mm linear" in table

    kept = CliRunner().invoke(cli, ["cache", "clear"], input="n\n")
    assert kept.exit_code == 0 and cache.has(key)
    cleared = CliRunner().invoke(cli, ["cache", "clear", "--yes"])
    assert "removed 1" in cleared.output and not cache.has(key)
