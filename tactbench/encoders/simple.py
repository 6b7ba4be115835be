"""Encoders that need nothing but numpy: ``raw`` and ``frame-diff``."""

from __future__ import annotations

import numpy as np

from tactbench.encoders.base import Encoder, previous_frames


class Raw(Encoder):
    """The pressure image itself: the study's baseline (1 channel, [0, 1])."""

    name = "raw"
    channels = ("pressure",)
    ranges = ((0.0, 1.0),)

    def _encode(self, seq: np.ndarray) -> np.ndarray:
        return seq[:, None].copy()


class FrameDiff(Encoder):
    """Pressure and its signed change from the previous frame (2 channels).

    ``diff = I_k - I_{k-1}`` lies in [-1, 1]; at k = 0 it equals ``I_0``.
    """

    name = "frame-diff"
    channels = ("pressure", "diff")
    ranges = ((0.0, 1.0), (-1.0, 1.0))

    def _encode(self, seq: np.ndarray) -> np.ndarray:
        out = np.empty((seq.shape[0], 2, *seq.shape[1:]), dtype=np.float32)
        out[:, 0] = seq
        np.subtract(seq, previous_frames(seq), out=out[:, 1])
        return out
