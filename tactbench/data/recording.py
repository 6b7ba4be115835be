"""Recordings, labelled samples and datasets, and their on-disk format.

- :class:`Recording`: taxel values ``(T, N)`` float32 (raw sensor units; NaN
  marks a missing reading), timestamps ``(T,)`` float64 seconds
  (non-decreasing), taxel ids ``(N,)`` int64 (unique).
- :class:`Sample`: a recording with its label and where it came from.
- :class:`Dataset`: samples, class names, an optional :class:`TaxelLayout`, and
  the normalisation that maps raw values to pressure in [0, 1].

On disk a dataset is a folder with ``manifest.json`` (format name, schema
version, names, per-sample metadata, content hash) and ``arrays.npz`` (all
numbers; read with ``allow_pickle=False``). Loading validates everything and
raises ``ValueError`` naming the file and the problem; nothing is half-loaded.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, NamedTuple, Sequence

import numpy as np

from tactbench.data.layout import TaxelLayout
from tactbench.errors import InputError, MissingFileError

FORMAT_NAME = "tactbench-dataset"
SCHEMA_VERSION = 1
MANIFEST = "manifest.json"
ARRAYS = "arrays.npz"
UINT16_MAX = 65535


class Frame(NamedTuple):
    """One sweep: ``timestamp`` (s) and ``values`` float32 ``(N,)``."""

    timestamp: float
    values: np.ndarray


# ---------------------------------------------------------------- recordings


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
        values = values.astype(np.float32, copy=False)
        if np.isinf(values).any():
            t, n = np.argwhere(np.isinf(values))[0]
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


@dataclass(frozen=True, eq=False)
class Sample:
    """A labelled recording. ``label`` indexes the dataset's ``classes``."""

    recording: Recording
    label: int
    user: str = ""
    position: str = ""
    repetition: int = 0
    source: str = ""


# ------------------------------------------------------------- normalisation


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
        from tactbench.plugins import parse_spec

        kind, opts = parse_spec(str(spec))
        if kind not in cls.KINDS:
            raise InputError(f"unknown normalisation {kind!r}; choose one of "
                             f"{', '.join(cls.KINDS)}")
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
        from tactbench.plugins import format_spec

        return format_spec(self.kind, {k: (int(v) if float(v).is_integer() else v)
                                       for k, v in self.options})

    def fit(self, samples: Sequence[Sample]) -> tuple[np.ndarray | float, float]:
        """Offset (scalar or ``(N,)``) and scale for these samples."""
        opts = dict(self.options)
        if self.kind == "fixed":
            return opts["offset"], opts["scale"]
        stacked = np.concatenate([s.recording.values for s in samples], axis=0)
        with np.errstate(all="ignore"):
            if np.isnan(stacked).any():  # nanpercentile is much slower: only when needed
                offset = np.nanpercentile(stacked, opts["low"], axis=0)
            else:
                offset = np.percentile(stacked, opts["low"], axis=0)
        offset = np.nan_to_num(offset, nan=0.0).astype(np.float32)
        rest = stacked - offset
        rest = rest[np.isfinite(rest)]
        scale = float(np.percentile(rest, opts["high"])) if rest.size else 1.0
        return offset, max(scale, 1.0)


