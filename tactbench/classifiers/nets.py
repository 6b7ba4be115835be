"""Torch modules of the sequence classifiers: per-frame encoder → LSTM → head.

Every network maps a batch of windows ``(B, L, *frame_shape)`` (float32, as
:meth:`tactbench.data.windows.Windows.batch` gives them) to class logits ``(B, K)``.
Resizing and normalisation are part of the network, so a saved model carries
them and accepts frames at any size.
"""

from __future__ import annotations

from contextlib import nullcontext
from typing import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from tactbench.classifiers.efficientnet import EfficientNetB0
from tactbench.classifiers.training import TEMPORAL_HEADS

#: ImageNet channel statistics (RGB), for ``normalisation="imagenet"``.
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def resize_frames(x: torch.Tensor, size: int) -> torch.Tensor:
    """``(N, C, H, W)`` → ``(N, C, size, size)``, bilinear with antialiasing
    (the frames shrink several-fold, and plain bilinear would alias); unchanged
    when already that size."""
    if x.shape[-2:] == (size, size):
        return x
    return F.interpolate(x, size=(size, size), mode="bilinear", align_corners=False,
                         antialias=True)


class Normalize(nn.Module):
    """``(x - mean) / std`` over the channel (or taxel) axis ``1``; statistics are buffers,
    so they are saved with the weights."""

    def __init__(self, n: int, spatial_dims: int) -> None:
        super().__init__()
        shape = (1, n) + (1,) * spatial_dims
        self.register_buffer("mean", torch.zeros(shape))
        self.register_buffer("std", torch.ones(shape))

    def set(self, mean: Sequence[float] | torch.Tensor,
            std: Sequence[float] | torch.Tensor) -> None:
        mean_t = torch.as_tensor(mean, dtype=torch.float32).reshape(self.mean.shape)
        std_t = torch.as_tensor(std, dtype=torch.float32).reshape(self.std.shape)
        # A constant channel (a dead taxel, no flow at all) must not divide by zero.
        std_t = torch.where(std_t < 1e-6, torch.ones_like(std_t), std_t)
        self.mean.copy_(mean_t)
        self.std.copy_(std_t)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std


class SmallCNN(nn.Module):
    """``layers`` × (3×3 conv → BatchNorm → ReLU → 2×2 max-pool), then global average pool.

    Channels grow ``width, 2w, 2w, 4w, 4w, …``; ``(N, C, S, S)`` → ``(N, out_features)``.
    Each block runs the max-pool before the ReLU: ReLU is monotone, so
    ``max(relu(x)) = relu(max(x))`` exactly, forward and backward, and the ReLU touches a
    quarter of the values (a training step 5–15 % faster; the same weights after it, bit
    for bit, tested). The modules without parameters are the ones that swapped places, so
    saved weights load as before.
    """

    #: False builds the textbook order (ReLU before the pool): the code before, for
    #: benchmarks/training.py's "before" rows.
    pool_before_relu: bool = True

    def __init__(self, in_channels: int, width: int = 16, layers: int = 4) -> None:
        super().__init__()
        mods: list[nn.Module] = []
        cin = in_channels
        for i in range(layers):
            cout = width * 2 ** ((i + 1) // 2)
            pool, relu = nn.MaxPool2d(2, ceil_mode=True), nn.ReLU(inplace=True)
            mods += [nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout),
                     *((pool, relu) if self.pool_before_relu else (relu, pool))]
            cin = cout
        self.body = nn.Sequential(*mods)
        self.out_features = cin

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x).mean((2, 3))


class TaxelMLP(nn.Module):
    """Per-frame encoder for taxel vectors without a layout: ``(F, n)`` → ``(F, out)``."""

    def __init__(self, n_taxels: int, width: int = 128, out_features: int = 64) -> None:
        super().__init__()
        self.body = nn.Sequential(nn.Linear(n_taxels, width), nn.ReLU(inplace=True),
                                  nn.Linear(width, out_features), nn.ReLU(inplace=True))
        self.out_features = out_features

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x)


def as_channels_last(x: torch.Tensor) -> torch.Tensor:
    """``(N, C, H, W)`` in channels-last memory format, so that the convolutions that
    follow run (and keep) channels-last.

    With ``C == 1`` both layouts hold the same bytes and ``contiguous(memory_format=...)``
    returns the tensor unchanged, with NCHW strides, so torch chooses NCHW kernels for
    the whole network (raw pressure images trained 1.6× slower than 3-channel flow
    images). A one-channel tensor gets the channels-last strides as a view: no copy, the
    same values."""
    n, c, h, w = x.shape
    if c == 1 and x.is_contiguous():
        return x.as_strided(x.shape, (h * w, 1, w, 1))
    return x.contiguous(memory_format=torch.channels_last)


