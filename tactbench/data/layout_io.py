"""Taxel layouts in files and in plain dicts.

Files
    :func:`load_layout` picks the reader by suffix: :func:`read_layout_json` (CySkin
    calibration files, positions in metres, in all three forms: 3-D ``skin.taxels``,
    2-D ``tactile_maps`` as an object or as a list of maps) and :func:`read_layout_csv`
    (``id,x_mm,y_mm[,z_mm]``, millimetres). :func:`write_layout_csv` writes the CSV
    back exactly. Bad files raise :class:`~tactbench.errors.InputError` naming the file
    (and line); a missing one :class:`~tactbench.errors.MissingFileError`.

Dicts
    THE layout ↔ dict format, used by the dataset store (``arrays.npz``) and by model
    metadata for ``tactbench live``: :func:`layout_to_dict` gives a JSON-ready dict
    ``{"name", "ids", "positions", "bounds"[, "positions_3d"][, "normals"]}`` (lists of
    numbers, mm; ``bounds`` is ``[x_min, y_min, x_max, y_max]``); :func:`layout_from_dict`
    reads it back (lists or numpy arrays), exactly.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tactbench.budget import check_budget
from tactbench.data.layout import TaxelLayout, unroll
from tactbench.errors import InputError
from tactbench.integrity import check_regular_file
from tactbench.paths import atomic_write_text

#: The keys of the dict format: required, then optional.
DICT_REQUIRED = ("ids", "positions")
DICT_OPTIONAL = ("name", "bounds", "positions_3d", "normals")


# ----------------------------------------------------------------------------- dicts


def layout_to_dict(layout: TaxelLayout) -> dict[str, Any]:
    """``layout`` as a JSON-ready dict (see the module docstring); floats are kept exactly."""
    out: dict[str, Any] = {
        "name": layout.name,
        "ids": [int(i) for i in layout.ids],
        "positions": layout.positions.tolist(),
        "bounds": [float(b) for b in layout.bounds],
    }
    if layout.positions_3d is not None:
        out["positions_3d"] = layout.positions_3d.tolist()
    if layout.normals is not None:
        out["normals"] = layout.normals.tolist()
    return out


def layout_from_dict(obj: Any, where: str) -> TaxelLayout:
    """The :class:`TaxelLayout` of a dict written by :func:`layout_to_dict`.

    Values may be lists or numpy arrays. ``where`` (a file, or a file and a key) starts
    every error message. ``bounds`` missing or ``None``: the layout's default bounds.
    """
    if not isinstance(obj, Mapping):
        raise InputError(f"{where}: a layout must be a dict with 'ids' and 'positions', "
                         f"got {type(obj).__name__}")
    missing = [k for k in DICT_REQUIRED if k not in obj]
    if missing:
        raise InputError(f"{where}: the layout has no {' or '.join(map(repr, missing))}")
    unknown = sorted(set(obj) - set(DICT_REQUIRED) - set(DICT_OPTIONAL))
    if unknown:
        raise InputError(f"{where}: unknown layout key(s) {', '.join(map(repr, unknown))}; "
                         f"known: {', '.join(DICT_REQUIRED + DICT_OPTIONAL)}")
    arrays = {key: _numbers(obj[key], key, where)
              for key in ("ids", "positions", "positions_3d", "normals", "bounds")
              if obj.get(key) is not None}
    name = obj.get("name", "")
    if not isinstance(name, str):
        raise InputError(f"{where}: the layout's 'name' must be a string, got {name!r}")
    bounds = arrays.get("bounds")
    if bounds is not None and bounds.shape != (4,):
        raise InputError(f"{where}: the layout's 'bounds' must be 4 numbers "
                         f"[x_min, y_min, x_max, y_max], got shape {bounds.shape}")
    try:
        return TaxelLayout(ids=arrays["ids"], positions=arrays["positions"],
                           positions_3d=arrays.get("positions_3d"),
                           normals=arrays.get("normals"),
                           bounds=None if bounds is None else tuple(bounds.tolist()),
                           name=name)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None


def _numbers(value: Any, key: str, where: str) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except ValueError:  # ragged nested lists
        raise InputError(f"{where}: the layout's {key!r} is not a regular array") from None
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{where}: the layout's {key!r} must hold numbers, got "
                         f"{'nothing' if arr.size == 0 else arr.dtype}")
    if key == "ids" and arr.size and arr.dtype.kind in "uf":
        with np.errstate(invalid="ignore"):
            out = ~((arr >= _ID_MIN) & (arr <= _ID_MAX))  # NaN is out of range too
        if np.any(out):
            raise InputError(f"{where}: the layout's 'ids' hold {arr[out].ravel()[0]!r}, "
                             f"outside the 64-bit integer range")
    return arr


#: Taxel ids are stored as int64.
_ID_MIN, _ID_MAX = -(1 << 63), (1 << 63) - 1


# ----------------------------------------------------------------------------- files


def load_layout(path: str | Path) -> TaxelLayout:
    """Load a layout from ``.json`` (CySkin calibration) or ``.csv``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".json":
        return read_layout_json(path)
    if suffix == ".csv":
        return read_layout_csv(path)
    raise InputError(f"{path}: unknown layout format {suffix or '(no suffix)'!r}; "
                     f"expected a CySkin calibration .json or a .csv (id,x_mm,y_mm)")


