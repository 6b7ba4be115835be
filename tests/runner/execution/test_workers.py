"""The worker count is decided once (workers.py), from the cores, the GPUs and the memory,
and every reader (executors, looks, estimate, plan) takes that one count."""

from __future__ import annotations

import pytest

from tactbench.errors import InputError
from tactbench.runner.execution import workers as workers_module
from tactbench.runner.execution.scene import Scene
from tactbench.runner.execution.workers import (WORKER_BASE_MB, decide_workers, run_workers,
                                                worker_peak)


def test_cells_share_the_cores_one_thread_each():
    """The thread count is fixed (1, in no identity); the cores go to cells side by side."""
    assert Scene().threads == 1 and decide_workers(Scene(), cores=8).count == 8
    assert decide_workers(Scene(threads=2), cores=8).count == 4  # threads × cells ≤ cores
    assert decide_workers(Scene(workers=3), cores=8).limit == "--workers"
    assert decide_workers(Scene(threads=16), cores=8).count == 1


def test_the_memory_bounds_the_workers_beside_the_runs_own_process():
    # 8 cores, 12 GiB, a 1 GiB parent and 3.94 GiB workers (the paper cnn-lstm's peak)
    w = decide_workers(Scene(), cores=8, memory_mb=12 * 1024, parent_peak_mb=1024,
                       worker_peak_mb=3.94 * 1024)
    assert (w.count, w.limit) == (2, "memory")
    assert w.run_peak_mb == pytest.approx(1024 + 2 * 3.94 * 1024)  # every process
    # never below one: a single worker runs in the run's own process
    one = decide_workers(Scene(), cores=8, memory_mb=4096, parent_peak_mb=1024,
                         worker_peak_mb=3.94 * 1024)
    assert (one.count, one.limit) == (1, "memory")
    assert one.run_peak_mb == pytest.approx(1024 + 3.94 * 1024 - WORKER_BASE_MB)
    # plenty of memory: the cores decide
    assert decide_workers(Scene(), cores=2, memory_mb=24 * 1024, parent_peak_mb=1024,
                          worker_peak_mb=1500).limit == "cores"


def test_one_worker_per_gpu_by_default_and_never_two_on_one():
    two = ["cuda:0", "cuda:1"]
    assert decide_workers(Scene(device="cuda"), cores=16, devices=two).count == 2
    assert decide_workers(Scene(device="cuda", workers=1), devices=two).count == 1
    with pytest.raises(InputError, match="each worker owns one GPU"):
        decide_workers(Scene(device="cuda", workers=3), devices=two)


def test_a_workers_peak_is_the_largest_a_stored_cell_measured_else_the_plans_estimate():
    class P:
        classifier_specs = ["logreg"]
        batch_bytes = 64 << 20

    rows = [{"classifier": "logreg", "peak_rss_mb": 700.0},
            {"classifier": "logreg", "peak_rss_mb": 900.0, "status": "failed"},
            {"classifier": "other", "peak_rss_mb": 5000.0}]
    assert worker_peak(rows, P())[0] == 700.0
    peak, source = worker_peak([], P())
    bank = workers_module.bank_budget_bytes() / 2 ** 20
    assert peak == pytest.approx(WORKER_BASE_MB + bank + 128) and "at least" in source
    assert worker_peak([]) == (None, "not forecast")


def test_run_workers_reads_this_machine(monkeypatch):
    monkeypatch.setattr(workers_module, "memory_bytes", lambda: 6 << 30)
    rows = [{"classifier": "x", "peak_rss_mb": 2048.0}]
    w = run_workers(Scene(), rows, parent_peak_mb=1024)
    assert w.memory_mb == 6 * 1024 and w.worker_peak_mb == 2048.0
    assert w.count == min(workers_module.usable_cores(), 2)


def test_no_scene_works_out_its_own_worker_count():
    """One place decides: the scene has no rule of its own any more."""
    assert not hasattr(Scene, "resolved_workers")


def test_memory_caps_the_whole_run_and_a_forecast_above_it_is_refused(monkeypatch):
    """``--memory``: the run's processes together; the count fits in it, and a run whose
    forecast peak is above it is refused in one line before any training."""
    monkeypatch.setattr(workers_module, "memory_bytes", lambda: 24 << 30)
    monkeypatch.setattr(workers_module, "usable_cores", lambda: 2)
    rows = [{"classifier": "x", "peak_rss_mb": 1500.0}]
    free = run_workers(Scene(), rows, parent_peak_mb=500)
    assert (free.count, free.memory_source) == (2, "this machine")
    capped = run_workers(Scene(memory="3GiB"), rows, parent_peak_mb=500)
    assert (capped.count, capped.limit, capped.memory_source) == (1, "memory", "--memory")
    assert capped.memory_mb == 3072 and capped.run_peak_mb <= 3072
    with pytest.raises(InputError, match=r"--memory 1GiB: the run's forecast peak is 1\.56 GiB"):
        run_workers(Scene(memory="1GiB"), rows, parent_peak_mb=500)
    with pytest.raises(InputError, match="scene field 'memory' must be a size"):
        Scene(memory="lots")
    with pytest.raises(InputError, match="--memory must be at least 64MiB"):
        Scene.of({"memory": "1MiB"}, labels={"memory": "--memory"})


def test_under_a_memory_cap_cells_run_side_by_side_only_on_a_measured_peak(monkeypatch):
    """Without a pilot, a worker's forecast is a floor: under --memory one cell runs at a
    time until a stored cell has measured a peak."""
    monkeypatch.setattr(workers_module, "memory_bytes", lambda: 24 << 30)
    monkeypatch.setattr(workers_module, "usable_cores", lambda: 2)
    floor = run_workers(Scene(memory="4GiB"), [], parent_peak_mb=500)
    assert (floor.count, floor.limit) == (1, "--memory without a measured peak")
    measured = run_workers(Scene(memory="4GiB"), [{"classifier": "x", "peak_rss_mb": 1000.0}],
                           parent_peak_mb=500)
    assert measured.count == 2  # 500 + 2 × 1000 MiB fit in 4 GiB
    assert run_workers(Scene(memory="4GiB", workers=2), [], parent_peak_mb=500).count == 2
