"""Taxel layouts: where each taxel sits on the (unrolled) skin.

A :class:`TaxelLayout` holds, for ``N`` taxels:

- ``ids``: int64 ``(N,)``, unique taxel ids (CySkin: ``module_id * 16 + slot``);
- ``positions``: float64 ``(N, 2)``, millimetres on the flat (unrolled) surface,
  ``x`` across (around the limb) and ``y`` along it; image column ``j`` and row
  ``i`` grow with ``x`` and ``y``;
- optionally ``positions_3d`` (float64 ``(N, 3)``, mm) and ``normals``
  (float64 ``(N, 3)``, unit vectors);
- ``bounds``: ``(x_min, y_min, x_max, y_max)`` in mm, the rectangle of skin
  that images cover (by default the taxels' bounding box grown by half the
  median taxel spacing on each side).

Loaders: :meth:`TaxelLayout.from_json` (CySkin calibration files in all three
forms: 3-D ``skin.taxels``, 2-D ``tactile_maps`` as an object or as a list of
maps), :meth:`TaxelLayout.from_csv` (``id,x_mm,y_mm[,z_mm]``) and
:func:`load_layout` (by file suffix). :func:`cyskin_forearm` generates the
CySkin-like forearm of the study.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactbench.errors import InputError, MissingFileError

#: CySkin taxel ids: ``module_id * SLOTS_PER_ID + slot``.
SLOTS_PER_ID = 16


@dataclass(frozen=True, eq=False)
class TaxelLayout:
    """Taxel ids and positions (see the module docstring for units and shapes)."""

    ids: np.ndarray
    positions: np.ndarray
    positions_3d: np.ndarray | None = None
    normals: np.ndarray | None = None
    bounds: tuple[float, float, float, float] | None = None
    name: str = ""
    _index: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        ids = np.asarray(self.ids)
        if ids.ndim != 1 or ids.size == 0:
            raise InputError(f"layout {self.name!r}: ids must be a non-empty 1-D array, "
                             f"got shape {ids.shape}")
        if not np.issubdtype(ids.dtype, np.integer):
            if not np.all(np.isfinite(ids)) or not np.all(ids == np.round(ids)):
                raise InputError(f"layout {self.name!r}: taxel ids must be integers")
        ids = ids.astype(np.int64)
        n = ids.size
        uniq, counts = np.unique(ids, return_counts=True)
        if uniq.size != n:
            dup = uniq[counts > 1]
            raise InputError(f"layout {self.name!r}: duplicate taxel ids "
                             f"{', '.join(map(str, dup[:5]))}"
                             f"{' ...' if dup.size > 5 else ''} ({dup.size} duplicated)")
        pos = _check_points(self.positions, n, 2, "positions", self.name)
        p3 = None if self.positions_3d is None else _check_points(
            self.positions_3d, n, 3, "positions_3d", self.name)
        nrm = None if self.normals is None else _check_points(
            self.normals, n, 3, "normals", self.name)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "positions_3d", p3)
        object.__setattr__(self, "normals", nrm)
        if self.bounds is None:
            pad = 0.5 * self.median_spacing() if n > 1 else 0.5
            lo, hi = pos.min(axis=0) - pad, pos.max(axis=0) + pad
            bounds = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        else:
            bounds = tuple(float(b) for b in self.bounds)
            if len(bounds) != 4 or not all(math.isfinite(b) for b in bounds) \
                    or bounds[2] <= bounds[0] or bounds[3] <= bounds[1]:
                raise InputError(f"layout {self.name!r}: bounds must be (x_min, y_min, "
                                 f"x_max, y_max) with max > min, got {self.bounds}")
        object.__setattr__(self, "bounds", bounds)
        self._index.update({int(t): i for i, t in enumerate(ids)})

    # ------------------------------------------------------------------ queries

    def __len__(self) -> int:
        return int(self.ids.size)

    @property
    def n_taxels(self) -> int:
        return int(self.ids.size)

    def extent_mm(self) -> tuple[float, float]:
        """Width (x) and height (y) of the taxels' bounding box, in mm."""
        span = self.positions.max(axis=0) - self.positions.min(axis=0)
        return float(span[0]), float(span[1])

    def nearest_distances(self) -> np.ndarray:
        """Distance from each taxel to its nearest neighbour, mm, ``(N,)``."""
        if self.n_taxels < 2:
            return np.zeros(self.n_taxels)
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(self.positions).query(self.positions, k=2)
        return dist[:, 1]

    def median_spacing(self) -> float:
        """Median nearest-neighbour distance between taxels, mm."""
        if self.n_taxels < 2:
            return 0.0
        return float(np.median(self.nearest_distances()))

    def indices_of(self, taxel_ids: Any, *, what: str = "recording") -> np.ndarray:
        """Row index in this layout of each id in ``taxel_ids`` (int64 ``(M,)``).

        Raises ``ValueError`` naming the ids the layout lacks.
        """
        ids = np.asarray(taxel_ids, dtype=np.int64).ravel()
        out = np.empty(ids.size, dtype=np.int64)
        missing = []
        for k, t in enumerate(ids.tolist()):
            i = self._index.get(t)
            if i is None:
                missing.append(t)
                out[k] = -1
            else:
                out[k] = i
        if missing:
            raise InputError(f"{len(missing)} taxel id(s) of the {what} are not in layout "
                             f"{self.name or '(unnamed)'}: {', '.join(map(str, missing[:8]))}"
                             f"{' ...' if len(missing) > 8 else ''}")
        return out

    def subset(self, taxel_ids: Any) -> "TaxelLayout":
        """The layout restricted to (and ordered as) ``taxel_ids``; same bounds."""
        idx = self.indices_of(taxel_ids)
        return TaxelLayout(
            ids=self.ids[idx], positions=self.positions[idx],
            positions_3d=None if self.positions_3d is None else self.positions_3d[idx],
            normals=None if self.normals is None else self.normals[idx],
            bounds=self.bounds, name=self.name)

    def summary(self) -> dict[str, Any]:
        """Counts and sizes for ``tactbench layout info`` (JSON-ready)."""
        w, h = self.extent_mm()
        return {
            "name": self.name,
            "taxels": self.n_taxels,
            "extent_mm": [round(w, 3), round(h, 3)],
            "bounds_mm": [round(b, 3) for b in self.bounds],
            "median_spacing_mm": round(self.median_spacing(), 3),
            "has_3d": self.positions_3d is not None,
            "has_normals": self.normals is not None,
            "modules": int(np.unique(self.ids // SLOTS_PER_ID).size),
        }

    # ------------------------------------------------------------------ writers

    def to_csv(self, path: str | Path) -> None:
        """Write ``id,x_mm,y_mm`` (the 2-D positions), after a comment line
        ``# bounds_mm=x_min,y_min,x_max,y_max`` that :meth:`from_csv` reads back.

        Floats are written with ``repr`` so reading back is exact.
        """
        path = Path(path)
        with path.open("w", newline="") as fh:
            fh.write("# bounds_mm=" + ",".join(repr(float(b)) for b in self.bounds) + "\n")
            writer = csv.writer(fh)
            writer.writerow(["id", "x_mm", "y_mm"])
            for k in range(self.n_taxels):
                writer.writerow([int(self.ids[k]), repr(float(self.positions[k, 0])),
                                 repr(float(self.positions[k, 1]))])

    # ------------------------------------------------------------------ loaders

    @classmethod
    def from_csv(cls, path: str | Path) -> "TaxelLayout":
        """Read a CSV with header ``id,x_mm,y_mm`` and optionally ``z_mm``.

        ``x_mm, y_mm`` are the 2-D positions; with ``z_mm`` the 3-D positions
        are ``(x, y, z)``. Lines starting with ``#`` before the header are
        comments; ``# bounds_mm=x_min,y_min,x_max,y_max`` sets the image bounds.
        Bad rows raise ``ValueError`` naming the line.
        """
        path = Path(path)
        text = _read_text(path)
        lines = text.splitlines()
        bounds = None
        first = 0
        while first < len(lines) and lines[first].lstrip().startswith("#"):
            comment = lines[first].lstrip("# \t")
            if comment.startswith("bounds_mm="):
                try:
                    bounds = tuple(float(v) for v in comment[len("bounds_mm="):].split(","))
                except ValueError:
                    raise InputError(f"{path}, line {first + 1}: bounds_mm must be four "
                                     f"numbers x_min,y_min,x_max,y_max") from None
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
                raise InputError(f"{path}, line {lineno}: expected {ncol} columns, "
                                 f"got {len(row)}")
            try:
                tid = int(row[0])
            except ValueError:
                raise InputError(f"{path}, line {lineno}: taxel id {row[0]!r} is not an "
                                 f"integer") from None
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
        p3 = arr if ncol == 4 else None
        return _build(cls, ids, arr[:, :2], p3, None, path, bounds)

    @classmethod
    def from_json(cls, path: str | Path, *, map_index: int = 0) -> "TaxelLayout":
        """Read a CySkin calibration JSON (positions in metres, converted to mm).

        Forms accepted (as in the ``cyskin-layouts`` files):

        - ``{"tactile_maps": {...taxels: [{id, x: [x, y]}]}}``: a 2-D map;
        - ``{"tactile_maps": [map, ...]}``: a list of maps; ``map_index`` picks one;
        - ``{"skin": {"taxels": [{id, x: [x, y, z], n: [...]}]}}``: 3-D only, flattened
          by :func:`unroll` (a cylinder unwrap when the normals say the patch is
          curved, else the best-fitting plane);
        - both ``skin`` and ``tactile_maps``: 2-D from the map, 3-D and normals from
          ``skin`` (matched by id).
        """
        path = Path(path)
        text = _read_text(path)
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"{path}, line {exc.lineno}: not valid JSON: {exc.msg}") from None
        if not isinstance(doc, dict) or not ("skin" in doc or "tactile_maps" in doc):
            raise InputError(f"{path}: not a CySkin calibration file (expected a top-level "
                             f"'skin' or 'tactile_maps' object)")
        skin = None
        if "skin" in doc:
            skin = _json_taxels(doc["skin"], path, "skin", dims=3)
        if "tactile_maps" in doc:
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
            return _build(cls, ids, pos2, p3, nrm, path)
        ids, x3, n3 = skin
        return _build(cls, ids, unroll(x3, n3), x3, n3, path)


def load_layout(path: str | Path) -> TaxelLayout:
    """Load a layout from ``.json`` (CySkin calibration) or ``.csv``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".json":
        return TaxelLayout.from_json(path)
    if suffix == ".csv":
        return TaxelLayout.from_csv(path)
    raise InputError(f"{path}: unknown layout format {suffix or '(no suffix)'!r}; "
                     f"expected a CySkin calibration .json or a .csv (id,x_mm,y_mm)")


# ---------------------------------------------------------------------- helpers


def _read_text(path: Path) -> str:
    if not path.exists():
        raise MissingFileError(f"{path}: no such file")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None


def _check_points(arr: Any, n: int, dims: int, what: str, name: str) -> np.ndarray:
    a = np.asarray(arr, dtype=np.float64)
    if a.shape != (n, dims):
        raise InputError(f"layout {name!r}: {what} must have shape ({n}, {dims}), "
                         f"got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"layout {name!r}: {what} contain NaN or Inf")
    return a


def _build(cls, ids, pos2, p3, nrm, path: Path, bounds=None) -> TaxelLayout:
    try:
        return cls(ids=np.asarray(ids, dtype=np.int64), positions=pos2, positions_3d=p3,
                   normals=nrm, bounds=bounds, name=path.stem)
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None


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
            raise InputError(f"{loc}: id {tid!r} is not an integer")
        x = tax["x"]
        if not isinstance(x, list) or len(x) < dims or \
                not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in x):
            raise InputError(f"{loc}: 'x' must be a list of {dims} numbers, got {x!r}")
        ids.append(tid)
        xs.append([float(v) * 1000.0 for v in x[:dims]])  # metres → mm
        if dims == 3 and "n" in tax:
            n = tax["n"]
            if not isinstance(n, list) or len(n) != 3:
                raise InputError(f"{loc}: 'n' must be a 3-vector, got {n!r}")
            ns.append([float(v) for v in n])
    pos = np.asarray(xs, dtype=np.float64)
    if not np.all(np.isfinite(pos)):
        raise InputError(f"{path}: '{where}' has non-finite taxel positions")
    normals = np.asarray(ns, dtype=np.float64) if len(ns) == len(ids) and ns else None
    if normals is not None:
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    return ids, pos, normals


def unroll(points: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
    """Flatten 3-D taxel positions ``(N, 3)`` mm to 2-D ``(N, 2)`` mm.

    When normals are given and spread over more than ~10 degrees, the patch is
    treated as part of a cylinder: its axis is the direction most orthogonal to
    all normals (smallest eigenvector of the normals' scatter matrix), the cross
    section is fitted by a least-squares circle, and each taxel maps to (arc
    length around the axis, position along it) — distances along and around
    the cylinder are kept. Otherwise the points are projected on their
    best-fitting plane (principal axes). Either way this is an approximation
    of the calibrated flat maps; prefer a file's own ``tactile_maps``.
    """
    pts = np.asarray(points, dtype=np.float64)
    centred = pts - pts.mean(axis=0)
    if normals is not None and len(normals) >= 3:
        nrm = np.asarray(normals, dtype=np.float64)
        w, v = np.linalg.eigh(nrm.T @ nrm / len(nrm))
        spread = math.degrees(math.asin(min(1.0, math.sqrt(max(w[1], 0.0) / max(w[2], 1e-12)))))
        if spread > 10.0:
            axis = v[:, 0]
            e1 = v[:, 2]  # mean normal direction, orthogonal to the axis
            e2 = np.cross(axis, e1)
            u, s, h = centred @ e1, centred @ e2, centred @ axis
            # circle fit in the (u, s) plane: u² + s² = 2a u + 2b s + c
            a_mat = np.column_stack([2 * u, 2 * s, np.ones_like(u)])
            (a, b, c), *_ = np.linalg.lstsq(a_mat, u ** 2 + s ** 2, rcond=None)
            radius = math.sqrt(max(c + a * a + b * b, 1e-12))
            ang = np.arctan2(s - b, u - a)
            # measure angles from the patch's circular mean, so the seam (±π) falls
            # on the far side of the cylinder, away from the taxels
            mean = math.atan2(np.sin(ang).mean(), np.cos(ang).mean())
            ang = (ang - mean + np.pi) % (2 * np.pi) - np.pi
            return np.column_stack([ang * radius, h])
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return centred @ vt[:2].T


# ---------------------------------------------------------------- the forearm

#: Slot positions of a CySkin-like triangular module in lattice coordinates
#: (i, j): the 12 points on the perimeter of a triangle 4 pitches (30 mm) a side.
_MODULE_SLOTS = [(i, j) for j in range(5) for i in range(5 - j)
                 if i == 0 or j == 0 or i + j == 4]
#: The slot that carries no taxel (CySkin modules: 12 slots, up to 11 taxels).
_EMPTY_SLOT = 11


def cyskin_forearm(n_taxels: int = 1558, *, circumference_mm: float = 334.0,
                   length_mm: float = 357.0, pitch_mm: float = 7.5,
                   module_side_mm: float = 44.0, seed: int = 0) -> TaxelLayout:
    """A CySkin-like forearm: triangular modules on a cylinder, unrolled.

    The cylinder's circumference (``x``) and length (``y``) give the sheet
    ``bounds = (0, 0, circumference_mm, length_mm)``; with the defaults the image
    at 1 mm per pixel is 357 × 334 (rows × columns), as in the study.

    Modules are triangles (alternately pointing up and down) laid in rows
    along the axis; each has 12 slots on a triangular lattice of ``pitch_mm``
    (the perimeter of a triangle 4 pitches a side) of which 11 carry taxels
    (slot 11 is empty, as a temperature sensor's would be). With the default
    ``module_side_mm`` neighbouring modules continue the same lattice, so the
    skin has no gaps wider than two pitches apart from the underside strip. Module
    rows and columns are spread evenly over the sheet (nominal triangle side
    ``module_side_mm``); the columns wrap around the cylinder. When fewer
    taxels are asked for than modules hold, the modules farthest from the top
    of the arm (``x = circumference / 2``, so starting on the underside, where
    a cable channel would run) are left out, then the remaining surplus
    taxels (4 for the default 1558) are dropped at random (``seed``), like the
    unpopulated slots of a real skin.

    Ids are ``module_id * 16 + slot`` with module ids from 1. ``positions_3d``
    and ``normals`` describe the cylinder (axis along ``y``).
    """
    if n_taxels < 1:
        raise InputError(f"n_taxels must be ≥ 1, got {n_taxels}")
    per_module = len(_MODULE_SLOTS) - 1
    row_h = module_side_mm * math.sqrt(3) / 2
    n_rows = max(1, round(length_mm / row_h))
    n_cols = max(2, 2 * round(circumference_mm / module_side_mm))
    step_x = circumference_mm / n_cols  # half a triangle side
    step_y = length_mm / n_rows
    n_modules = math.ceil(n_taxels / per_module)
    if n_modules > n_rows * n_cols:
        raise InputError(f"{n_taxels} taxels need {n_modules} modules, but a "
                         f"{circumference_mm} x {length_mm} mm sheet holds {n_rows * n_cols}")
    # module centres and orientation (up/down alternate along a row and between rows)
    rr, cc = np.meshgrid(np.arange(n_rows), np.arange(n_cols), indexing="ij")
    rr, cc = rr.ravel(), cc.ravel()
    up = (rr + cc) % 2 == 0
    cx = (cc + 0.5) * step_x
    cy = (rr + 0.5) * step_y + np.where(up, -1.0, 1.0) * step_y / 6  # centroids
    # keep the modules nearest the top of the arm (x = C/2), row by row outwards
    around = np.abs(cx - circumference_mm / 2)
    order = np.lexsort((np.abs(cy - length_mm / 2), around))
    keep = np.sort(order[:n_modules])
    # slot offsets from a module's centroid (pointing up; flip y for down)
    lat = np.array([(i + j / 2, j * math.sqrt(3) / 2) for i, j in _MODULE_SLOTS]) * pitch_mm
    lat -= np.array([2.0, 2 / math.sqrt(3)]) * pitch_mm  # centroid of the 4-pitch triangle
    slots = np.array([s for s in range(len(_MODULE_SLOTS)) if s != _EMPTY_SLOT])
    ids, xs, ys = [], [], []
    for module_id, m in enumerate(keep, start=1):
        off = lat[slots].copy()
        if not up[m]:
            off[:, 1] *= -1
        ids.append(module_id * SLOTS_PER_ID + slots)
        xs.append(cx[m] + off[:, 0])
        ys.append(cy[m] + off[:, 1])
    ids_a = np.concatenate(ids)
    pos = np.column_stack([np.concatenate(xs) % circumference_mm, np.concatenate(ys)])
    surplus = ids_a.size - n_taxels
    if surplus > 0:
        rng = np.random.default_rng(seed)
        drop = rng.choice(ids_a.size, size=surplus, replace=False)
        mask = np.ones(ids_a.size, dtype=bool)
        mask[drop] = False
        ids_a, pos = ids_a[mask], pos[mask]
    radius = circumference_mm / (2 * math.pi)
    theta = pos[:, 0] / radius
    normals = np.column_stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)])
    p3 = np.column_stack([radius * normals[:, 0], radius * normals[:, 1], pos[:, 1]])
    return TaxelLayout(ids=ids_a, positions=pos, positions_3d=p3, normals=normals,
                       bounds=(0.0, 0.0, float(circumference_mm), float(length_mm)),
                       name=f"cyskin-forearm-{n_taxels}")