# ------------------------------------------------------------------- datasets


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
        """Raw ``(T, N)`` → float32 pressure in [0, 1]; NaN stays NaN."""
        offset, scale = self.normalisation_params()
        out = (np.asarray(values, dtype=np.float32) - offset) / np.float32(scale)
        return np.clip(out, 0.0, 1.0, out=out).astype(np.float32, copy=False)

    def vectors(self) -> list[np.ndarray]:
        """Each sample's normalised taxel values, float32 ``(T, N)`` in [0, 1].

        Missing readings (NaN) become 0 (read as "no pressure").
        """
        return [np.nan_to_num(self.normalise(s.recording.values), nan=0.0)
                for s in self.samples]

    # ---------------------------------------------------------------- imaging

    def imager(self, pixel_mm: float = 1.0, method: str = "linear"):
        """The :class:`~tactbench.data.imaging.Imager` for this dataset's taxels (cached)."""
        if self.layout is None:
            raise InputError(f"dataset {self.name!r} has no taxel layout, so it cannot be "
                             f"turned into tactile images; use its taxel vectors "
                             f"(Dataset.vectors) or give it a layout")
        key = (float(pixel_mm), str(method))
        if key not in self._imagers:
            from tactbench.data.imaging import Imager

            layout = self.layout
            if layout.n_taxels != self.n_taxels or not np.array_equal(layout.ids,
                                                                      self.taxel_ids):
                layout = layout.subset(self.taxel_ids)
            self._imagers[key] = Imager(layout, pixel_mm=pixel_mm, method=method)
        return self._imagers[key]

    def iter_images(self, pixel_mm: float = 1.0, method: str = "linear") -> Iterator[np.ndarray]:
        """Like :meth:`images`, one sample at a time."""
        imager = self.imager(pixel_mm, method)
        for s in self.samples:
            img = imager.apply(self.normalise(s.recording.values))
            yield np.clip(img, 0.0, 1.0, out=img)

    def images(self, pixel_mm: float = 1.0, method: str = "linear") -> list[np.ndarray]:
        """Each sample as tactile images, float32 ``(T, H, W)`` in [0, 1].

        Raises ``ValueError`` naming the dataset when it has no layout.
        """
        return list(self.iter_images(pixel_mm, method))

    # ----------------------------------------------------------- content hash

    def content_hash(self) -> str:
        """SHA-256 (hex) of everything that defines the data, stable across processes.

        Covers classes, labels, per-sample user/position/repetition, values,
        timestamps, taxel ids, the layout and the normalisation; not the
        dataset's name, description or sample sources (where files were read).
        Computed once and cached.
        """
        if self._hash is None:
            h = hashlib.sha256()
            meta = {"format": FORMAT_NAME, "schema": SCHEMA_VERSION,
                    "classes": list(self.classes),
                    "normalisation": self.normalisation.spec,
                    "samples": [[int(s.label), s.user, s.position, int(s.repetition)]
                                for s in self.samples]}
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
        """Write ``manifest.json`` and ``arrays.npz`` into ``folder`` (created).

        Values are stored as uint16 when they are all whole numbers in
        [0, 65535] (raw sensor counts: half the size, exact), else float32.
        Files are written under temporary names and renamed, so a crash never
        leaves a half-written dataset behind a valid manifest.
        """
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        values = np.concatenate([s.recording.values for s in self.samples], axis=0)
        stored = values
        if np.all(np.isfinite(values)) and values.min() >= 0 and values.max() <= UINT16_MAX \
                and np.array_equal(values, np.round(values)):
            stored = values.astype(np.uint16)
        lengths = self.lengths()
        arrays: dict[str, np.ndarray] = {
            "values": stored,
            "timestamps": np.concatenate([s.recording.timestamps for s in self.samples]),
            "offsets": np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
            "taxel_ids": self.taxel_ids,
            "labels": self.labels,
            "repetitions": self.repetitions,
        }
        if self.layout is not None:
            lay = self.layout
            arrays["layout_ids"] = lay.ids
            arrays["layout_positions"] = lay.positions
            arrays["layout_bounds"] = np.asarray(lay.bounds, dtype=np.float64)
            if lay.positions_3d is not None:
                arrays["layout_positions_3d"] = lay.positions_3d
            if lay.normals is not None:
                arrays["layout_normals"] = lay.normals
        manifest = {
            "format": FORMAT_NAME,
            "schema_version": SCHEMA_VERSION,
            "name": self.name,
            "description": self.description,
            "classes": list(self.classes),
            "normalisation": self.normalisation.spec,
            "n_samples": len(self),
            "n_taxels": self.n_taxels,
            "n_frames": int(lengths.sum()),
            "values_dtype": str(stored.dtype),
            "layout": None if self.layout is None else {"name": self.layout.name},
            "users": self.users,
            "positions": self.positions,
            "sources": self.sources,
            "content_hash": self.content_hash(),
        }
        tmp_arrays = folder / (ARRAYS + ".tmp.npz")
        np.savez(tmp_arrays, **arrays)
        tmp_manifest = folder / (MANIFEST + ".tmp")
        tmp_manifest.write_text(json.dumps(manifest, indent=1) + "\n")
        os.replace(tmp_arrays, folder / ARRAYS)
        os.replace(tmp_manifest, folder / MANIFEST)
        return folder

    @classmethod
    def load(cls, folder: str | Path, *, verify: bool = True) -> "Dataset":
        """Read a dataset folder written by :meth:`save`, validating it.

        ``verify`` recomputes the content hash and compares it with the
        manifest's (detects edited or corrupted arrays).
        """
        folder = Path(folder)
        if not folder.is_dir():
            raise MissingFileError(f"{folder}: no such dataset folder")
        mpath, apath = folder / MANIFEST, folder / ARRAYS
        if not mpath.is_file():
            raise InputError(f"{folder}: not a tactbench dataset folder (no {MANIFEST})")
        try:
            manifest = json.loads(mpath.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"{mpath}: not valid JSON: {exc}") from None
        _check_manifest(manifest, mpath)
        if not apath.is_file():
            raise InputError(f"{folder}: {ARRAYS} is missing (the manifest names "
                             f"{manifest['n_samples']} samples)")
        arrays = _read_npz(apath)
        ds = _dataset_from(manifest, arrays, mpath, apath)
        if verify and ds.content_hash() != manifest["content_hash"]:
            raise InputError(f"{apath}: content hash {ds.content_hash()[:12]}… does not "
                             f"match the manifest's {str(manifest['content_hash'])[:12]}…: "
                             f"the files were modified or are corrupted")
        return ds


