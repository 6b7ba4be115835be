"""The encoder contract and the input policy every encoder shares.

An encoder turns a tactile-image sequence into per-frame feature images::

    seq: float32 (T, H, W), values in [0, 1]   →   float32 (T, C, H, W)

Frame ``k`` may use ``I_k`` and ``I_{k-1}``; ``I_{-1}`` (the frame before the
first) is all zeros, as in the study, so channel values at ``k = 0`` describe
the step from an empty skin to the first contact.

Input policy (the same for every encoder, see :func:`check_sequence`):

- rank must be 3 and every axis non-empty, else ``InputError`` (a ``ValueError``);
- integer input is scaled by its dtype's maximum (``uint8 / 255``,
  ``uint16 / 65535``); bool becomes 0/1; float16/float64 are cast to float32;
- NaN or ±Inf anywhere → ``ValueError`` naming how many and where the first is;
- values outside [0, 1] by more than ``1e-6`` → ``ValueError`` with the range
  found (nothing is silently clipped: a benchmark must not repair its inputs).
"""

from __future__ import annotations

import inspect
from typing import Any, ClassVar

import numpy as np

from tactbench.errors import InputError

#: Values this far outside [0, 1] are rounding noise and are clipped.
RANGE_TOLERANCE = 1e-6


def check_sequence(seq: Any) -> np.ndarray:
    """Validate and convert ``seq`` to float32 ``(T, H, W)`` in [0, 1] (see module doc)."""
    arr = np.asarray(seq)
    if arr.ndim != 3:
        raise InputError(f"expected a sequence of shape (T, H, W), got shape {arr.shape}")
    if 0 in arr.shape:
        raise InputError(f"sequence is empty: shape {arr.shape} (T, H and W must be ≥ 1)")
    if arr.dtype == np.bool_:
        return arr.astype(np.float32)
    if np.issubdtype(arr.dtype, np.unsignedinteger):
        return (arr.astype(np.float64) / np.iinfo(arr.dtype).max).astype(np.float32)
    if np.issubdtype(arr.dtype, np.signedinteger):
        raise InputError(f"signed integer input ({arr.dtype}) has no defined pressure scale; "
                         f"pass unsigned integers or floats in [0, 1]")
    if not np.issubdtype(arr.dtype, np.floating):
        raise InputError(f"expected a numeric array, got dtype {arr.dtype}")
    # Check in the input's own precision, then cast: a finite float64 such as
    # 1e39 must be reported as out of range, not overflow to Inf in float32
    # and be called non-finite (found by the hypothesis tests).
    # A sum is one pass without a temporary: NaN/Inf propagate into it. Only when
    # it is not finite (bad values, or huge finite ones overflowing) look closer.
    with np.errstate(over="ignore", invalid="ignore"):  # float16 sums overflow harmlessly
        total = np.add.reduce(arr, axis=None)
    finite = True if np.isfinite(total) else np.isfinite(arr)
    if finite is not True and not finite.all():
        bad = np.argwhere(~finite)
        first = tuple(int(i) for i in bad[0])
        raise InputError(f"sequence has {len(bad)} non-finite value(s) (NaN or Inf); "
                         f"first at (t, y, x) = {first}")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < -RANGE_TOLERANCE or hi > 1.0 + RANGE_TOLERANCE:
        raise InputError(f"values must lie in [0, 1]; found range [{lo:.6g}, {hi:.6g}]. "
                         f"Normalise the pressure images first")
    arr = arr.astype(np.float32, copy=False)
    if lo < 0.0 or hi > 1.0:
        arr = np.clip(arr, 0.0, 1.0)
    return np.ascontiguousarray(arr)


def previous_frames(seq: np.ndarray) -> np.ndarray:
    """``I_{k-1}`` for every k, with an all-zero frame before the first: shape ``(T, H, W)``."""
    prev = np.empty_like(seq)
    prev[0] = 0.0
    prev[1:] = seq[:-1]
    return prev


class Encoder:
    """Base class for encoders. Subclasses set ``channels``/``ranges`` and write ``_encode``.

    The members and their meaning are the encoder contract,
    :data:`tactbench.contracts.ENCODER` (checked when the registry builds an encoder);
    this class adds the shared input policy (:func:`check_sequence`), the output
    check, and ``options()``/``metadata()`` from the constructor's keyword options.
    """

    name: ClassVar[str] = ""
    version: ClassVar[str] = "1"
    channels: ClassVar[tuple[str, ...]] = ()
    ranges: ClassVar[tuple[tuple[float, float], ...]] = ()

    def encode(self, seq: Any) -> np.ndarray:
        """Encode ``seq`` (T, H, W) into float32 ``(T, C, H, W)``; see the module docstring."""
        arr = check_sequence(seq)
        out = self._encode(arr)
        expected = (arr.shape[0], len(self.channels), *arr.shape[1:])
        if out.shape != expected or out.dtype != np.float32:
            raise RuntimeError(f"{type(self).__name__} returned {out.dtype} {out.shape}, "
                               f"expected float32 {expected}")
        return out

    def _encode(self, seq: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def options(self) -> dict[str, Any]:
        """The keyword options this encoder was built with (for cache keys and reports)."""
        params = inspect.signature(type(self)).parameters
        return {name: getattr(self, name) for name in params if hasattr(self, name)}

    def metadata(self) -> dict[str, Any]:
        """What a reader of an encoded array needs: name, version, options, channels, ranges.

        Written next to encoded arrays (``tactbench encode``) and usable in cache keys.
        """
        return {"encoder": self.name, "version": self.version, "options": self.options(),
                "channels": list(self.channels), "ranges": [list(r) for r in self.ranges]}

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"
