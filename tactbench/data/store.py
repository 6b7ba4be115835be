"""The dataset store: the folder format a :class:`~tactbench.data.dataset.Dataset` is kept in.

A dataset folder holds

- ``manifest.json``: format name (:data:`FORMAT_NAME`), :data:`SCHEMA_VERSION`, the
  dataset's name, description, classes and normalisation spec, counts, per-sample
  users, positions and sources, the samples' attributes where they have any
  (``{"attributes": {name: [value of every sample]}}``), the layout's name and the
  content hash;
- ``arrays.npz``: all numbers, read with ``allow_pickle=False``: ``values``
  ``(F, N)`` (uint16 when every reading is a whole number in [0, 65535], else float32;
  ``F`` frames of all samples stacked), ``timestamps`` ``(F,)`` s, ``offsets``
  ``(S + 1,)`` (sample ``k`` is frames ``offsets[k]:offsets[k+1]``), ``taxel_ids``
  ``(N,)``, ``labels`` and ``repetitions`` ``(S,)``, and the layout as ``layout_<key>``
  arrays of :func:`tactbench.data.layout_io.layout_to_dict` (``layout_ids``,
  ``layout_positions``, ``layout_bounds``, optionally ``layout_positions_3d`` and
  ``layout_normals``).

:func:`write_dataset` writes each file atomically, manifest last; :func:`read_dataset_fields`
validates everything and raises :class:`~tactbench.errors.InputError` naming the file
and the problem; nothing is half-loaded. This module knows the format, not the class:
:meth:`Dataset.save <tactbench.data.dataset.Dataset.save>` and
:meth:`Dataset.load <tactbench.data.dataset.Dataset.load>` call it (the dependency points
one way, from the dataset to its store). Whole folders (the synthetic dataset's cache)
are built with :func:`tactbench.paths.atomic_folder`.
"""

from __future__ import annotations

import io
import json
import math
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from tactbench.budget import check_budget, human_bytes
from tactbench.data.layout_io import layout_from_dict, layout_to_dict
from tactbench.data.recording import UINT16_MAX, Recording, Sample
from tactbench.errors import InputError, MissingFileError, TactbenchError
from tactbench.integrity import read_npy_header, special_file_problem, zip_read_errors
from tactbench.paths import atomic_write_bytes, atomic_write_text

FORMAT_NAME = "tactbench-dataset"
SCHEMA_VERSION = 1
MANIFEST = "manifest.json"
ARRAYS = "arrays.npz"
#: The layout's arrays in ``arrays.npz`` are its dict format's keys with this prefix.
_LAYOUT_PREFIX = "layout_"
_LAYOUT_DTYPES = {"ids": np.int64, "positions": np.float64, "bounds": np.float64,
                  "positions_3d": np.float64, "normals": np.float64}


# ----------------------------------------------------------------------------- write


def _raw_counts(values: np.ndarray) -> bool:
    """Whether ``values`` are all whole numbers in [0, 65535] (raw sensor counts)."""
    return bool(np.all(np.isfinite(values)) and (values.size == 0 or (
        values.min() >= 0 and values.max() <= UINT16_MAX
        and np.array_equal(values, np.round(values)))))


