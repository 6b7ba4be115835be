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

from tactbench.data.windows import Windows
from tactbench.errors import InputError
from tactbench.profiles import DEFAULT_PROFILE, PROFILE_NAMES, profile_options
from tactbench.seeds import derive_seed  # re-exported: it lived here before

if TYPE_CHECKING:  # torch stays out of import time
    import torch

__all__ = [  # profiles and derive_seed are re-exported from their homes
    "DEFAULT_PROFILE", "PROFILE_NAMES", "profile_options", "derive_seed", "select_device",
    "Precision", "precision_for", "FitReport", "TrainingInterrupted", "ProgressFn",
    "epoch_order", "make_optimizer", "make_schedule", "train_loop", "BestWeights",
    "carve_validation", "augment_windows", "VAL_WINDOWS", "TEMPORAL_HEADS",
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
    #: CPU time of this process during training (every thread, ``time.process_time``):
    #: robust to other processes sharing the cores, where wall time is not.
    train_cpu_seconds: float = 0.0
    windows_per_second: float = 0.0
    final_loss: float = float("nan")
    epoch_losses: list[float] = field(default_factory=list)
    val_accuracy: list[float] = field(default_factory=list)
    #: Early stopping (``patience``): the epoch whose weights were kept (1-based; 0: the
    #: last, no validation) and whether training stopped before its last epoch.
    best_epoch: int = 0
    stopped_early: bool = False
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


def make_schedule(name: str, opt, *, total: int, lr: float):
    """The learning-rate schedule stepped after every optimiser step, or None.

    ``constant``: none. ``cosine``: from ``lr`` down to 0 over ``total`` steps.
    ``onecycle``: :class:`torch.optim.lr_scheduler.OneCycleLR`, up from ``lr / 25`` to
    ``lr`` over the first 30 % of the steps, then down (cosine) to ``lr / 25 / 1e4``;
    with Adam/AdamW it also cycles β₁ between 0.95 and 0.85."""
    import torch

    if name == "constant":
        return None
    if name == "cosine":
        return torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(total, 1))
    if name == "onecycle":
        return torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=max(total, 2))
    raise InputError(f"unknown schedule '{name}': use constant, cosine or onecycle")


class BestWeights:
    """The weights (and buffers) of the epoch with the best validation accuracy so far,
    copied on the CPU; ``patience`` epochs without a gain stop training (0: never)."""

    def __init__(self, patience: int = 0) -> None:
        self.patience = int(patience)
        self.best = -1.0
        self.epoch = 0
        self.since = 0
        self.state: dict[str, Any] | None = None

    def update(self, model, accuracy: float, epoch: int) -> bool:
        """Record ``epoch``'s accuracy; True when training should stop."""
        if accuracy > self.best:
            self.best, self.epoch, self.since = accuracy, epoch, 0
            self.state = {k: v.detach().to("cpu", copy=True)
                          for k, v in model.state_dict().items()}
            return False
        self.since += 1
        return self.patience > 0 and self.since >= self.patience

    def restore(self, model) -> None:
        if self.state is not None:
            model.load_state_dict(self.state)