class SequenceNet(nn.Module):
    """Frame encoder on every frame → temporal head → dropout → FC → ReLU → logits.

    The study: "EfficientNet-B0 → LSTM → dropout 0.3 → fully connected layer of 256 →
    classes". ``input_size`` (images only) is the square size frames are resized to
    before ``normalize``; ``None`` for taxel vectors. ``temporal`` (the per-window
    features ``(B, L, F)`` → ``(B, D)``): ``lstm`` (its last step, ``D = hidden``, the
    study's), ``concat`` (the ``L`` frames' features side by side, ``D = L·F``: needs the
    window length ``L``) or ``tcn`` (two 1-D convolutions over time, kernel 3, dilation 1
    then 2, ReLU, averaged over time, ``D = hidden``).
    """

    def __init__(self, encoder: nn.Module, *, frame_shape: Sequence[int], n_classes: int,
                 hidden: int, fc: int, dropout: float, input_size: int | None,
                 temporal: str = "lstm", L: int | None = None) -> None:
        super().__init__()
        if temporal not in TEMPORAL_HEADS:
            raise ValueError(f"temporal must be one of {TEMPORAL_HEADS}, got {temporal!r}")
        if temporal == "concat" and not L:
            raise ValueError("the concat head needs the window length L")  # a bug
        self.frame_shape = tuple(int(s) for s in frame_shape)
        self.input_size = input_size
        self.temporal, self.L = temporal, L
        self.normalize = Normalize(self.frame_shape[0], len(self.frame_shape) - 1)
        self.encoder = encoder
        features = encoder.out_features
        if temporal == "lstm":  # the names the saved models of before hold
            self.lstm = nn.LSTM(features, hidden, batch_first=True)
            width = hidden
        elif temporal == "tcn":
            self.tcn = nn.Sequential(
                nn.Conv1d(features, hidden, 3, padding=1), nn.ReLU(inplace=True),
                nn.Conv1d(hidden, hidden, 3, padding=2, dilation=2), nn.ReLU(inplace=True))
            width = hidden
        else:
            width = L * features
        self.head = nn.Sequential(nn.Dropout(dropout), nn.Linear(width, fc),
                                  nn.ReLU(inplace=True), nn.Linear(fc, n_classes))

    def prepare(self, frames: torch.Tensor) -> torch.Tensor:
        """Resize (images) only: ``(N, *frame_shape)`` → network-sized frames."""
        if self.input_size is not None:
            return resize_frames(frames, self.input_size)
        return frames

    #: Image frames go through the encoder in channels-last memory format: the same
    #: arithmetic as NCHW up to float rounding, 1.1–2× less CPU time (docs/classifiers.md).
    #: An instance attribute set to False restores the NCHW path (benchmarks/training.py).
    #: A one-channel frame is NCHW and channels-last at once, and torch then keeps NCHW
    #: for every layer after it: :func:`as_channels_last` marks it explicitly.
    channels_last: bool = True
    #: Gradient checkpointing of the encoder (see :func:`checkpointed`): the encoder's
    #: inner activations are recomputed in the backward pass instead of held. Set by the
    #: classifier; the same forward, gradients and BatchNorm statistics as without.
    checkpoint_segments: int = 0

    def encode(self, frames: torch.Tensor) -> torch.Tensor:
        """Per-frame features ``(N, F)`` of frames ``(N, *frame_shape)`` at any size."""
        frames = self.normalize(self.prepare(frames))
        if frames.ndim == 4 and self.channels_last:
            frames = as_channels_last(frames)
        if self.checkpoint_segments > 0 and self.training and torch.is_grad_enabled():
            return checkpointed(self.encoder, frames, self.checkpoint_segments)
        return self.encoder(frames)

    def forward(self, x: "torch.Tensor | SharedWindows") -> torch.Tensor:
        if isinstance(x, FrameFeatures):  # a frozen encoder's features, computed before
            feats = x.frames[x.index]
        elif isinstance(x, SharedWindows):  # each distinct frame encoded once
            feats = self.encode(x.frames)[x.index]
        else:
            b, length = x.shape[:2]
            feats = self.encode(x.reshape(b * length, *x.shape[2:])).reshape(b, length, -1)
        return self.classify(feats)

    def classify(self, feats: torch.Tensor) -> torch.Tensor:
        """Logits ``(B, K)`` of windows whose frames have features ``feats`` ``(B, L, F)``."""
        if self.temporal == "lstm":
            out, _ = self.lstm(feats)
            return self.head(out[:, -1])
        if self.temporal == "tcn":
            return self.head(self.tcn(feats.transpose(1, 2)).mean(2))
        if feats.shape[1] != self.L:
            raise ValueError(f"the concat head takes windows of L = {self.L} frames, "
                             f"got {feats.shape[1]}")
        return self.head(feats.reshape(feats.shape[0], -1))