def _le(arr: np.ndarray, dtype: str) -> bytes:
    return np.ascontiguousarray(arr, dtype=np.dtype(dtype)).tobytes()


_MANIFEST_FIELDS = {
    "format": str, "schema_version": int, "name": str, "classes": list,
    "normalisation": str, "n_samples": int, "n_taxels": int, "n_frames": int,
    "users": list, "positions": list, "sources": list, "content_hash": str,
}


def _check_manifest(m: Any, path: Path) -> None:
    if not isinstance(m, dict):
        raise InputError(f"{path}: the manifest must be a JSON object")
    if m.get("format") != FORMAT_NAME:
        raise InputError(f"{path}: 'format' is {m.get('format')!r}, expected {FORMAT_NAME!r}")
    version = m.get("schema_version")
    if version != SCHEMA_VERSION:
        raise InputError(f"{path}: schema_version {version!r} is not supported (this "
                         f"tactbench reads version {SCHEMA_VERSION})")
    for key, typ in _MANIFEST_FIELDS.items():
        if key not in m:
            raise InputError(f"{path}: missing field {key!r}")
        if not isinstance(m[key], typ) or (typ is int and isinstance(m[key], bool)):
            raise InputError(f"{path}: field {key!r} must be a {typ.__name__}, got "
                             f"{type(m[key]).__name__}")
    n = m["n_samples"]
    for key in ("users", "positions", "sources"):
        if len(m[key]) != n or not all(isinstance(v, str) for v in m[key]):
            raise InputError(f"{path}: {key!r} must list {n} strings, got {len(m[key])} items")
    if not all(isinstance(c, str) for c in m["classes"]):
        raise InputError(f"{path}: 'classes' must be strings")
    if not re.fullmatch(r"[0-9a-f]{64}", m["content_hash"]):
        raise InputError(f"{path}: 'content_hash' is not a SHA-256 hex digest")


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, EOFError, OSError) as exc:
        raise InputError(f"{path}: cannot read the arrays (truncated or not an .npz "
                         f"file): {exc}") from None
    except ValueError as exc:  # object arrays need pickle: refused
        raise InputError(f"{path}: {exc}") from None


