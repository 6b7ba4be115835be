"""Encoders that need nothing but numpy: ``raw`` and ``frame-diff``."""

from __future__ import annotations

import numpy as np

from tactbench.encoders.base import Encoder, previous_frames
from tactbench.errors import check_shape


class Raw(Encoder):
    """The pressure image itself: the study's baseline (1 channel, [0, 1])."""

    name = "raw"
    channels = ("pressure",)
    ranges = ((0.0, 1.0),)

    def _encode(self, seq: np.ndarray) -> np.ndarray:
        return seq[:, None].copy()

    def encode_vectors(self, seq: np.ndarray) -> np.ndarray:
        """Taxel vectors ``(T, N)`` pass through (a float32 copy)."""
        seq = np.array(seq, dtype=np.float32)
        check_shape(seq, "T N", "taxel vectors", dtype_kind="f")
        return seq


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

    def encode_vectors(self, seq: np.ndarray) -> np.ndarray:
        """Taxel vectors ``(T, N)`` → ``(T, 2N)``: the pressures, then their change
        from the previous sweep (the same two channels, side by side)."""
        seq = np.asarray(seq, dtype=np.float32)
        check_shape(seq, "T N", "taxel vectors", dtype_kind="f")
        return self._encode(seq).reshape(seq.shape[0], -1)
