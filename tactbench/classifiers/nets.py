"""Torch modules of the sequence classifiers: per-frame encoder → LSTM → head.

Every network maps a batch of windows ``(B, L, *frame_shape)`` (float32, as
:meth:`tactbench.data.windows.Windows.batch` gives them) to class logits ``(B, K)``.
Resizing and normalisation are part of the network, so a saved model carries
them and accepts frames at any size.
"""

from __future__ import annotations

from typing import Sequence

import torch
import torch.nn.functional as F
from torch import nn

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
    """

    def __init__(self, in_channels: int, width: int = 16, layers: int = 4) -> None:
        super().__init__()
        mods: list[nn.Module] = []
        cin = in_channels
        for i in range(layers):
            cout = width * 2 ** ((i + 1) // 2)
            mods += [nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout),
                     nn.ReLU(inplace=True), nn.MaxPool2d(2, ceil_mode=True)]
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


class SequenceNet(nn.Module):
    """Frame encoder on every frame → LSTM → last step → dropout → FC → ReLU → logits.

    The study: "EfficientNet-B0 → LSTM → dropout 0.3 → fully connected layer of 256 →
    classes". ``input_size`` (images only) is the square size frames are resized to
    before ``normalize``; ``None`` for taxel vectors.
    """

    def __init__(self, encoder: nn.Module, *, frame_shape: Sequence[int], n_classes: int,
                 hidden: int, fc: int, dropout: float, input_size: int | None) -> None:
        super().__init__()
        self.frame_shape = tuple(int(s) for s in frame_shape)
        self.input_size = input_size
        self.normalize = Normalize(self.frame_shape[0], len(self.frame_shape) - 1)
        self.encoder = encoder
        self.lstm = nn.LSTM(encoder.out_features, hidden, batch_first=True)
        self.head = nn.Sequential(nn.Dropout(dropout), nn.Linear(hidden, fc),
                                  nn.ReLU(inplace=True), nn.Linear(fc, n_classes))

    def prepare(self, frames: torch.Tensor) -> torch.Tensor:
        """Resize (images) only: ``(N, *frame_shape)`` → network-sized frames."""
        if self.input_size is not None:
            return resize_frames(frames, self.input_size)
        return frames

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, length = x.shape[:2]
        frames = self.normalize(self.prepare(x.reshape(b * length, *x.shape[2:])))
        feats = self.encoder(frames).reshape(b, length, -1)
        out, _ = self.lstm(feats)
        return self.head(out[:, -1])