class SharedWindows:
    """A batch of windows as its distinct frames ``(U, *frame)`` and, per window, the
    positions of its frames among them, ``index`` ``(B, L)`` int64: overlapping windows
    of one sequence share frames, and :class:`SequenceNet` encodes each frame once."""

    def __init__(self, frames: torch.Tensor, index: torch.Tensor) -> None:
        self.frames = frames
        self.index = index

    def __len__(self) -> int:
        return int(self.index.shape[0])

    def to(self, device, non_blocking: bool = False) -> "SharedWindows":
        return type(self)(self.frames.to(device, non_blocking=non_blocking),
                          self.index.to(device, non_blocking=non_blocking))


class FrameFeatures(SharedWindows):
    """A batch of windows as features of the frame encoder computed beforehand (a frozen
    backbone, :mod:`tactbench.classifiers.pretrained`): ``frames`` ``(U, F)``, ``index``
    ``(B, L)``; :class:`SequenceNet` runs only its LSTM and head on them."""


def segments_of(encoder: nn.Module) -> list[nn.Module]:
    """The encoder as a list of modules applied in turn: EfficientNet's stem, blocks and
    head (pooled at the end), SmallCNN's conv blocks, a Sequential's children; else the
    encoder whole."""
    if isinstance(encoder, EfficientNetB0):
        return [encoder.stem, *encoder.blocks, encoder.head, _MeanPool()]
    if isinstance(encoder, SmallCNN):  # whole conv blocks (ReLU works in place)
        body = list(encoder.body)
        return [nn.Sequential(*body[i:i + 4]) for i in range(0, len(body), 4)] + [_MeanPool()]
    if isinstance(encoder, nn.Sequential):
        return list(encoder)
    return [encoder]


class _MeanPool(nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x.mean((2, 3))


class _KeepBatchNormStats:
    """Context of a checkpoint's recomputation: BatchNorm buffers (running statistics,
    batch count) of ``module`` are restored on exit, so recomputing a forward in the
    backward pass does not update them a second time."""

    def __init__(self, module: nn.Module) -> None:
        self.module = module
        self.saved: list[tuple[torch.Tensor, torch.Tensor]] = []

    def __enter__(self):
        self.saved = [(buf, buf.detach().clone())
                      for m in self.module.modules() if isinstance(m, nn.modules.batchnorm._BatchNorm)
                      for buf in m.buffers()]
        return self

    def __exit__(self, *exc) -> None:
        with torch.no_grad():
            for buf, value in self.saved:
                buf.copy_(value)
        self.saved = []


def checkpointed(encoder: nn.Module, x: torch.Tensor, segments: int) -> torch.Tensor:
    """``encoder(x)`` with gradient checkpointing over ``segments`` runs of its layers
    (:func:`segments_of`): only each run's input is held for the backward pass, and a
    run's inner activations are recomputed there (the whole batch at once, so BatchNorm
    sees the same batch). Random draws (stochastic depth) are replayed
    (``preserve_rng_state``) and BatchNorm's running statistics are updated once, as
    without checkpointing: the same outputs, gradients and buffers, to float rounding."""
    from torch.utils.checkpoint import checkpoint

    layers = segments_of(encoder)
    n = max(1, min(int(segments), len(layers)))
    bounds = [round(i * len(layers) / n) for i in range(n + 1)]

    def run(lo: int, hi: int):
        def fn(y: torch.Tensor) -> torch.Tensor:
            for layer in layers[lo:hi]:
                y = layer(y)
            return y
        return fn

    for lo, hi in zip(bounds[:-1], bounds[1:]):
        if hi <= lo:
            continue
        mods = nn.ModuleList([m for m in layers[lo:hi]])
        x = checkpoint(run(lo, hi), x, use_reentrant=False, preserve_rng_state=True,
                       context_fn=lambda mods=mods: (nullcontext(), _KeepBatchNormStats(mods)))
    return x