def write_layout_csv(layout: TaxelLayout, path: str | Path) -> None:
    """Write ``id,x_mm,y_mm`` (the 2-D positions), after a comment line
    ``# bounds_mm=x_min,y_min,x_max,y_max`` that :func:`read_layout_csv` reads back.

    Floats are written with ``repr`` so reading back is exact; the file is replaced
    atomically.
    """
    buf = io.StringIO(newline="")
    buf.write("# bounds_mm=" + ",".join(repr(float(b)) for b in layout.bounds) + "\n")
    writer = csv.writer(buf)
    writer.writerow(["id", "x_mm", "y_mm"])
    for k in range(layout.n_taxels):
        writer.writerow([int(layout.ids[k]), repr(float(layout.positions[k, 0])),
                         repr(float(layout.positions[k, 1]))])
    atomic_write_text(path, buf.getvalue())


def read_layout_csv(path: str | Path) -> TaxelLayout:
    """Read a CSV with header ``id,x_mm,y_mm`` and optionally ``z_mm``.

    ``x_mm, y_mm`` are the 2-D positions; with ``z_mm`` the 3-D positions
    are ``(x, y, z)``. Lines starting with ``#`` before the header are
    comments; ``# bounds_mm=x_min,y_min,x_max,y_max`` sets the image bounds.
    Bad rows raise :class:`~tactbench.errors.InputError` naming the line.
    """
    path = Path(path)
    lines = _read_text(path).splitlines()
    bounds = None
    first = 0
    while first < len(lines) and lines[first].lstrip().startswith("#"):
        comment = lines[first].lstrip("# \t")
        if comment.startswith("bounds_mm="):
            try:
                bounds = tuple(float(v) for v in comment[len("bounds_mm="):].split(","))
            except ValueError:
                bounds = ()
            if len(bounds) != 4:
                raise InputError(f"{path}, line {first + 1}: bounds_mm must be four "
                                 f"numbers x_min,y_min,x_max,y_max")
        first += 1
    rows = list(csv.reader(lines[first:]))
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise InputError(f"{path}: empty layout file (expected a header id,x_mm,y_mm)")
    header = [c.strip().lower() for c in rows[0]]
    if header[:3] != ["id", "x_mm", "y_mm"] or len(header) > 4 or \
            (len(header) == 4 and header[3] != "z_mm"):
        raise InputError(f"{path}, line {first + 1}: header must be 'id,x_mm,y_mm' or "
                         f"'id,x_mm,y_mm,z_mm', got {','.join(rows[0])!r}")
    ncol = len(header)
    ids, xyz = [], []
    for lineno, row in enumerate(rows[1:], start=first + 2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != ncol:
            raise InputError(f"{path}, line {lineno}: expected {ncol} columns, got {len(row)}")
        try:
            tid = int(row[0])
        except ValueError:
            raise InputError(f"{path}, line {lineno}: taxel id {row[0]!r:.40} is not an "
                             f"integer") from None
        if not _ID_MIN <= tid <= _ID_MAX:
            raise InputError(f"{path}, line {lineno}: taxel id {row[0].strip()[:40]} is "
                             f"outside the 64-bit integer range")
        vals = []
        for name, cell in zip(header[1:], row[1:]):
            try:
                v = float(cell)
            except ValueError:
                raise InputError(f"{path}, line {lineno}: {name} {cell!r} is not a "
                                 f"number") from None
            if not math.isfinite(v):
                raise InputError(f"{path}, line {lineno}: {name} is {cell.strip()} "
                                 f"(positions must be finite)")
            vals.append(v)
        ids.append(tid)
        xyz.append(vals)
    if not ids:
        raise InputError(f"{path}: no taxels after the header")
    arr = np.asarray(xyz, dtype=np.float64)
    return _build(ids, arr[:, :2], arr if ncol == 4 else None, None, path, bounds)


def read_layout_json(path: str | Path, *, map_index: int = 0) -> TaxelLayout:
    """Read a CySkin calibration JSON (positions in metres, converted to mm).

    Forms accepted (as in the ``cyskin-layouts`` files):

    - ``{"tactile_maps": {...taxels: [{id, x: [x, y]}]}}``: a 2-D map;
    - ``{"tactile_maps": [map, ...]}``: a list of maps; ``map_index`` picks one;
    - ``{"skin": {"taxels": [{id, x: [x, y, z], n: [...]}]}}``: 3-D only, flattened
      by :func:`~tactbench.data.layout.unroll` (a cylinder unwrap when the normals say
      the patch is curved, else the best-fitting plane);
    - both ``skin`` and ``tactile_maps``: 2-D from the map, 3-D and normals from
      ``skin`` (matched by id).
    """
    path = Path(path)
    try:
        doc = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}, line {exc.lineno}: not valid JSON: {exc.msg}") from None
    except RecursionError:
        raise InputError(f"{path}: not valid JSON: nested too deeply") from None
    if not isinstance(doc, dict) or not ("skin" in doc or "tactile_maps" in doc):
        raise InputError(f"{path}: not a CySkin calibration file (expected a top-level "
                         f"'skin' or 'tactile_maps' object)")
    skin = _json_taxels(doc["skin"], path, "skin", dims=3) if "skin" in doc else None
    if "tactile_maps" not in doc:
        ids, x3, n3 = skin
        if len(ids) < 3:
            raise InputError(f"{path}: 'skin.taxels' has {len(ids)} taxel(s) and no "
                             f"'tactile_maps'; flattening 3-D positions needs at least 3")
        return _build(ids, unroll(x3, n3), x3, n3, path)
    maps = doc["tactile_maps"]
    if isinstance(maps, list):
        if not maps:
            raise InputError(f"{path}: 'tactile_maps' is an empty list")
        if not 0 <= map_index < len(maps):
            raise InputError(f"{path}: map_index {map_index} out of range; the file "
                             f"has {len(maps)} tactile map(s)")
        tmap, where = maps[map_index], f"tactile_maps[{map_index}]"
    else:
        tmap, where = maps, "tactile_maps"
    ids, pos2, _ = _json_taxels(tmap, path, where, dims=2)
    p3 = nrm = None
    if skin is not None:
        sids, sx, sn = skin
        lookup = {t: i for i, t in enumerate(sids)}
        try:
            order = [lookup[t] for t in ids]
        except KeyError as exc:
            raise InputError(f"{path}: taxel {exc.args[0]} of {where} is missing "
                             f"from 'skin.taxels'") from None
        p3, nrm = sx[order], (None if sn is None else sn[order])
    return _build(ids, pos2, p3, nrm, path)


