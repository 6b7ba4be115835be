"""The device a cell computes on: its kind in the cell's identity, and a device each worker
owns.

A cell's numbers depend on the device that trained it, so its kind (``cpu``, ``cuda``) is
in its identity (:func:`~tactbench.runner.execution.identity.compute_identity`, left out
at ``cpu``): a GPU cell never stands in for a CPU cell, nor the reverse. ``auto`` is
resolved once, when the run is planned (:func:`resolve_kind`), on this machine; on dask
the workers' machines decide, so there the device is named.

Each worker owns its device (:func:`owned_devices`): on CUDA one process per GPU by
default, each given its own (``cuda:0``, ``cuda:1`` ...), never two on one; CPU workers
share the cores, one thread each. A worker checks, before it trains, that the device it
really has is of the kind the cell's identity says (:func:`check_device`) — in a dask
worker that is the worker's own device, not the planning process's.
"""

from __future__ import annotations

from typing import Any, Mapping

from tactbench.classifiers.training import select_device
from tactbench.errors import InputError
from tactbench.runner.execution.identity import DEFAULT_DEVICE, kind_of

#: The device a process owns, set once when a worker starts (:func:`own_device`); empty
#: in a process that owns none (the run's own process, a dask worker of another cluster).
_OWNED: list[str] = []


def resolve_kind(device: str, executor: str = "local") -> str:
    """The kind of device a run's cells compute on: ``auto`` is CUDA where this machine
    has it, else the CPU (local runs only: on dask the workers' machines decide, so
    ``auto`` is refused there in one line)."""
    kind = kind_of(device)
    if kind != "auto":
        return kind
    if executor != "local":
        raise InputError("--device auto with --executor dask: the workers' machines decide "
                         "what auto means; name the device they train on (cpu or cuda)")
    import torch

    return "cuda" if torch.cuda.is_available() else "cpu"


def gpu_count() -> int:
    """CUDA devices this process sees (0 without torch's CUDA). Imports torch."""
    import torch

    return torch.cuda.device_count() if torch.cuda.is_available() else 0


def owned_devices(device: str, executor: str = "local", *,
                  count: int | None = None) -> list[str] | None:
    """The devices a run's workers own, one each, or None where workers own no device of
    their own (the CPU, whose cores they share; a remote dask cluster, whose workers own
    what their cluster gave them: start one per GPU). ``cuda``: every GPU of this machine
    (``count`` stands in for :func:`gpu_count`), ``cuda:N``: that one."""
    kind = resolve_kind(device, executor)
    if kind != "cuda":
        return None
    name = str(device).strip().lower()
    if name.startswith("cuda:"):
        return [name]
    n = gpu_count() if count is None else count
    if n < 1:
        raise InputError(f"device {device!r} was asked for but this machine has no CUDA "
                         f"device; use --device cpu")
    return [f"cuda:{i}" for i in range(n)]


def own_device(device: str | None) -> None:
    """Make ``device`` the one this (worker) process owns: every cell it trains uses it."""
    _OWNED[:] = [device] if device else []


def start_owning(devices: Any) -> None:
    """A local worker's start: take the next device of the run's queue ``devices``
    (one per worker, put there by the run), or none where the queue is None."""
    own_device(devices.get() if devices is not None else None)


def cell_device(identity: Mapping[str, Any], asked: str) -> str:
    """The device this process trains a cell of ``identity`` on: the one it owns, else
    the device ``asked`` (the scene's) where it names one, else the identity's kind."""
    if _OWNED:
        return _OWNED[0]
    kind = identity.get("device", DEFAULT_DEVICE)
    return asked if kind_of(asked) == kind else kind


def device_label(device: str) -> str:
    """``device`` as a row records the one a cell trained on: a GPU with its model
    (``cuda:1 (NVIDIA H200)``), the CPU as ``cpu``. Imports torch for a GPU."""
    if kind_of(device) != "cuda":
        return str(device)
    import torch

    return f"{device} ({torch.cuda.get_device_name(torch.device(device))})"


def check_device(identity: Mapping[str, Any], device: str) -> str:
    """Refuse to train a cell of ``identity`` on ``device`` when that device is not of
    the kind the identity says, or is missing here (a dask worker without the GPU):
    its numbers would be stored under a key that promises another device. Returns the
    device as torch names it (``cuda:1``)."""
    wanted = identity.get("device", DEFAULT_DEVICE)
    real = select_device(device)  # the device this process really has (raises if none)
    if real.type != wanted:
        raise RuntimeError(f"this worker computes on {real}, the cell's identity says "
                           f"{wanted}: give each worker a device of that kind "
                           f"(docs/runner.md, \"Devices\")")
    return str(real)