def train_loop(
    model: "torch.nn.Module",
    get_batch: Callable[[np.ndarray], "tuple[torch.Tensor, torch.Tensor]"],
    *,
    n_windows: int, report: FitReport, epochs: int, batch_size: int,
    windows_per_epoch: int, optimizer: str, lr: float,
    momentum: float = 0.0, weight_decay: float = 0.0, schedule: str = "constant",
    device: "torch.device", precision: Precision, progress: ProgressFn | None = None,
    evaluate: Callable[[], float] | None = None,
    load_batches: Callable[[list[np.ndarray]], Iterable[tuple["torch.Tensor", "torch.Tensor"]]]
    | None = None,
    groups: np.ndarray | None = None,
    label_smoothing: float = 0.0,
    augment: Callable[["torch.Tensor", np.random.Generator], "torch.Tensor"] | None = None,
    keep_best: bool = False, patience: int = 0,
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
    (:func:`epoch_order`). ``label_smoothing``: of the cross-entropy targets (0: none).
    ``augment(x, rng)`` (optional) transforms each training batch ``x``.
    ``keep_best`` (with ``evaluate``): the model ends with the weights of its best
    validation epoch (:class:`BestWeights`); ``patience`` > 0 stops after that many
    epochs without a gain.
    """

    if epochs < 0 or batch_size < 1:
        raise InputError(f"epochs must be ≥ 0 and batch_size ≥ 1 (got {epochs}, {batch_size})")
    rng = np.random.default_rng(report.seed)
    steps_per_epoch = _steps_per_epoch(windows_per_epoch if windows_per_epoch > 0
                                       else n_windows, batch_size)
    total = epochs * steps_per_epoch
    opt = make_optimizer(optimizer, model.parameters(), lr=lr, momentum=momentum,
                         weight_decay=weight_decay)
    step = _Step(model, opt, make_schedule(schedule, opt, total=total, lr=lr),
                 precision.scaler(device), precision, device, label_smoothing, augment,
                 np.random.default_rng([report.seed, 1]))  # its own stream: order unchanged
    best = BestWeights(patience) if keep_best and evaluate is not None else None
    report.train_windows = n_windows
    start, cpu0 = time.perf_counter(), time.process_time()
    try:
        for epoch in range(epochs):
            model.train()
            order = epoch_order(rng, n_windows, windows_per_epoch, groups)
            indices = [order[s * batch_size:(s + 1) * batch_size]
                       for s in range(steps_per_epoch)]
            stream = (load_batches(indices) if load_batches is not None
                      else (get_batch(idx) for idx in indices))
            report.epoch_losses.append(_epoch(step, indices, stream, report, progress,
                                              total, epoch, epochs))
            report.final_loss = report.epoch_losses[-1]
            report.epochs = epoch + 1
            if evaluate is not None and _evaluated(evaluate, report, progress, total, epochs,
                                                   best, model):
                report.stopped_early = epoch + 1 < epochs
                break
    except KeyboardInterrupt:
        model.eval()
        report.interrupted = True
        _finish(report, start, cpu0)
        raise TrainingInterrupted(report) from None
    if best is not None:
        best.restore(model)
        report.best_epoch = best.epoch
    model.eval()
    _finish(report, start, cpu0)
    return report


def _steps_per_epoch(per_epoch: int, batch_size: int) -> int:
    """Batches in an epoch of ``per_epoch`` windows: a trailing batch of one window breaks
    BatchNorm in training mode, so it is dropped."""
    return per_epoch // batch_size + (1 if per_epoch % batch_size > 1 else 0)


def _epoch(step, indices, stream, report: FitReport, progress, total: int, epoch: int,
           epochs: int) -> float:
    """One epoch's steps over the batches ``stream`` yields for ``indices``; its mean loss."""
    loss_sum, count = 0.0, 0
    for idx, (x, y) in zip(indices, stream):
        value = step(x, y)
        loss_sum += value * len(idx)
        count += len(idx)
        report.steps += 1
        report.windows_seen += len(idx)
        if progress is not None:
            progress(report.steps, total, epoch=epoch + 1, epochs=epochs, loss=value)
    return loss_sum / max(count, 1)


class _Step:
    """One optimiser step on a batch: augment, forward, (label-smoothed) cross-entropy,
    backward, step, schedule; returns the loss."""

    def __init__(self, model, opt, sched, scaler, precision, device, label_smoothing,
                 augment, aug_rng) -> None:
        self.model, self.opt, self.sched, self.scaler = model, opt, sched, scaler
        self.precision, self.device = precision, device
        self.label_smoothing, self.augment, self.aug_rng = label_smoothing, augment, aug_rng

    def __call__(self, x, y) -> float:
        import torch.nn.functional as F

        if self.augment is not None:
            x = self.augment(x, self.aug_rng)
        self.opt.zero_grad(set_to_none=True)
        with self.precision.autocast(self.device):
            loss = F.cross_entropy(self.model(x), y, label_smoothing=self.label_smoothing)
        self.scaler.scale(loss).backward()
        self.scaler.step(self.opt)
        self.scaler.update()
        if self.sched is not None:
            self.sched.step()
        return float(loss.detach())


def _evaluated(evaluate, report: FitReport, progress, total: int, epochs: int,
               best: BestWeights | None, model) -> bool:
    """Evaluate after an epoch, record it; True when early stopping says stop."""
    acc = float(evaluate())
    report.val_accuracy.append(acc)
    if progress is not None:
        progress(report.steps, total, epoch=report.epochs, epochs=epochs,
                 loss=report.final_loss, val_accuracy=acc)
    return best is not None and best.update(model, acc, report.epochs)


def _finish(report: FitReport, start: float, cpu0: float) -> None:
    report.train_seconds = time.perf_counter() - start
    report.train_cpu_seconds = time.process_time() - cpu0
    report.windows_per_second = (report.windows_seen / report.train_seconds
                                 if report.train_seconds > 0 else 0.0)


# --------------------------------------------------------------------------- heads

#: The temporal heads of :class:`tactbench.classifiers.nets.SequenceNet` (its
#: ``temporal`` argument; ``small-cnn-lstm``'s ``head`` option), named here, where torch
#: is not imported.
TEMPORAL_HEADS = ("lstm", "concat", "tcn")


# --------------------------------------------------------------------------- validation

#: Validation windows evaluated after each epoch, at most (a seeded sample of the carved
#: recordings' windows): ~2 % of an epoch's training work at the quick profile.
VAL_WINDOWS = 2048


def carve_validation(train: Windows, fraction: float, seed: int,
                     groups: np.ndarray | None = None) -> tuple[Windows, Windows]:
    """Split ``train`` into (train, validation) by whole recordings, so no recording
    gives windows to both: about ``fraction`` of each class's recordings (at least one
    where a class has two or more) go to validation, drawn with ``seed``. With
    ``groups`` (a group per recording, e.g. its user), whole groups are carved instead,
    about ``fraction`` of them. The validation windows are a seeded sample of at most
    :data:`VAL_WINDOWS` of the carved recordings' windows."""
    if not 0 < fraction < 1:
        raise InputError(f"the validation fraction must lie in (0, 1), got {fraction}")
    rng = np.random.default_rng([seed, 2])
    seqs = np.unique(train.seq_index)
    first = np.searchsorted(train.seq_index, seqs) if _sorted(train.seq_index) else \
        np.array([np.flatnonzero(train.seq_index == s)[0] for s in seqs])
    seq_labels = train.labels[first]
    if groups is not None:
        ids = np.asarray(groups)[seqs]
        names = np.unique(ids)
        pick = rng.permutation(names)[:max(1, round(fraction * len(names)))]
        held = seqs[np.isin(ids, pick)] if len(names) > 1 else seqs[:0]
    else:
        held_parts = []
        for label in np.unique(seq_labels):
            members = rng.permutation(seqs[seq_labels == label])
            k = round(fraction * len(members)) if len(members) > 1 else 0
            held_parts.append(members[:max(k, 1 if len(members) > 1 else 0)])
        held = np.concatenate(held_parts) if held_parts else seqs[:0]
    is_val = np.isin(train.seq_index, held)
    if not is_val.any() or is_val.all():
        raise InputError(f"cannot carve a validation split from {len(seqs)} training "
                         f"recordings: use val_fraction=0")
    val_idx = np.flatnonzero(is_val)
    if len(val_idx) > VAL_WINDOWS:
        val_idx = np.sort(rng.choice(val_idx, VAL_WINDOWS, replace=False))
    keep = np.flatnonzero(~is_val)

    def part(idx: np.ndarray) -> Windows:
        return Windows(train.sequences, train.seq_index[idx], train.starts[idx],
                       train.labels[idx], train.L)
    return part(keep), part(val_idx)


def _sorted(a: np.ndarray) -> bool:
    return bool(len(a) == 0 or np.all(a[1:] >= a[:-1]))


# --------------------------------------------------------------------------- augmentation


def augment_windows(x: "torch.Tensor", rng: np.random.Generator, *, shift: int = 0,
                    gain: float = 0.0) -> "torch.Tensor":
    """A training batch ``(B, L, C, H, W)`` (prepared, before normalisation), each window
    moved and scaled as a whole: every frame of a window by the same offset
    ``(dy, dx)`` drawn from ``[-shift, shift]`` pixels, the vacated border filled with
    0 (no contact, no motion), and multiplied by ``exp(u)``, ``u`` uniform in
    ``[-gain, gain]``. Shifts model where on the skin a hand lands, the gain how hard it
    presses (and, on flow channels, how fast it moves); neither changes which gesture it
    is. No flips or rotations: the skin's layout is not symmetric under them, and a
    flow channel's sign would have to flip with the image, which the classifier cannot
    know."""
    import torch
    import torch.nn.functional as F

    if x.ndim != 5:
        raise ValueError(f"augment_windows takes (B, L, C, H, W), got {tuple(x.shape)}")
    b, length, c, h, w = x.shape
    if gain > 0:
        factor = np.exp(rng.uniform(-gain, gain, size=b)).astype(np.float32)
        x = x * torch.from_numpy(factor).to(x.device).view(b, 1, 1, 1, 1)
    if shift <= 0:
        return x
    offsets = rng.integers(-shift, shift + 1, size=(b, 2))
    padded = F.pad(x.reshape(b, length * c, h, w), (shift, shift, shift, shift))
    out = torch.empty_like(x).reshape(b, length * c, h, w)
    for dy, dx in np.unique(offsets, axis=0):
        rows = torch.from_numpy(np.flatnonzero((offsets == (dy, dx)).all(axis=1))).to(x.device)
        top, left = shift - int(dy), shift - int(dx)
        out[rows] = padded[rows, :, top:top + h, left:left + w]
    return out.reshape(b, length, c, h, w)
