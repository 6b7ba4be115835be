"""Training: seeds, devices, and the loop every torch classifier shares.

Profiles (named sets of classifier options, ``quick`` and ``paper``) are defined in
:mod:`tactbench.profiles`; :func:`profile_options` is re-exported here, where it lived
before.

Seeds
-----
:func:`tactbench.seeds.derive_seed` hashes its parts with SHA-256 (never ``hash()``,
which is salted per process). The loop draws window order from ``numpy`` with the seed
and seeds torch inside :func:`torch.random.fork_rng`, so the caller's global
random state is left as it was. On the CPU the same seed gives the same model.

Devices
-------
``"cpu"`` (default), ``"cuda"``/``"cuda:N"`` (an error when CUDA is absent), or
``"auto"`` (CUDA when available). Mixed precision (``amp``) defaults to on for
CUDA (float16 autocast with a gradient scaler) and off on the CPU; asking for
it on the CPU uses bfloat16 autocast, which is how the tests exercise that path.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Iterable

import numpy as np

from tactbench.errors import InputError
from tactbench.profiles import DEFAULT_PROFILE, PROFILE_NAMES, profile_options
from tactbench.seeds import derive_seed  # re-exported: it lived here before

if TYPE_CHECKING:  # torch stays out of import time
    import torch

__all__ = [  # profiles and derive_seed are re-exported from their homes
    "DEFAULT_PROFILE", "PROFILE_NAMES", "profile_options", "derive_seed", "select_device",
    "Precision", "precision_for", "FitReport", "TrainingInterrupted", "ProgressFn",
    "epoch_order", "make_optimizer", "train_loop",
]

# --------------------------------------------------------------------------- seeds


# --------------------------------------------------------------------------- devices


def select_device(device: str | None = "cpu") -> "torch.device":
    """``"cpu"``, ``"cuda"``, ``"cuda:N"`` or ``"auto"`` → a :class:`torch.device`.

    Asking for CUDA where there is none is an error, not a silent fallback.
    """
    import torch

    name = (device or "cpu").strip().lower()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(name)
    except RuntimeError as exc:
        raise InputError(f"unknown device '{device}': use cpu, cuda, cuda:N or auto") from exc
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise InputError(f"device '{device}' was asked for but CUDA is not available "
                             f"(torch {torch.__version__}); use device='cpu' or 'auto'")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise InputError(f"device '{device}': only {torch.cuda.device_count()} CUDA "
                             f"device(s) present")
    elif dev.type != "cpu":
        raise InputError(f"device type '{dev.type}' is not supported: use cpu or cuda")
    return dev


@dataclass(frozen=True)
class Precision:
    """How the forward pass runs: autocast on/off, its dtype, and whether grads are scaled."""

    enabled: bool
    dtype: "torch.dtype | None"
    scale_gradients: bool

    def autocast(self, device: "torch.device"):
        import torch

        if not self.enabled:
            return torch.autocast(device_type=device.type, enabled=False)
        return torch.autocast(device_type=device.type, dtype=self.dtype)

    def scaler(self, device: "torch.device"):
        import torch

        return torch.amp.GradScaler(device.type, enabled=self.scale_gradients)


def precision_for(device: "torch.device", amp: bool | None) -> Precision:
    """Mixed precision for ``device``: float16 + gradient scaling on CUDA (default there),
    bfloat16 autocast on the CPU when ``amp`` is true (off by default: slower on most CPUs)."""
    import torch

    enabled = (device.type == "cuda") if amp is None else bool(amp)
    if not enabled:
        return Precision(False, None, False)
    if device.type == "cuda":
        return Precision(True, torch.float16, True)
    return Precision(True, torch.bfloat16, False)


# --------------------------------------------------------------------------- the loop


@dataclass
class FitReport:
    """What a training run did; ``as_dict()`` is JSON-ready."""

    classifier: str
    seed: int
    device: str
    amp: bool
    epochs: int = 0  # epochs completed
    steps: int = 0  # optimizer steps taken
    windows_seen: int = 0
    train_windows: int = 0
    train_seconds: float = 0.0
    windows_per_second: float = 0.0
    final_loss: float = float("nan")
    epoch_losses: list[float] = field(default_factory=list)
    val_accuracy: list[float] = field(default_factory=list)
    interrupted: bool = False
    n_classes: int = 0
    options: dict[str, Any] = field(default_factory=dict)
    #: How training batches were made: "frame bank" (frames prepared once, held in
    #: memory) or "per batch" (read from the sequences and prepared for each batch).
    batches: str = "per batch"
    bank_mb: float = 0.0  # size of the frame bank (held only when batches is "frame bank")
    loader_workers: int = 0  # DataLoader processes reading ahead (per batch only)

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        for key in ("final_loss",):
            if isinstance(out[key], float) and not math.isfinite(out[key]):
                out[key] = None
        return out


class TrainingInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`train_loop`: the model holds the last completed step's
    weights and is in eval mode; ``report`` says how far training got."""

    def __init__(self, report: FitReport) -> None:
        super().__init__(f"training interrupted after {report.steps} steps "
                         f"({report.epochs} full epochs)")
        self.report = report


ProgressFn = Callable[..., Any]


