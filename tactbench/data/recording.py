"""Recordings and labelled samples: the data stage's core types.

- :class:`Recording`: taxel values ``(T, N)`` float32 (raw sensor units; NaN
  marks a missing reading), timestamps ``(T,)`` float64 seconds
  (non-decreasing), taxel ids ``(N,)`` int64 (unique).
- :class:`Frame`: one sweep of a recording (what a sensor yields).
- :class:`Sample`: a recording with its label, where it came from and the conditions
  it was recorded under (``attributes``: a corpus's variant, substrate, cover).

The dataset is :class:`tactbench.data.dataset.Dataset`, its normalisation
:class:`tactbench.data.normalisation.Normalisation` and its on-disk format
:mod:`tactbench.data.store`; those names stay importable from here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterator, Mapping, NamedTuple

import numpy as np

from tactbench.errors import InputError

#: Largest raw reading of a 16-bit sensor (CySkin counts).
UINT16_MAX = 65535


class Frame(NamedTuple):
    """One sweep: ``timestamp`` (s) and ``values`` float32 ``(N,)``."""

    timestamp: float
    values: np.ndarray


@dataclass(frozen=True, eq=False)
class Recording:
    """Taxel values over time (see the module docstring for the contract)."""

    values: np.ndarray
    timestamps: np.ndarray
    taxel_ids: np.ndarray

    def __post_init__(self) -> None:
        values = np.asarray(self.values)
        if values.ndim != 2 or 0 in values.shape:
            raise InputError(f"recording values must have shape (T, N) with T, N ≥ 1, "
                             f"got {values.shape}")
        if not (np.issubdtype(values.dtype, np.number) or values.dtype == np.bool_):
            raise InputError(f"recording values must be numeric, got dtype {values.dtype}")
        given = values
        values = values.astype(np.float32, copy=False)
        if np.isinf(values).any():
            t, n = np.argwhere(np.isinf(values))[0]
            if np.isfinite(given[t, n]):  # finite, but beyond what float32 holds
                raise InputError(f"recording has a value of {float(given[t, n]):.6g} (first "
                                 f"at frame {t}, taxel column {n}), beyond the ±3.4e38 a "
                                 f"float32 reading holds")
            raise InputError(f"recording has infinite values (first at frame {t}, taxel "
                             f"column {n}); use NaN for a missing reading")
        ts = np.asarray(self.timestamps, dtype=np.float64)
        if ts.shape != (values.shape[0],):
            raise InputError(f"timestamps must have shape ({values.shape[0]},), got {ts.shape}")
        if not np.all(np.isfinite(ts)):
            raise InputError("timestamps must be finite")
        if ts.size > 1 and np.any(np.diff(ts) < 0):
            k = int(np.nonzero(np.diff(ts) < 0)[0][0])
            raise InputError(f"timestamps go backwards at frame {k + 1} "
                             f"({ts[k]:.6f} → {ts[k + 1]:.6f} s)")
        ids = _as_ids(self.taxel_ids, values.shape[1])
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "timestamps", ts)
        object.__setattr__(self, "taxel_ids", ids)

    @property
    def n_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def n_taxels(self) -> int:
        return int(self.values.shape[1])

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return float(self.timestamps[-1] - self.timestamps[0])

    def frames(self) -> Iterator[Frame]:
        for t, row in zip(self.timestamps, self.values):
            yield Frame(float(t), row)


def _as_ids(ids: Any, n: int) -> np.ndarray:
    arr = np.asarray(ids)
    if arr.shape != (n,):
        raise InputError(f"taxel_ids must have shape ({n},), got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"taxel_ids must be integers, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    uniq, counts = np.unique(arr, return_counts=True)
    if uniq.size != arr.size:
        raise InputError(f"duplicate taxel ids: {', '.join(map(str, uniq[counts > 1][:8]))}")
    return arr


#: Metadata every sample has by name; an attribute may not take one of these names.
RESERVED_ATTRIBUTES = ("user", "position", "repetition", "label", "source")


@dataclass(frozen=True, eq=False)
class Sample:
    """A labelled recording. ``label`` indexes the dataset's ``classes``.

    ``attributes`` are further conditions of the recording, ``{name: value}`` text (CoST's
    ``variant``, HAART's ``substrate`` and ``cover``): a group split leaves their values
    out as it does users (``group:variant``), and they are kept with the dataset."""

    recording: Recording
    label: int
    user: str = ""
    position: str = ""
    repetition: int = 0
    source: str = ""
    attributes: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        attrs = dict(self.attributes)
        for key, value in attrs.items():
            if not isinstance(key, str) or not key.isidentifier() or \
                    key in RESERVED_ATTRIBUTES:
                raise InputError(f"a sample attribute is named by a word that is not one of "
                                 f"{', '.join(RESERVED_ATTRIBUTES)} (variant, substrate), "
                                 f"got {key!r}")
            if not isinstance(value, str):
                raise InputError(f"sample attribute {key!r} must be text, got "
                                 f"{type(value).__name__}")
        object.__setattr__(self, "attributes", attrs)