def write_dataset(dataset: Any, folder: str | Path) -> Path:
    """Write ``manifest.json`` and ``arrays.npz`` of ``dataset`` (a
    :class:`~tactbench.data.dataset.Dataset`) into ``folder`` (created).

    Values are stored as uint16 when they are all whole numbers in [0, 65535] (raw
    sensor counts: half the size, exact), else float32. Each file is replaced
    atomically and the manifest is written last, so a crash never leaves a half-written
    file; new arrays beside an old manifest fail the content-hash check on load.
    Returns ``folder`` as a :class:`~pathlib.Path`.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    samples = dataset.samples
    # One array of all values is unavoidable (the npz member); it is built in its stored
    # type straight from the samples, checked a sample at a time, so writing a large
    # dataset costs one copy of its values rather than three.
    counts = all(_raw_counts(s.recording.values) for s in samples)
    stored = np.concatenate([s.recording.values.astype(np.uint16 if counts else np.float32,
                                                       copy=False) for s in samples], axis=0)
    lengths = dataset.lengths()
    arrays: dict[str, np.ndarray] = {
        "values": stored,
        "timestamps": np.concatenate([s.recording.timestamps for s in samples]),
        "offsets": np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
        "taxel_ids": dataset.taxel_ids,
        "labels": dataset.labels,
        "repetitions": dataset.repetitions,
    }
    layout = dataset.layout
    if layout is not None:
        for key, value in layout_to_dict(layout).items():
            if key != "name":  # the name goes into the manifest
                arrays[_LAYOUT_PREFIX + key] = np.asarray(value, dtype=_LAYOUT_DTYPES[key])
    manifest = {
        "format": FORMAT_NAME,
        "schema_version": SCHEMA_VERSION,
        "name": dataset.name,
        "description": dataset.description,
        "classes": list(dataset.classes),
        "normalisation": dataset.normalisation.spec,
        "n_samples": len(dataset),
        "n_taxels": dataset.n_taxels,
        "n_frames": int(lengths.sum()),
        "values_dtype": str(stored.dtype),
        "layout": None if layout is None else {"name": layout.name},
        "users": dataset.users,
        "positions": dataset.positions,
        "sources": dataset.sources,
        **({"attributes": dataset.attributes}
           if any(s.attributes for s in samples) else {}),
        "content_hash": dataset.content_hash(),
    }
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(folder / ARRAYS, buf.getbuffer())
    atomic_write_text(folder / MANIFEST, json.dumps(manifest, indent=1) + "\n")
    return folder


# ------------------------------------------------------------------------------ read


def read_dataset_fields(folder: str | Path) -> tuple[dict[str, Any], str]:
    """Read a dataset folder written by :func:`write_dataset`, validating it: the keyword
    arguments of :class:`~tactbench.data.dataset.Dataset` (``name``, ``samples``,
    ``classes``, ``layout``, ``normalisation``, ``description``) and the content hash
    the manifest records, which :meth:`Dataset.load <tactbench.data.dataset.Dataset.load>`
    compares with the data's.

    Every manifest field's type is checked; of ``arrays.npz`` only the members the
    format defines are read (others are ignored, never decompressed), each after its
    npy header (shape × item size) was checked against the zip member's size and the
    whole against the memory budget (:func:`tactbench.budget.check_budget`).
    Nothing in the folder is written.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingFileError(f"{folder}: no such dataset folder")
    mpath, apath = folder / MANIFEST, folder / ARRAYS
    for special in map(special_file_problem, (mpath, apath)):
        if special is not None:  # a FIFO or a device: one line, never opened
            raise InputError(special)
    if not mpath.is_file():
        raise InputError(f"{folder}: not a tactbench dataset folder (no {MANIFEST})")
    # Parsed JSON takes several times its text (the samples' lists of strings).
    check_budget(16 * mpath.stat().st_size, f"reading {mpath}")
    try:
        manifest = json.loads(mpath.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{mpath}: not valid JSON: {exc}") from None
    except RecursionError:
        raise InputError(f"{mpath}: not valid JSON: nested too deeply") from None
    _check_manifest(manifest, mpath)
    if not apath.is_file():
        raise InputError(f"{folder}: {ARRAYS} is missing (the manifest names "
                         f"{manifest['n_samples']} samples)")
    fields = _fields_from(manifest, _read_npz(apath, manifest), apath)
    return fields, manifest["content_hash"]


_MANIFEST_FIELDS = {
    "format": str, "schema_version": int, "name": str, "classes": list,
    "normalisation": str, "n_samples": int, "n_taxels": int, "n_frames": int,
    "users": list, "positions": list, "sources": list, "content_hash": str,
}
#: Optional fields and their types (``None`` allowed where the type is a tuple with it).
_MANIFEST_OPTIONAL = {"description": (str,), "values_dtype": (str,),
                      "layout": (dict, type(None)), "attributes": (dict,)}
#: The values types write_dataset stores.
_VALUES_DTYPES = ("uint16", "float32")


def _type_name(typ: type) -> str:
    return {"str": "string", "int": "integer", "list": "list", "dict": "object",
            "NoneType": "null"}.get(typ.__name__, typ.__name__)


def _check_manifest(m: Any, path: Path) -> None:
    if not isinstance(m, dict):
        raise InputError(f"{path}: the manifest must be a JSON object")
    if m.get("format") != FORMAT_NAME:
        raise InputError(f"{path}: 'format' is {m.get('format')!r:.60}, expected "
                         f"{FORMAT_NAME!r}")
    version = m.get("schema_version")
    if version != SCHEMA_VERSION or isinstance(version, bool):
        raise InputError(f"{path}: schema_version {version!r:.40} is not supported (this "
                         f"tactbench reads version {SCHEMA_VERSION})")
    for key, typ in _MANIFEST_FIELDS.items():
        if key not in m:
            raise InputError(f"{path}: missing field {key!r}")
        if not isinstance(m[key], typ) or (typ is int and isinstance(m[key], bool)):
            raise InputError(f"{path}: field {key!r} must be a {typ.__name__}, got "
                             f"{type(m[key]).__name__}")
    for key, types in _MANIFEST_OPTIONAL.items():
        if key in m and not isinstance(m[key], types):
            raise InputError(f"{path}: field {key!r} must be "
                             f"{' or '.join(map(_type_name, types))}, got "
                             f"{type(m[key]).__name__}")
    for key in ("n_samples", "n_taxels", "n_frames"):
        if m[key] < 1:
            raise InputError(f"{path}: field {key!r} must be ≥ 1, got {m[key]}")
    n = m["n_samples"]
    for key in ("users", "positions", "sources"):
        if len(m[key]) != n or not all(isinstance(v, str) for v in m[key]):
            raise InputError(f"{path}: {key!r} must list {n} strings, got {len(m[key])} items")
    for key, values in m.get("attributes", {}).items():
        if not key.isidentifier() or not isinstance(values, list) or len(values) != n \
                or not all(isinstance(v, str) for v in values):
            raise InputError(f"{path}: 'attributes' must map names to lists of {n} strings; "
                             f"{key!r:.40} does not")
    if not all(isinstance(c, str) for c in m["classes"]):
        raise InputError(f"{path}: 'classes' must be strings")
    if not re.fullmatch(r"[0-9a-f]{64}", m["content_hash"]):
        raise InputError(f"{path}: 'content_hash' is not a SHA-256 hex digest")
    if m.get("values_dtype", "float32") not in _VALUES_DTYPES:
        raise InputError(f"{path}: field 'values_dtype' must be one of "
                         f"{', '.join(_VALUES_DTYPES)}, got {m['values_dtype']!r:.40}")
    layout = m.get("layout")
    if layout is not None:
        unknown = sorted(set(layout) - {"name"})
        if unknown or not isinstance(layout.get("name", ""), str):
            raise InputError(f"{path}: field 'layout' must be null or {{\"name\": string}}, "
                             f"got {json.dumps(layout)[:60]}")


#: The members of ``arrays.npz`` the format defines; no other member is ever read.
MEMBERS = ("values", "timestamps", "offsets", "taxel_ids", "labels", "repetitions",
           *(_LAYOUT_PREFIX + key for key in _LAYOUT_DTYPES))


def _read_npz(path: Path, manifest: dict | None = None) -> dict[str, np.ndarray]:
    """The format's members of ``path`` (see :data:`MEMBERS`), each checked before it is
    read: its npy header (no objects; shape × item size equal to the zip member's
    uncompressed size) and the members' total (plus the float32 copy of ``values``)
    against the memory budget. Other members are not decompressed."""
    from numpy.lib import format as npy

    def bad(problem: str) -> InputError:
        return InputError(f"{path}: {problem}")

    try:
        archive = zipfile.ZipFile(path)
    except OSError as exc:  # before the others: BadZipFile is not an OSError
        raise bad(f"cannot read the arrays: {exc}") from None
    except (*zip_read_errors(), ValueError) as exc:
        raise bad(f"not a valid .npz file (not a zip archive, or truncated): "
                  f"{str(exc)[:80]}") from None
    with archive:
        infos: dict[str, zipfile.ZipInfo] = {}
        for info in archive.infolist():
            key = info.filename[:-4] if info.filename.endswith(".npy") else None
            if key in MEMBERS:
                if key in infos:
                    raise bad(f"member {info.filename!r} appears twice")
                infos[key] = info
        headers: dict[str, tuple[tuple[int, ...], bool, np.dtype]] = {}
        try:
            for key, info in infos.items():
                with archive.open(info) as fh:
                    try:
                        shape, fortran, dtype = read_npy_header(fh)
                    except ValueError as exc:
                        raise bad(f"member {key!r} is not a valid .npy array: {exc}") from None
                    if dtype.hasobject:
                        raise bad(f"member {key!r} holds Python objects, which would need "
                                  f"allow_pickle; refused")
                    claimed = math.prod(shape) * dtype.itemsize
                    held = info.file_size - fh.tell()
                    if claimed != held:
                        raise bad(f"member {key!r} claims shape {shape} {dtype} "
                                  f"({human_bytes(claimed)}), but holds {human_bytes(held)}")
                headers[key] = (shape, fortran, dtype)
            total = sum(math.prod(s) * d.itemsize for s, _, d in headers.values())
            if "values" in headers and headers["values"][2] != np.float32:
                total += 4 * math.prod(headers["values"][0])  # the float32 copy
            check_budget(total, f"reading {path} ({len(headers)} arrays)")
            arrays = {}
            for key, info in infos.items():
                with archive.open(info) as fh:
                    arrays[key] = npy.read_array(fh, allow_pickle=False)
            return arrays
        except TactbenchError:
            raise
        except zip_read_errors() as exc:
            raise bad(f"cannot read the arrays (corrupt or truncated): "
                      f"{type(exc).__name__}: {str(exc)[:120]}") from None
        except ValueError as exc:  # read_array: data shorter than its header says
            raise bad(f"cannot read the arrays (corrupt or truncated): "
                      f"{str(exc).splitlines()[0][:120]}") from None


def _need(arrays: dict, key: str, path: Path, ndim: int, kinds: str) -> np.ndarray:
    if key not in arrays:
        raise InputError(f"{path}: array {key!r} is missing")
    arr = arrays[key]
    if arr.ndim != ndim or arr.dtype.kind not in kinds:
        raise InputError(f"{path}: array {key!r} has shape {arr.shape} and dtype "
                         f"{arr.dtype}; expected {ndim} dimension(s) of kind {kinds!r}")
    return arr


def _fields_from(m: dict, arrays: dict, apath: Path) -> dict[str, Any]:
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
    dtype = m.get("values_dtype")
    if dtype is not None and values.dtype != np.dtype(dtype):
        raise InputError(f"{apath}: 'values' is {values.dtype}, the manifest says {dtype}")
    layout = None
    if "layout_ids" in arrays:
        fields = {key[len(_LAYOUT_PREFIX):]: value for key, value in arrays.items()
                  if key.startswith(_LAYOUT_PREFIX)}
        layout = layout_from_dict({**fields, "name": (m.get("layout") or {}).get("name", "")},
                                  f"{apath}: layout")
    elif m.get("layout") is not None:
        raise InputError(f"{apath}: the manifest names a layout, but there is no "
                         f"'layout_ids' array")
    vals32 = values.astype(np.float32, copy=False)
    attributes = m.get("attributes", {})
    samples = []
    for k in range(n):
        a, b = offsets[k], offsets[k + 1]
        try:
            rec = Recording(vals32[a:b], timestamps[a:b], taxel_ids)
            samples.append(Sample(rec, int(labels[k]), m["users"][k], m["positions"][k],
                                  int(reps[k]), m["sources"][k],
                                  {name: values[k] for name, values in attributes.items()
                                   if values[k]}))
        except InputError as exc:
            raise InputError(f"{apath}: sample {k}: {exc}") from None
    return {"name": m["name"], "samples": samples, "classes": classes, "layout": layout,
            "normalisation": m["normalisation"], "description": str(m.get("description", ""))}