# ---------------------------------------------------------------------- helpers


def _read_text(path: Path) -> str:
    if path.is_dir():
        raise InputError(f"{path}: a folder, not a layout file")
    check_regular_file(path, what="file")  # a FIFO or a device: one line, never opened

    # Parsed JSON of numbers takes several times its text.
    check_budget(16 * path.stat().st_size, f"reading layout file {path}")
    try:
        return path.read_text(encoding="utf-8-sig")  # a byte-order mark is no mistake
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the file: {exc.strerror or exc}") from None


def _build(ids, pos2, p3, nrm, path: Path, bounds=None) -> TaxelLayout:
    """The layout named after the file; its own checks' errors name the file.

    Positions must be finite and span an area (the image bounds too)."""
    if not np.all(np.isfinite(pos2)):
        raise InputError(f"{path}: the taxels' 2-D positions are not all finite")
    try:
        layout = TaxelLayout(ids=np.asarray(ids, dtype=np.int64), positions=pos2,
                             positions_3d=p3, normals=nrm, bounds=bounds, name=path.stem)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    x0, y0, x1, y1 = layout.bounds
    if not all(math.isfinite(b) for b in layout.bounds) or not (x1 > x0 and y1 > y0):
        raise InputError(f"{path}: the taxels' positions give image bounds {layout.bounds}, "
                         f"which are not a finite area (all taxels at one point, or "
                         f"positions too large)")
    return layout


