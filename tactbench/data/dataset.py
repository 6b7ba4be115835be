"""The dataset: labelled samples, class names, a taxel layout and a normalisation.

:class:`Dataset` is what every dataset loader returns and what the runner splits,
images and encodes. Its samples share one taxel order, so each frame is a vector of
the same ``N`` taxels; :meth:`Dataset.vectors` gives them normalised to [0, 1] and
:meth:`Dataset.images` as tactile images ``(T, H, W)`` through
:class:`~tactbench.data.imaging.Imager`. On disk: :mod:`tactbench.data.store`
(:meth:`Dataset.save`, :meth:`Dataset.load`).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from tactbench.data.imaging import Imager
from tactbench.data.layout import TaxelLayout
from tactbench.data.normalisation import Normalisation
from tactbench.data.recording import Sample
from tactbench.data.store import (
    ARRAYS,
    FORMAT_NAME,
    MANIFEST,
    SCHEMA_VERSION,
    read_dataset_fields,
    write_dataset,
)
from tactbench.errors import InputError


#: Below this, readings, offsets and scales are normalised in float32 without overflow.
_F32_SAFE = float(np.finfo(np.float32).max) / 4


class Dataset:
    """Labelled samples with class names, an optional layout and a normalisation.

    Parameters
    ----------
    name
        A short name (``"synthetic-forearm"``).
    samples
        The samples; all recordings must have the same taxel ids in the same
        order (so that every frame is a vector of the same taxels).
    classes
        Class names; ``sample.label`` indexes this tuple.
    layout
        Where the taxels are, or ``None`` (then :meth:`images` raises).
        Every taxel id of the recordings must be in the layout.
    normalisation
        A :class:`Normalisation` or its spec string (``"fixed"``,
        ``"baseline:high=99.9"``).
    """

    def __init__(self, name: str, samples: Sequence[Sample], classes: Sequence[str],
                 layout: TaxelLayout | None = None,
                 normalisation: "str | Normalisation" = "fixed",
                 description: str = "") -> None:
        self.name = str(name)
        self.samples: tuple[Sample, ...] = tuple(samples)
        self.classes: tuple[str, ...] = tuple(str(c) for c in classes)
        self.layout = layout
        self.normalisation = Normalisation.parse(normalisation)
        self.description = description
        self._hash: str | None = None
        self._norm_params: tuple[Any, float] | None = None
        self._imagers: dict[tuple[float, str], Any] = {}
        self._validate()

    def _validate(self) -> None:
        where = f"dataset {self.name!r}"
        if not self.classes:
            raise InputError(f"{where}: no classes")
        if len(set(self.classes)) != len(self.classes):
            raise InputError(f"{where}: duplicate class names in {self.classes}")
        if not self.samples:
            raise InputError(f"{where}: no samples")
        ids0 = self.samples[0].recording.taxel_ids
        for k, s in enumerate(self.samples):
            if not isinstance(s, Sample):
                raise TypeError(f"{where}: sample {k} is a {type(s).__name__}, not a Sample")
            if not (isinstance(s.label, (int, np.integer)) and 0 <= s.label < len(self.classes)):
                raise InputError(f"{where}: sample {k} ({s.source or 'no source'}) has label "
                                 f"{s.label!r}, expected 0..{len(self.classes) - 1}")
            ids = s.recording.taxel_ids
            if ids is not ids0 and (ids.shape != ids0.shape or not np.array_equal(ids, ids0)):
                raise InputError(f"{where}: sample {k} ({s.source or 'no source'}) has "
                                 f"different taxel ids than sample 0 ({ids.size} vs "
                                 f"{ids0.size} taxels); all samples must share them")
        if self.layout is not None:
            self.layout.indices_of(ids0, what=f"dataset {self.name!r}")

    # ----------------------------------------------------------------- access

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, index: int) -> Sample:
        return self.samples[index]

    def __iter__(self) -> Iterator[Sample]:
        return iter(self.samples)

    def __repr__(self) -> str:
        return (f"Dataset({self.name!r}, {len(self)} samples, {len(self.classes)} classes, "
                f"{self.n_taxels} taxels, layout={'yes' if self.layout else 'none'})")

    @property
    def labels(self) -> np.ndarray:
        """int64 ``(S,)``."""
        return np.array([s.label for s in self.samples], dtype=np.int64)

    @property
    def users(self) -> list[str]:
        return [s.user for s in self.samples]

    @property
    def positions(self) -> list[str]:
        return [s.position for s in self.samples]

    @property
    def repetitions(self) -> np.ndarray:
        return np.array([s.repetition for s in self.samples], dtype=np.int64)

    @property
    def attributes(self) -> dict[str, list[str]]:
        """``{name: value of every sample}`` for each attribute some sample has (``""``
        where a sample lacks it), names in the order they first appear."""
        names: dict[str, None] = {}
        for s in self.samples:
            names.update(dict.fromkeys(s.attributes))
        return {n: [s.attributes.get(n, "") for s in self.samples] for n in names}

    @property
    def sources(self) -> list[str]:
        return [s.source for s in self.samples]

    @property
    def taxel_ids(self) -> np.ndarray:
        return self.samples[0].recording.taxel_ids

    @property
    def n_taxels(self) -> int:
        return int(self.taxel_ids.size)

    def lengths(self) -> np.ndarray:
        """Frames per sample, int64 ``(S,)``."""
        return np.array([s.recording.n_frames for s in self.samples], dtype=np.int64)

    def summary(self) -> dict[str, Any]:
        """What ``tactbench data info`` prints (JSON-ready)."""
        lengths = self.lengths()
        per_class = {c: 0 for c in self.classes}
        for s in self.samples:
            per_class[self.classes[s.label]] += 1
        per_user: dict[str, int] = {}
        for u in self.users:
            per_user[u] = per_user.get(u, 0) + 1
        missing = int(sum(np.isnan(s.recording.values).sum() for s in self.samples))
        periods = np.concatenate([np.diff(s.recording.timestamps) for s in self.samples])
        return {
            "name": self.name,
            "samples": len(self),
            "classes": list(self.classes),
            "samples_per_class": per_class,
            "samples_per_user": per_user,
            "frames_per_sample": {"min": int(lengths.min()), "median": float(np.median(lengths)),
                                  "max": int(lengths.max())},
            "frame_rate_hz": (round(float(1 / np.median(periods)), 3)
                              if periods.size and np.median(periods) > 0 else None),
            "taxels": self.n_taxels,
            "layout": (None if self.layout is None else self.layout.summary()),
            "normalisation": self.normalisation.spec,
            **({"attributes": {name: dict(sorted(_counts(values).items()))
                               for name, values in self.attributes.items()}}
               if any(s.attributes for s in self.samples) else {}),
            "missing_readings": missing,
            "content_hash": self.content_hash(),
        }

    # ---------------------------------------------------------- normalisation

    def normalisation_params(self) -> tuple[np.ndarray | float, float]:
        """``(offset, scale)`` of the normalisation, estimated once."""
        if self._norm_params is None:
            self._norm_params = self.normalisation.fit(self.samples)
        return self._norm_params

    def normalise(self, values: np.ndarray) -> np.ndarray:
        """Raw ``(T, N)`` → float32 pressure in [0, 1]; NaN stays NaN.

        Readings near the float32 limit (±3.4e38), and a range spanning them (a scale of
        6.8e38, beyond float32), are computed in float64: float32 would overflow into inf
        and NaN. Other readings are computed in float32, as they always were."""
        offset, scale = self.normalisation_params()
        values = np.asarray(values, dtype=np.float32)
        reach = float(np.nanmax(np.abs(values), initial=0.0)) \
            + float(np.max(np.abs(offset), initial=0.0))
        if reach < _F32_SAFE and float(scale) < _F32_SAFE:  # the usual case, bit for bit
            out = (values - offset) / np.float32(scale)
        else:  # near ±3.4e38: float32 would overflow into inf and NaN
            out = (values.astype(np.float64) - np.asarray(offset, np.float64)) / float(scale)
        return np.clip(out, 0.0, 1.0, out=out).astype(np.float32, copy=False)

    def vectors(self, indices: Sequence[int] | None = None) -> list[np.ndarray]:
        """Each sample's normalised taxel values, float32 ``(T, N)`` in [0, 1].

        Missing readings (NaN) become 0 (read as "no pressure"). ``indices`` (default:
        every sample) picks the samples, in that order, so a caller can take the
        dataset a chunk at a time.
        """
        return [np.nan_to_num(self.normalise(s.recording.values), nan=0.0)
                for s in self._picked(indices)]

    def _picked(self, indices: Sequence[int] | None) -> Sequence[Sample]:
        if indices is None:
            return self.samples
        return [self.samples[int(i)] for i in indices]

    # ---------------------------------------------------------------- imaging

    def imager(self, pixel_mm: float = 1.0, method: str = "linear"):
        """The :class:`~tactbench.data.imaging.Imager` for this dataset's taxels (cached)."""
        if self.layout is None:
            raise InputError(f"dataset {self.name!r} has no taxel layout, so it cannot be "
                             f"turned into tactile images; use its taxel vectors "
                             f"(Dataset.vectors) or give it a layout")
        key = (float(pixel_mm), str(method))
        if key not in self._imagers:
            layout = self.layout
            if layout.n_taxels != self.n_taxels or not np.array_equal(layout.ids,
                                                                      self.taxel_ids):
                layout = layout.subset(self.taxel_ids)
            self._imagers[key] = Imager(layout, pixel_mm=pixel_mm, method=method)
        return self._imagers[key]

    def image_shape(self, pixel_mm: float = 1.0, method: str = "linear") -> tuple[int, int]:
        """``(H, W)`` of this dataset's tactile images at ``pixel_mm``, without imaging any."""
        return tuple(self.imager(pixel_mm, method).shape)  # type: ignore[return-value]

    def iter_images(self, pixel_mm: float = 1.0, method: str = "linear",
                    indices: Sequence[int] | None = None) -> Iterator[np.ndarray]:
        """Like :meth:`images`, one sample at a time."""
        imager = self.imager(pixel_mm, method)
        for s in self._picked(indices):
            img = imager.apply(self.normalise(s.recording.values))
            yield np.clip(img, 0.0, 1.0, out=img)

    def images(self, pixel_mm: float = 1.0, method: str = "linear",
               indices: Sequence[int] | None = None) -> list[np.ndarray]:
        """Each sample as tactile images, float32 ``(T, H, W)`` in [0, 1].

        ``indices`` (default: every sample) picks the samples, in that order: the
        runner images a dataset a chunk of samples at a time, so that its memory does
        not grow with the dataset. Raises :class:`~tactbench.errors.InputError` naming
        the dataset when it has no layout.
        """
        return list(self.iter_images(pixel_mm, method, indices))

    # ----------------------------------------------------------- content hash

    def content_hash(self) -> str:
        """SHA-256 (hex) of everything that defines the data, stable across processes.

        Covers classes, labels, per-sample user/position/repetition and attributes,
        values, timestamps, taxel ids, the layout and the normalisation; not the
        dataset's name, description or sample sources (where files were read).
        Computed once and cached (a dataset without attributes hashes as it did before
        samples had them).
        """
        if self._hash is None:
            h = hashlib.sha256()
            meta = {"format": FORMAT_NAME, "schema": SCHEMA_VERSION,
                    "classes": list(self.classes),
                    "normalisation": self.normalisation.spec,
                    "samples": [[int(s.label), s.user, s.position, int(s.repetition)]
                                for s in self.samples]}
            if any(s.attributes for s in self.samples):
                meta["attributes"] = [sorted(s.attributes.items()) for s in self.samples]
            h.update(json.dumps(meta, sort_keys=True).encode())
            h.update(_le(self.taxel_ids, "<i8"))
            for s in self.samples:
                rec = s.recording
                h.update(np.int64(rec.n_frames).tobytes())
                h.update(_le(rec.timestamps, "<f8"))
                vals = rec.values
                if np.isnan(vals).any():  # one NaN bit pattern whatever produced it
                    vals = np.where(np.isnan(vals), np.float32(np.nan), vals)
                h.update(_le(vals, "<f4"))
            if self.layout is not None:
                lay = self.layout
                h.update(b"layout")
                h.update(_le(lay.ids, "<i8"))
                h.update(_le(lay.positions, "<f8"))
                h.update(_le(np.asarray(lay.bounds), "<f8"))
            self._hash = h.hexdigest()
        return self._hash

    # ---------------------------------------------------------------- on disk

    def save(self, folder: str | Path) -> Path:
        """Write ``manifest.json`` and ``arrays.npz`` into ``folder`` (created); returns it.

        See :func:`tactbench.data.store.write_dataset`.
        """
        return write_dataset(self, folder)

    @classmethod
    def load(cls, folder: str | Path, *, verify: bool = True) -> "Dataset":
        """Read a dataset folder written by :meth:`save`, validating it
        (:func:`tactbench.data.store.read_dataset_fields`); ``verify`` also recomputes the
        content hash and compares it with the manifest's (detects edited or corrupted
        arrays). Nothing in the folder is written."""
        folder = Path(folder)
        fields, recorded = read_dataset_fields(folder)
        try:
            ds = cls(**fields)
        except InputError as exc:
            raise InputError(f"{folder / MANIFEST}: {exc}") from None
        if verify and ds.content_hash() != recorded:
            raise InputError(f"{folder / ARRAYS}: content hash {ds.content_hash()[:12]}… does "
                             f"not match the manifest's {str(recorded)[:12]}…: the files were "
                             f"modified or are corrupted")
        return ds


def _counts(values: Sequence[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return out


def _le(arr: np.ndarray, dtype: str) -> bytes:
    return np.ascontiguousarray(arr, dtype=np.dtype(dtype)).tobytes()