def epoch_order(rng: np.random.Generator, n: int, per_epoch: int,
                groups: np.ndarray | None = None) -> np.ndarray:
    """Window indices for one epoch: a permutation of ``n``, cut to (or repeated up to)
    ``per_epoch`` when ``per_epoch > 0``. With ``groups`` (a group number per window),
    the groups are permuted and each group's windows follow one another (in index
    order), so a batch holds whole runs of windows."""
    if n <= 0:
        raise InputError("no training windows")
    if groups is None:
        def permutation() -> np.ndarray:
            return rng.permutation(n)
    else:
        groups = np.asarray(groups)
        if groups.shape != (n,):
            raise ValueError(f"groups has shape {groups.shape}, expected ({n},)")  # a bug
        by_group = np.argsort(groups, kind="stable")
        bounds = np.flatnonzero(np.diff(groups[by_group])) + 1
        members = np.split(by_group, bounds)

        def permutation() -> np.ndarray:
            return np.concatenate([members[g] for g in rng.permutation(len(members))])
    if per_epoch <= 0 or per_epoch == n:
        return permutation()
    reps = -(-per_epoch // n)
    return np.concatenate([permutation() for _ in range(reps)])[:per_epoch]


def make_optimizer(name: str, params, *, lr: float, momentum: float, weight_decay: float):
    import torch

    key = name.lower()
    if key == "sgd":
        return torch.optim.SGD(params, lr=lr, momentum=momentum, weight_decay=weight_decay)
    if key == "adam":
        return torch.optim.Adam(params, lr=lr, weight_decay=weight_decay)
    if key == "adamw":
        return torch.optim.AdamW(params, lr=lr, weight_decay=weight_decay)
    raise InputError(f"unknown optimizer '{name}': use sgd, adam or adamw")


def train_loop(
    model: "torch.nn.Module",
    get_batch: Callable[[np.ndarray], "tuple[torch.Tensor, torch.Tensor]"],
    *,
    n_windows: int,
    report: FitReport,
    epochs: int,
    batch_size: int,
    windows_per_epoch: int,
    optimizer: str,
    lr: float,
    momentum: float = 0.0,
    weight_decay: float = 0.0,
    schedule: str = "constant",
    device: "torch.device",
    precision: Precision,
    progress: ProgressFn | None = None,
    evaluate: Callable[[], float] | None = None,
    load_batches: Callable[[list[np.ndarray]], Iterable[tuple["torch.Tensor", "torch.Tensor"]]]
    | None = None,
    groups: np.ndarray | None = None,
) -> FitReport:
    """Train ``model`` with cross-entropy and fill ``report``.

    ``get_batch(indices)`` returns ``(x, y)`` on ``device`` for those training
    windows. ``load_batches(index_arrays)`` (optional) yields the same ``(x, y)`` for
    each of an epoch's index arrays in order, and may read ahead (a ``DataLoader``
    with workers); without it, ``get_batch`` is called step by step.
    ``progress(done, total, **info)`` is called after every step (``info``: ``epoch``,
    ``epochs``, ``loss``) and after each epoch's evaluation (``val_accuracy``).
    ``evaluate()`` (optional) returns the validation accuracy after each epoch. Random
    order comes from ``report.seed``; the caller seeds torch. ``groups`` (a group
    number per window, optional): batches are drawn as whole groups
    (:func:`epoch_order`).
    """
    import torch
    import torch.nn.functional as F

    if epochs < 0 or batch_size < 1:
        raise InputError(f"epochs must be ≥ 0 and batch_size ≥ 1 (got {epochs}, {batch_size})")
    if schedule not in ("constant", "cosine"):
        raise InputError(f"unknown schedule '{schedule}': use constant or cosine")
    rng = np.random.default_rng(report.seed)
    per_epoch = windows_per_epoch if windows_per_epoch > 0 else n_windows
    # A trailing batch of one window breaks BatchNorm in training mode: drop it.
    steps_per_epoch = per_epoch // batch_size + (1 if per_epoch % batch_size > 1 else 0)
    total = epochs * steps_per_epoch
    opt = make_optimizer(optimizer, model.parameters(), lr=lr, momentum=momentum,
                         weight_decay=weight_decay)
    sched = (torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(total, 1))
             if schedule == "cosine" else None)
    scaler = precision.scaler(device)
    report.train_windows = n_windows
    start = time.perf_counter()
    done = 0
    try:
        for epoch in range(epochs):
            model.train()
            order = epoch_order(rng, n_windows, windows_per_epoch, groups)
            loss_sum, count = 0.0, 0
            indices = [order[s * batch_size:(s + 1) * batch_size]
                       for s in range(steps_per_epoch)]
            stream = (load_batches(indices) if load_batches is not None
                      else (get_batch(idx) for idx in indices))
            for idx, (x, y) in zip(indices, stream):
                opt.zero_grad(set_to_none=True)
                with precision.autocast(device):
                    loss = F.cross_entropy(model(x), y)
                scaler.scale(loss).backward()
                scaler.step(opt)
                scaler.update()
                if sched is not None:
                    sched.step()
                value = float(loss.detach())
                loss_sum += value * len(idx)
                count += len(idx)
                done += 1
                report.steps = done
                report.windows_seen += len(idx)
                if progress is not None:
                    progress(done, total, epoch=epoch + 1, epochs=epochs, loss=value)
            report.epoch_losses.append(loss_sum / max(count, 1))
            report.final_loss = report.epoch_losses[-1]
            report.epochs = epoch + 1
            if evaluate is not None:
                acc = float(evaluate())
                report.val_accuracy.append(acc)
                if progress is not None:
                    progress(done, total, epoch=epoch + 1, epochs=epochs,
                             loss=report.final_loss, val_accuracy=acc)
    except KeyboardInterrupt:
        model.eval()
        report.interrupted = True
        _finish(report, start)
        raise TrainingInterrupted(report) from None
    model.eval()
    _finish(report, start)
    return report


def _finish(report: FitReport, start: float) -> None:
    report.train_seconds = time.perf_counter() - start
    report.windows_per_second = (report.windows_seen / report.train_seconds
                                 if report.train_seconds > 0 else 0.0)