def _json_vector(value: Any, dims: int, where: str, *, exact: bool) -> list[float]:
    """The first ``dims`` (exactly ``dims`` with ``exact``) finite numbers of a JSON list."""
    want = f"a list of {dims} finite numbers"
    if not isinstance(value, list) or len(value) < dims or (exact and len(value) != dims) \
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       for v in value[:dims]):
        raise InputError(f"{where} must be {want}, got {json.dumps(value)[:60]}")
    try:
        out = [float(v) for v in value[:dims]]
    except OverflowError:
        out = [math.inf]
    if not all(math.isfinite(v) for v in out):
        raise InputError(f"{where} must be {want}, got {json.dumps(value)[:60]}")
    return out


def _json_taxels(obj: Any, path: Path, where: str, *, dims: int):
    """ids, positions (mm) and normals (or None) of a CySkin JSON taxel list."""
    if not isinstance(obj, dict) or not isinstance(obj.get("taxels"), list):
        raise InputError(f"{path}: '{where}' has no 'taxels' list")
    taxels = obj["taxels"]
    if not taxels:
        raise InputError(f"{path}: '{where}.taxels' is empty")
    ids, xs, ns = [], [], []
    for k, tax in enumerate(taxels):
        loc = f"{path}: {where}.taxels[{k}]"
        if not isinstance(tax, dict) or "id" not in tax or "x" not in tax:
            raise InputError(f"{loc}: each taxel needs 'id' and 'x'")
        tid = tax["id"]
        if isinstance(tid, bool) or not isinstance(tid, int):
            raise InputError(f"{loc}: id {tid!r:.40} is not an integer")
        if not _ID_MIN <= tid <= _ID_MAX:
            raise InputError(f"{loc}: id {tid!r:.40} is outside the 64-bit integer range")
        x = _json_vector(tax["x"], dims, f"{loc}: 'x'", exact=False)
        ids.append(tid)
        xs.append([v * 1000.0 for v in x])  # metres → mm
        if dims == 3 and "n" in tax:
            ns.append(_json_vector(tax["n"], 3, f"{loc}: 'n'", exact=True))
    pos = np.asarray(xs, dtype=np.float64)
    if not np.all(np.isfinite(pos)):
        raise InputError(f"{path}: '{where}' has non-finite taxel positions")
    normals = np.asarray(ns, dtype=np.float64) if len(ns) == len(ids) and ns else None
    if normals is not None:
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    return ids, pos, normals
