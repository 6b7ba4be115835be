"""Hardening, round five: a cache shared with running runs (leases honoured by ``cache
prune`` and ``cache clear``, listing beside pruning, sizes and durations with their units,
marks dated in the future, ``TACTBENCH_CACHE`` expanded)."""

from __future__ import annotations

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
from tactbench.errors import InputError
from tactbench.paths import cache_root
from tactbench.runner import EncodingCache
from tactbench.runner.execution.cache import KEEP_RECENT_S
from tactbench.runner.execution.entries import USED_MARKER, mark_used
from tactbench.runner.execution.leases import LEASES, live_leases

DAY = 86400.0


def _entry(cache: EncodingCache, key: str, days: float = 3) -> None:
    """An entry last used ``days`` ago."""
    cache.write(key, [np.zeros((10, 1, 4, 4), np.float32)], {"encoder": "raw"})
    mark_used(cache.path(key))
    t = time.time() - days * DAY
    os.utime(cache.path(key) / USED_MARKER, (t, t))


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    return EncodingCache()


def test_prune_and_clear_keep_what_a_live_run_holds_a_lease_on(cache):
    _entry(cache, "inuse")
    _entry(cache, "idle")
    with cache.lease():
        cache.hold(["inuse"])
        pruned = CliRunner().invoke(cli, ["cache", "prune", "--max-size", "0", "--yes"])
        assert pruned.exit_code == 0, pruned.output
        assert "kept: inuse" in pruned.output and "in use by a running run" in pruned.output
        assert f"pid {os.getpid()} on this machine" in pruned.output
        listed = CliRunner().invoke(cli, ["cache", "ls", "--json"])
        assert '"inuse": "pid' in listed.output and '"idle": "pid' not in listed.output
        assert [e["key"] for e in cache.entries()] == ["inuse"]
        cleared = CliRunner().invoke(cli, ["cache", "clear", "--yes"])
        assert cleared.exit_code == 0, cleared.output
        assert cache.has("inuse") and "kept 1 in use by running runs" in cleared.output
    assert live_leases(cache.root) == []  # the lease ends with its block
    assert cache.prune(max_bytes=0)["removed"][0]["key"] == "inuse"


@pytest.mark.slow("runs a two-cell grid (~3 s) and prunes between its cells")
def test_a_lease_outlives_the_used_mark_through_the_whole_run(cache, tmp_path):
    """A run's entries are leased for its whole life: a prune between its cells (marks
    aged past the recent-use guard) keeps every entry the run uses."""
    from tactbench.runner import Scene, run

    seen = []

    def prune_now(row):  # as a neighbour's `cache prune` while the run goes on
        seen.append(cache.prune(max_bytes=0, now=time.time() + 10 * KEEP_RECENT_S))

    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1,positions=1",
                  encoders=["raw"],
                  classifiers=["logreg:max_iter=20"], L=[3], seeds=[0, 1], pixel_mm=10,
                  test_per_class=1, workers=1, out=str(tmp_path / "out"))
    report = run(scene, progress=False, plots=False, on_row=prune_now, cache=cache)
    assert report.computed == 2 and all(r["status"] == "ok" for r in report.rows)
    assert seen and all(not p["removed"] and len(p["leased"]) == 1 for p in seen)
    assert cache.prune(max_bytes=0, now=time.time() + 10 * KEEP_RECENT_S)["removed"]


@pytest.mark.slow("starts a Python process that imports tactbench, then kills it")
def test_the_lease_of_a_killed_run_is_let_go(cache):
    _entry(cache, "inuse")
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time; from tactbench.runner import EncodingCache\n"
         f"c = EncodingCache({str(cache.root)!r})\n"
         "with c.lease():\n    c.hold(['inuse']); print('held', flush=True); time.sleep(60)"],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert cache.prune(max_bytes=0)["leased"][0]["key"] == "inuse"
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert [e["key"] for e in cache.prune(max_bytes=0)["removed"]] == ["inuse"]
    assert list((cache.root / LEASES).glob("*.lease")) == []  # the dead run's lease is gone


def test_a_lease_file_left_unlocked_is_a_dead_runs_and_is_removed(cache):
    _entry(cache, "stale")
    (cache.root / LEASES).mkdir(exist_ok=True)
    left = cache.root / LEASES / "999999-00000000-deadbeef.lease"
    left.write_text('{"pid": 999999, "host": "00000000", "started": 0}\nstale\n')
    assert cache.prune(max_bytes=0)["removed"][0]["key"] == "stale"
    assert not left.exists()


def test_listing_beside_a_prune_that_removes_entries_mid_listing(cache, monkeypatch):
    from tactbench.paths import remove_path
    from tactbench.runner.execution import cache as cache_module

    for key in ("a", "b", "c"):
        _entry(cache, key)
    real = cache_module.verify_entry

    def pruned_meanwhile(folder, **kw):  # a prune beside the listing removes b
        if Path(folder).name == "b":
            remove_path(folder)
        return real(folder, **kw)

    monkeypatch.setattr(cache_module, "verify_entry", pruned_meanwhile)
    out = CliRunner().invoke(cli, ["cache", "ls", "--json"])
    assert out.exit_code == 0, out.output
    assert '"key": "a"' in out.output and '"key": "b"' not in out.output


