"""The device is in a cell's identity (a GPU cell never stands in for a CPU cell, nor the
reverse; CPU cells keep their keys), and each worker owns a device of its own."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
import multiprocessing

import pytest

from tactbench.errors import InputError
from tactbench.runner.execution import devices
from tactbench.runner.execution.identity import digest, row_identity
from tactbench.runner.execution.results import check_row
from tactbench.runner.execution.scene import Scene

TINY = dict(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
            classifiers=["logreg"], L=[3], seeds=[0], test_per_class=1, pixel_mm=10.0)


@pytest.fixture
def fake_gpus(monkeypatch):
    """This machine seen as one with two CUDA devices (there is none here)."""
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)


def test_a_cuda_cell_has_another_key_than_its_cpu_cell_and_cpu_keys_are_unchanged(fake_gpus):
    from tactbench.runner import plan

    cpu, cuda = plan(Scene(**TINY)), plan(Scene(**TINY, device="cuda:1"))
    cpu_id, cuda_id = (p.identities[p.cells[0].key] for p in (cpu, cuda))
    assert "device" not in cpu_id  # left out at its default: CPU keys as they were
    assert cuda_id == {**cpu_id, "device": "cuda"}
    assert cpu.cells[0].key != cuda.cells[0].key
    assert cpu.cells[0].key == digest(cpu_id)
    # auto resolves once, at planning, to the kind this machine has
    auto = plan(Scene(**TINY, device="auto"))
    assert auto.cells[0].key == cuda.cells[0].key


def test_a_row_of_one_device_is_refused_as_the_cell_of_the_other():
    row = {"key": "k", "encoder": "raw", "classifier": "logreg", "L": 3, "seed": 0,
           "status": "failed", "error": {}, "device": "cuda"}
    assert "records device = 'cuda', the cell has 'cpu'" in check_row(row, "k", {})
    assert check_row({**row, "device": "cpu"}, "k", {}) is None
    assert "records device = 'cpu'" in check_row({**row, "device": "cpu"}, "k",
                                                 {"device": "cuda"})
    # a stored CPU row reads back the identity (and key) it always had
    assert "device" not in row_identity({**row, "device": "cpu"})


def test_a_worker_refuses_a_device_of_another_kind_than_the_identity_says(fake_gpus):
    import torch

    with pytest.raises(RuntimeError, match="computes on cpu, the cell's identity says cuda"):
        devices.check_device({"device": "cuda"}, "cpu")
    with pytest.raises(RuntimeError, match="computes on cuda:1, the cell's identity says cpu"):
        devices.check_device({}, "cuda:1")
    assert devices.check_device({"device": "cuda"}, "cuda:1") == "cuda:1"
    torch.cuda.is_available = lambda: False  # undone by the fixture
    with pytest.raises(InputError, match="CUDA is not available"):  # a worker without it
        devices.check_device({"device": "cuda"}, "cuda")


def test_each_worker_owns_one_gpu_and_a_cell_trains_on_the_one_it_owns(fake_gpus):
    assert devices.owned_devices("cuda") == ["cuda:0", "cuda:1"]
    assert devices.owned_devices("cuda:1") == ["cuda:1"]
    assert devices.owned_devices("cpu") is None
    with pytest.raises(InputError, match="no CUDA device"):
        devices.owned_devices("cuda", count=0)
    try:
        assert devices.cell_device({"device": "cuda"}, "cuda") == "cuda"
        devices.own_device("cuda:1")
        assert devices.cell_device({"device": "cuda"}, "cuda") == "cuda:1"
    finally:
        devices.own_device(None)
    assert devices.cell_device({}, "cpu") == "cpu"
    assert devices.cell_device({"device": "cuda"}, "auto") == "cuda"  # planned: resolved


def test_auto_is_refused_on_dask_where_the_workers_decide():
    with pytest.raises(InputError, match="--device auto with --executor dask"):
        devices.resolve_kind("auto", "dask")
    assert devices.resolve_kind("cuda:3", "dask") == "cuda"


def test_local_workers_each_take_their_own_device_from_the_run():
    from tactbench.runner.execution.executors import _start_local_worker

    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    for device in ("cuda:0", "cuda:1"):
        queue.put(device)
    with ProcessPoolExecutor(2, initializer=_start_local_worker, initargs=(queue,),
                             mp_context=context) as pool:  # spawn: both start at once
        used = {f.result() for f in [pool.submit(devices.cell_device, {"device": "cuda"},
                                                 "cuda") for _ in range(8)]}
    assert used <= {"cuda:0", "cuda:1"}  # each cell on the device its worker owns
    assert queue.empty()  # and each of the two workers took one of its own
    queue.close()


def test_a_local_dask_worker_owns_the_device_of_its_place(monkeypatch):
    pytest.importorskip("distributed")
    import distributed

    from tactbench.runner.execution import executors

    seen = []
    monkeypatch.setattr(executors, "run_cell", lambda job: seen.append(
        devices._OWNED[0] if devices._OWNED else None))
    for name in (0, 1, 2):
        monkeypatch.setattr(distributed, "get_worker",
                            lambda name=name: type("W", (), {"name": name})())
        executors._dask_cell(None, ["cuda:0", "cuda:1", "cuda:2"])
    devices.own_device(None)
    assert seen == ["cuda:0", "cuda:1", "cuda:2"]


def test_a_row_names_the_gpu_it_trained_on(fake_gpus, monkeypatch):
    import torch

    monkeypatch.setattr(torch.cuda, "get_device_name", lambda d: f"GPU {d.index}")
    assert devices.device_label("cuda:1") == "cuda:1 (GPU 1)"
    assert devices.device_label("cpu") == "cpu"
