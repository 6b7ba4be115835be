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

:func:`unroll` flattens 3-D positions. Files and the dict format are
:mod:`tactbench.data.layout_io`'s (``read_layout_csv``, ``write_layout_csv``,
``read_layout_json``, ``load_layout``), which imports this module, never the reverse; the
generated CySkin-like forearm is
:func:`tactbench.datasets.forearm.cyskin_forearm`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactbench.errors import InputError, check_positive_float, check_positive_int, check_shape

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

    @classmethod
    def grid(cls, rows: int, cols: int, pitch_mm: float, *, name: str | None = None
             ) -> "TaxelLayout":
        """A ``rows`` × ``cols`` grid of taxels ``pitch_mm`` apart (a pressure mat, a glove).

        Taxel ``r * cols + c`` (row-major, as a ``(T, rows, cols)`` array flattens) sits at
        ``x = c · pitch_mm``, ``y = r · pitch_mm``, so image row ``i`` and column ``j`` follow
        the grid's rows and columns. The image bounds pad the grid by half a pitch on each
        side, so at ``pixel_mm == pitch_mm`` one pixel covers one cell.
        """
        rows = check_positive_int(rows, "grid rows")
        cols = check_positive_int(cols, "grid cols")
        pitch = check_positive_float(pitch_mm, "grid pitch_mm")
        k = np.arange(rows * cols, dtype=np.int64)
        pos = np.column_stack([(k % cols) * pitch, (k // cols) * pitch]).astype(np.float64)
        half = 0.5 * pitch
        bounds = (-half, -half, (cols - 1) * pitch + half, (rows - 1) * pitch + half)
        return cls(ids=k, positions=pos, bounds=bounds,
                   name=name if name is not None else f"grid-{rows}x{cols}")

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

        Raises :class:`~tactbench.errors.InputError` naming the ids the layout lacks.
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


# ---------------------------------------------------------------------- helpers


def _check_points(arr: Any, n: int, dims: int, what: str, name: str) -> np.ndarray:
    """``arr`` as float64 ``(n, dims)``, finite."""
    try:
        a = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError):  # text, ragged lists
        raise InputError(f"layout {name!r}: {what} must be numbers (N, {dims}), got "
                         f"{type(arr).__name__}") from None
    check_shape(a, "N D", f"layout {name!r}: {what}", N=n, D=dims)
    if not np.all(np.isfinite(a)):
        raise InputError(f"layout {name!r}: {what} contain NaN or Inf")
    return a


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
