"""``tactbench cache ls|clear``: the encodings kept on disk."""

from __future__ import annotations

import json

import numpy as np
import pytest
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


# -- prune ---------------------------------------------------------------------------

DAY = 86400.0


def _aged(cache, key, frames, days):
    """An entry of ``frames`` frames last used ``days`` ago."""
    import os
    import time

    from tactbench.runner.execution.entries import USED_MARKER, mark_used

    cache.write(key, [np.zeros((frames, 1, 4, 4), np.float32)], {"encoder": "raw"})
    mark_used(cache.path(key))
    t = time.time() - days * DAY
    os.utime(cache.path(key) / USED_MARKER, (t, t))
    return (cache.path(key) / "frames.npy").stat().st_size


def test_prune_removes_the_unused_then_the_least_recently_used_down_to_the_size(
        tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    cache = EncodingCache()
    sizes = {k: _aged(cache, k, 100, days) for k, days in
             (("old", 30), ("older", 40), ("mid", 5), ("new", 1))}

    unused = CliRunner().invoke(cli, ["cache", "prune", "--unused-for", "7d", "--yes"])
    assert unused.exit_code == 0, unused.output
    assert "older" in unused.output and "(unused)" in unused.output
    assert sorted(e["key"] for e in cache.entries()) == ["mid", "new"]
    assert "removed 2 cached encoding(s)" in unused.output

    # room for one entry and a bit: the least recently used of the two goes
    limit = f"{sizes['new'] + 1000}B"
    by_size = CliRunner().invoke(cli, ["cache", "prune", "--max-size", limit, "--yes"])
    assert by_size.exit_code == 0, by_size.output
    assert [e["key"] for e in cache.entries()] == ["new"]
    assert "mid" in by_size.output and "(size)" in by_size.output


def test_prune_dry_run_removes_nothing_and_recent_entries_are_kept(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    cache = EncodingCache()
    _aged(cache, "stale", 10, 3)
    _aged(cache, "recent", 10, 60 / DAY)  # used a minute ago: a run may be reading it
    dry = CliRunner().invoke(cli, ["cache", "prune", "--max-size", "0", "--dry-run"])
    assert dry.exit_code == 0, dry.output
    assert "would remove: stale" in dry.output and "kept: recent" in dry.output
    assert sorted(e["key"] for e in cache.entries()) == ["recent", "stale"]
    asked = CliRunner().invoke(cli, ["cache", "prune", "--max-size", "0"], input="n\n")
    assert asked.exit_code == 0 and cache.has("stale")

    done = CliRunner().invoke(cli, ["cache", "prune", "--max-size", "0", "--yes"])
    assert done.exit_code == 0, done.output
    assert [e["key"] for e in cache.entries()] == ["recent"]


def test_prune_removes_damaged_entries_and_orphans_whatever_the_limit(tmp_path, monkeypatch):
    import subprocess
    import sys

    from tactbench.paths import host_tag

    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    cache = EncodingCache()
    _aged(cache, "good", 10, 2)
    _aged(cache, "bad", 10, 2)
    with open(cache.path("bad") / "frames.npy", "r+b") as fh:
        fh.truncate(100)
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    (cache.root / f".gone.tmp-{proc.pid}-{host_tag()}-12345678").mkdir()
    out = cache.prune(unused_for=30 * DAY)
    assert [(e["key"], e["why"]) for e in out["removed"]] == [("bad", "damaged")]
    assert [t["key"] for t in out["orphans"]] == ["gone"]
    assert [p.name for p in cache.root.iterdir()] == ["good"]


def test_a_run_loading_or_checking_an_entry_marks_it_used(tmp_path):
    import os

    from tactbench.runner.execution.entries import USED_MARKER, last_used, load_encoding

    cache = EncodingCache(tmp_path)
    cache.write("k", [np.zeros((3, 2), np.float32)], {"encoder": "raw"})
    meta_time = (cache.path("k") / "meta.json").stat().st_mtime
    assert not (cache.path("k") / USED_MARKER).exists()
    assert last_used(cache.path("k")) == meta_time  # written: its first use
    os.utime(cache.path("k") / "meta.json", (1e9, 1e9))
    assert last_used(cache.path("k")) == 1e9
    load_encoding(cache.path("k"))
    assert last_used(cache.path("k")) > 1e9 + 365 * DAY
    assert cache.verify("k")["key"] == "k"  # the marker is not one of the entry's files


def test_the_used_marker_is_never_followed_or_opened_when_it_is_not_a_file(tmp_path):
    import os

    from tactbench.runner.execution.entries import USED_MARKER, mark_used

    target = tmp_path / "elsewhere.txt"
    target.write_text("x")
    os.utime(target, (1e9, 1e9))
    entry = tmp_path / "entry"
    entry.mkdir()
    (entry / USED_MARKER).symlink_to(target)
    mark_used(entry)
    assert target.stat().st_mtime == 1e9  # the link was not followed
    (entry / USED_MARKER).unlink()
    os.mkfifo(entry / USED_MARKER)
    mark_used(entry)  # returns at once: a FIFO without a reader is not waited on
    mark_used(tmp_path / "missing")  # nothing to record in: no error


@pytest.mark.parametrize("args, message", [
    ([], "say what to prune"),
    (["--max-size", "lots"], "--max-size must be a size"),
    (["--max-size", "-1GB"], "--max-size must be a size"),
    (["--unused-for", "a week"], "bad duration"),
])
def test_prune_mistakes_are_one_line(tmp_path, monkeypatch, args, message):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    out = CliRunner().invoke(cli, ["cache", "prune", *args])
    assert out.exit_code == 2 and message in out.output
    assert "Traceback" not in out.output


def test_sizes_and_durations_read_as_written():
    from tactbench.budget import parse_bytes
    from tactbench.runner.execution.scene import parse_duration

    assert parse_bytes("20GB", "s") == 20 * 10 ** 9
    assert parse_bytes("500MiB", "s") == 500 * 2 ** 20
    assert parse_bytes("1.5 G", "s") == int(1.5 * 2 ** 30)
    assert parse_bytes("0", "s") == 0 and parse_bytes("512", "s") == 512
    assert parse_duration("7d") == 7 * DAY and parse_duration("1d12h") == 1.5 * DAY
    with pytest.raises(Exception, match="bad duration"):
        parse_duration("1d12")


def test_a_run_whose_encodings_would_not_fit_is_refused_before_encoding(tmp_path,
                                                                       monkeypatch):
    """One line naming what the encodings need and what is free, before any work; nothing
    is left in the cache, and the same run goes through once there is room."""
    import shutil
    from collections import namedtuple

    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    args = ["run", "--dataset", "synthetic-forearm:users=2,repetitions=1", "--encoder", "raw",
            "--encoder", "frame-diff", "--classifier", "logreg:max_iter=20", "-L", "3",
            "--seed", "0", "--pixel-mm", "10", "--out", str(tmp_path / "out"), str(scene)]
    real = shutil.disk_usage
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10 ** 12, 10 ** 12 - 1000, 1000))
    refused = CliRunner().invoke(cli, args)
    assert refused.exit_code != 0
    line = refused.output.strip().splitlines()[-1]
    assert "the encodings of frame-diff, raw need about" in line or \
        "the encodings of raw, frame-diff need about" in line, refused.output
    assert "1000 B free" in line and "cache prune" in line and "Traceback" not in line
    assert EncodingCache().entries() == [] and EncodingCache().temporaries() == []
    monkeypatch.setattr(shutil, "disk_usage", real)
    done = CliRunner().invoke(cli, args)
    assert done.exit_code == 0, done.output
    assert len(EncodingCache().entries()) == 2


def test_an_entry_the_disk_will_not_let_go_of_is_not_reported_removed(tmp_path, monkeypatch):
    from tactbench.runner.execution import cache as cache_module

    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    cache = EncodingCache()
    _aged(cache, "kept", 10, 3)
    monkeypatch.setattr(cache_module, "remove_path", lambda path: None)  # as a read-only disk
    out = CliRunner().invoke(cli, ["cache", "prune", "--max-size", "0", "--yes"])
    assert out.exit_code == 1, out.output
    assert "could not remove" in out.output and "removed 0 cached encoding(s)" in out.output
    assert cache.has("kept")