def _need(arrays: dict, key: str, path: Path, ndim: int, kinds: str) -> np.ndarray:
    if key not in arrays:
        raise InputError(f"{path}: array {key!r} is missing")
    arr = arrays[key]
    if arr.ndim != ndim or arr.dtype.kind not in kinds:
        raise InputError(f"{path}: array {key!r} has shape {arr.shape} and dtype "
                         f"{arr.dtype}; expected {ndim} dimension(s) of kind {kinds!r}")
    return arr


def _dataset_from(m: dict, arrays: dict, mpath: Path, apath: Path) -> Dataset:
    n, n_tax, n_frames = m["n_samples"], m["n_taxels"], m["n_frames"]
    values = _need(arrays, "values", apath, 2, "fu")
    timestamps = _need(arrays, "timestamps", apath, 1, "f")
    offsets = _need(arrays, "offsets", apath, 1, "iu").astype(np.int64)
    taxel_ids = _need(arrays, "taxel_ids", apath, 1, "iu")
    labels = _need(arrays, "labels", apath, 1, "iu").astype(np.int64)
    reps = _need(arrays, "repetitions", apath, 1, "iu").astype(np.int64)
    if values.shape != (n_frames, n_tax):
        raise InputError(f"{apath}: 'values' has shape {values.shape}, the manifest says "
                         f"({n_frames}, {n_tax})")
    if timestamps.shape != (n_frames,):
        raise InputError(f"{apath}: 'timestamps' has {timestamps.size} entries, expected "
                         f"{n_frames}")
    if taxel_ids.shape != (n_tax,):
        raise InputError(f"{apath}: 'taxel_ids' has {taxel_ids.size} entries, expected {n_tax}")
    if labels.shape != (n,) or reps.shape != (n,):
        raise InputError(f"{apath}: 'labels'/'repetitions' must have {n} entries")
    if offsets.shape != (n + 1,) or offsets[0] != 0 or offsets[-1] != n_frames \
            or np.any(np.diff(offsets) < 1):
        raise InputError(f"{apath}: 'offsets' must rise strictly from 0 to {n_frames} in "
                         f"{n + 1} entries")
    classes = m["classes"]
    bad = np.nonzero((labels < 0) | (labels >= len(classes)))[0]
    if bad.size:
        raise InputError(f"{apath}: sample {bad[0]} has label {labels[bad[0]]}, but there "
                         f"are {len(classes)} classes")
    layout = None
    if "layout_ids" in arrays:
        try:
            layout = TaxelLayout(
                ids=_need(arrays, "layout_ids", apath, 1, "iu"),
                positions=_need(arrays, "layout_positions", apath, 2, "f"),
                positions_3d=arrays.get("layout_positions_3d"),
                normals=arrays.get("layout_normals"),
                bounds=tuple(_need(arrays, "layout_bounds", apath, 1, "f")),
                name=(m.get("layout") or {}).get("name", ""))
        except ValueError as exc:
            raise InputError(f"{apath}: bad layout: {exc}") from None
    vals32 = values.astype(np.float32, copy=False)
    samples = []
    for k in range(n):
        a, b = offsets[k], offsets[k + 1]
        try:
            rec = Recording(vals32[a:b], timestamps[a:b], taxel_ids)
        except ValueError as exc:
            raise InputError(f"{apath}: sample {k}: {exc}") from None
        samples.append(Sample(rec, int(labels[k]), m["users"][k], m["positions"][k],
                              int(reps[k]), m["sources"][k]))
    try:
        return Dataset(m["name"], samples, classes, layout, m["normalisation"],
                       description=str(m.get("description", "")))
    except ValueError as exc:
        raise InputError(f"{mpath}: {exc}") from None