@pytest.mark.parametrize("args, message", [
    (["--max-size", "20"], "--max-size 20 has no unit"),
    (["--max-size", "1.5"], "--max-size 1.5 has no unit"),
    (["--unused-for", "7"], "--unused-for 7 has no unit"),
])
def test_sizes_and_durations_without_a_unit_are_refused(cache, args, message):
    _entry(cache, "kept")
    out = CliRunner().invoke(cli, ["cache", "prune", *args, "--yes"])
    assert out.exit_code == 2 and message in out.output and "Traceback" not in out.output
    assert len(out.output.strip().splitlines()) == 1 and cache.has("kept")


def test_a_size_of_0_or_in_bytes_needs_no_more(cache):
    _entry(cache, "gone")
    out = CliRunner().invoke(cli, ["cache", "prune", "--max-size", "20B", "--yes"])
    assert out.exit_code == 0 and not cache.has("gone"), out.output


def test_a_used_mark_dated_in_the_future_is_taken_as_now(cache):
    _entry(cache, "future", days=-365)  # a clock set a year ahead
    now = time.time()
    first = cache.prune(max_bytes=0, now=now)
    assert [e["key"] for e in first["held"]] == ["future"]  # used now: within the guard
    assert (cache.path("future") / USED_MARKER).stat().st_mtime <= time.time() + 1
    later = cache.prune(max_bytes=0, now=now + KEEP_RECENT_S + 1)
    assert [e["key"] for e in later["removed"]] == ["future"]


def test_the_cache_variable_expands_home_and_variables(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("TACTBENCH_CACHE", "~/x")
    assert cache_root() == tmp_path / "home" / "x"
    monkeypatch.setenv("LAB", str(tmp_path / "lab"))
    monkeypatch.setenv("TACTBENCH_CACHE", "${LAB}/cache")
    assert EncodingCache().root == tmp_path / "lab" / "cache" / "encodings"
    assert not (tmp_path / "~").exists() and not (tmp_path / "$LAB").exists()
    monkeypatch.setenv("TACTBENCH_CACHE", "$NO_SUCH_TB_VARIABLE/cache")
    with pytest.raises(InputError, match="NO_SUCH_TB_VARIABLE, which is not set"):
        cache_root()
    out = CliRunner().invoke(cli, ["cache", "ls"])
    assert out.exit_code != 0 and "Traceback" not in out.output
    assert "NO_SUCH_TB_VARIABLE" in out.output and not list(tmp_path.glob("$*"))


# -- plans and the room check with a data set per run -----------------------------------

PER_RUN = "synthetic-forearm:users=2,repetitions=1,positions=1,people=per-run"


def _per_run_scene(tmp_path, seeds):
    from tactbench.runner import Scene

    return Scene(dataset=PER_RUN, encoders=["raw"], classifiers=["logreg:max_iter=20"],
                 L=[3], seeds=seeds, split="users", pixel_mm=15.0, test_per_class=1,
                 workers=1, out=str(tmp_path / "out"))


def _written(cache: EncodingCache) -> int:
    return sum(e["bytes"] for e in cache.entries())


def test_plan_counts_every_runs_data_set(cache, tmp_path):
    from tactbench.runner import forecast

    one = forecast(_per_run_scene(tmp_path, [0])).cache_bytes
    two = forecast(_per_run_scene(tmp_path, [0, 1])).cache_bytes
    assert one > 0 and two == 2 * one  # was: the first run's alone


@pytest.mark.slow("plans, then runs a grid of three runs, each on a data set of its own")
def test_a_per_run_grid_writes_what_plan_said(cache, tmp_path):
    from tactbench.runner import run
    from tactbench.runner import forecast

    said = forecast(_per_run_scene(tmp_path, [0, 1, 2])).cache_bytes
    run(_per_run_scene(tmp_path, [0, 1, 2]), progress=False, plots=False, cache=cache)
    assert len(cache.entries()) == 3
    assert abs(_written(cache) - said) < 0.25 * said  # each run's people differ a little


def test_the_room_check_counts_every_runs_data_set_before_writing(cache, tmp_path,
                                                                  monkeypatch):
    import shutil
    from collections import namedtuple

    from tactbench.errors import StorageError
    from tactbench.runner import run
    from tactbench.runner import forecast

    one = forecast(_per_run_scene(tmp_path, [0])).cache_bytes
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10 ** 12, 0, int(1.5 * one)))
    said = CliRunner().invoke(cli, ["plan", "--dataset", PER_RUN, "--encoder", "raw",
                                    "--classifier", "logreg:max_iter=20", "-L", "3",
                                    "--seed", "0-2", "--split", "users", "--pixel-mm", "15",
                                    "--out", str(tmp_path / "out")])
    assert said.exit_code == 0, said.output
    assert "a data set per run: 3 runs' entries" in said.output
    assert "warning: the cache's disk is too small for them" in said.output
    with pytest.raises(StorageError, match="for 3 runs \\(a data set each\\) need about"):
        run(_per_run_scene(tmp_path, [0, 1, 2]), progress=False, plots=False, cache=cache)
    assert cache.entries() == [] and cache.temporaries() == []  # nothing written
