"""Normalisation: raw sensor values → pressure in [0, 1], as a spec string.

``clip((v - offset) / scale, 0, 1)`` with ``offset`` and ``scale`` fixed in advance
(``"fixed"``) or estimated from a dataset's samples (``"baseline"``); see
:class:`Normalisation`. :class:`tactbench.data.dataset.Dataset` applies it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tactbench.data.recording import UINT16_MAX, Sample
from tactbench.errors import InputError, check_choice
from tactbench.specs import format_spec, parse_spec

#: Bytes of readings copied at once while finding each taxel's rest value.
OFFSET_BLOCK_BYTES = 16 * 2 ** 20


@dataclass(frozen=True)
class Normalisation:
    """Raw sensor values → pressure in [0, 1]: ``clip((v - offset) / scale, 0, 1)``.

    Kinds (written as a spec string, e.g. ``"baseline:high=99.9"``):

    ``fixed`` (options ``offset=0``, ``scale=65535``)
        The same offset and scale for every taxel: the full 16-bit range by
        default. For data whose range is known in advance.
    ``baseline`` (options ``low=5``, ``high=99.9``)
        Estimated from the dataset: each taxel's offset is the ``low``-th
        percentile of its readings over all frames of all samples (a taxel is
        untouched most of the time, so this is its rest value); the scale is
        the ``high``-th percentile of all baseline-removed readings (one scale
        for all taxels, so their relative sensitivity is kept). Values above
        the scale clip to 1.

    Missing readings (NaN) stay NaN here; :meth:`Dataset.vectors` reads them
    as 0 and :meth:`Dataset.images` fills them from neighbouring taxels.
    """

    kind: str = "fixed"
    options: tuple[tuple[str, float], ...] = ()

    KINDS = {"fixed": {"offset": 0.0, "scale": float(UINT16_MAX)},
             "baseline": {"low": 5.0, "high": 99.9}}

    @classmethod
    def parse(cls, spec: "str | Normalisation") -> "Normalisation":
        if isinstance(spec, Normalisation):
            return spec

        kind, opts = parse_spec(str(spec))
        check_choice(kind, "normalisation", tuple(cls.KINDS))
        allowed = cls.KINDS[kind]
        for key, value in opts.items():
            if key not in allowed:
                raise InputError(f"normalisation {kind!r} has no option {key!r}; options: "
                                 f"{', '.join(allowed)}")
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value):
                raise InputError(f"normalisation option {key}={value!r} must be a number")
        merged = {**allowed, **{k: float(v) for k, v in opts.items()}}
        if kind == "fixed" and not merged["scale"] > 0:
            raise InputError("normalisation 'fixed' needs scale > 0")
        if kind == "baseline" and not 0 <= merged["low"] < merged["high"] <= 100:
            raise InputError("normalisation 'baseline' needs 0 ≤ low < high ≤ 100")
        return cls(kind, tuple(sorted(merged.items())))

    @property
    def spec(self) -> str:
        return format_spec(self.kind, {k: (int(v) if float(v).is_integer() else v)
                                       for k, v in self.options})

    def fit(self, samples: Sequence[Sample]) -> tuple[np.ndarray | float, float]:
        """Offset (scalar or ``(N,)``) and scale for these samples.

        ``baseline`` needs every reading once: its transient memory is one float32 copy
        of the dataset's values (the per-taxel percentiles go a block of taxels at a
        time, the scale's percentile works in place), not the four copies a plain
        ``np.percentile`` chain would make. Results are the same to the bit.
        """
        opts = dict(self.options)
        if self.kind == "fixed":
            return opts["offset"], opts["scale"]
        stacked = np.concatenate([s.recording.values for s in samples], axis=0)
        has_nan = bool(np.isnan(stacked).any())
        # nanpercentile is much slower: only when needed
        percentile = np.nanpercentile if has_nan else np.percentile
        offset = np.empty(stacked.shape[1], dtype=np.float64)
        block = max(1, OFFSET_BLOCK_BYTES // max(1, 4 * len(stacked)))
        with np.errstate(all="ignore"):
            for a in range(0, stacked.shape[1], block):  # a copy of a few taxels at a time
                offset[a:a + block] = percentile(stacked[:, a:a + block], opts["low"], axis=0)
        offset = np.nan_to_num(offset, nan=0.0).astype(np.float32)
        span = max(float(np.nanmax(np.abs(stacked), initial=0.0)),
                   float(np.abs(offset).max(initial=0.0)))
        if 2 * span > float(np.finfo(np.float32).max):  # near ±3.4e38: float32 overflows
            stacked = stacked.astype(np.float64)
        stacked -= offset  # in place: the readings with each taxel's rest value removed
        rest = stacked[np.isfinite(stacked)] if has_nan else stacked.reshape(-1)
        scale = (float(np.percentile(rest, opts["high"], overwrite_input=True))
                 if rest.size else 1.0)
        return offset, max(scale, 1.0)
