"""Imaging Φ: taxel values → tactile image, as a precomputed sparse operator.

:class:`Imager` is built once per (layout, pixel size, method); applying it is
one sparse matrix product, for one frame ``(N,)`` or a batch ``(T, N)``.

Grid
    The image covers the layout's ``bounds`` (mm): ``W = ceil(width / pixel_mm)``
    columns (``x``) and ``H = ceil(height / pixel_mm)`` rows (``y``), at least 1 each
    (:func:`image_shape`, the one place this is computed); pixel
    ``(i, j)`` is the square whose centre is at ``x_min + (j + ½)·pixel_mm``,
    ``y_min + (i + ½)·pixel_mm``. The generated forearm gives 357 × 334 at
    1 mm, 90 × 84 at 4 mm and 72 × 67 at 5 mm.

Spacing
    A taxel's *local spacing* is the distance to its 3rd-nearest neighbour (on
    a lattice: the pitch, even where the pitch differs by direction or the
    taxel borders a hole). Rules below use it rather than one median, because
    flattened maps are denser at their edges than in their middle.

Methods
    ``"linear"``: piecewise-linear interpolation over a Delaunay triangulation
    of the taxels (as ``scipy.interpolate.griddata(method="linear")``), with
    triangles removed whose longest edge exceeds 2.5 × the mean local
    spacing of their corners (or ``max_edge`` mm when given), so that holes and
    concave edges of the skin are not bridged. ``"gaussian"``: a normalised
    Gaussian splat: each pixel is the weighted mean of the taxels within 3σ,
    σ = half the taxel's local spacing (or ``sigma`` mm); a pixel counts as
    skin when its nearest taxel is within 2σ of it.

Off the skin
    Pixels outside the kept triangles (linear) or farther than 2σ from their
    nearest taxel (gaussian) are exactly 0, never NaN.

Coarse pixels
    When a pixel is larger than a quarter of the taxel spacing, each pixel is
    the mean over ``s × s`` sub-samples (``s = ceil(pixel_mm / (spacing / 4))``),
    i.e. an area average rather than a point sample: a contact smaller than a
    pixel keeps its total weight wherever it falls, and pixels on the skin's
    edge are dimmed in proportion to the skin they cover.

Missing taxels (NaN or ±Inf readings)
    A non-finite reading is treated as *missing* and replaced, before
    imaging, by the mean of the finite readings of its neighbours (taxels
    within 1.5 × the larger of the two local spacings) in the same frame; a
    missing taxel with no
    finite neighbour reads 0. So a missing taxel is filled from its
    neighbours and never propagates.

Values are float32. Inputs in [0, 1] give outputs in [0, 1] (every pixel is a
convex combination of taxel values, times a coverage ≤ 1).

Memory
    Building the operator visits every sub-sample of the grid: its peak is about
    :data:`BUILD_BYTES_PER_POINT` bytes per sub-sample (measured with tracemalloc on the
    generated forearm from 5 mm to 0.3 mm: 275–294 B linear, 847 B gaussian), so a
    pixel size far below the taxel pitch grows it with the square of the ratio (0.01 mm
    on the forearm: 1.2 billion pixels, ~350 GiB). :class:`Imager` estimates it
    (:func:`imager_build_bytes`) and imaging a batch of frames, and refuses either above
    the memory budget (:func:`tactbench.budget.check_budget`) before allocating.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tactbench.budget import check_budget
from tactbench.data.layout import TaxelLayout
from tactbench.errors import InputError, check_choice, check_positive_float, check_positive_int

METHODS = ("linear", "gaussian")
#: Sub-samples per pixel side are chosen so sub-samples are ≤ spacing / 4 apart.
_SUBSAMPLES_PER_SPACING = 4.0
#: Peak bytes per grid sub-sample while an :class:`Imager` is built (measured, rounded
#: up; see the module docstring).
BUILD_BYTES_PER_POINT = {"linear": 320, "gaussian": 900}
#: The largest image, in pixels, :func:`image_shape` computes (far beyond any budget).
_MAX_PIXELS = 2.0 ** 60
#: The most sub-samples per pixel side :class:`Imager` chooses (also far beyond any budget).
_MAX_SUPERSAMPLE = 2 ** 16


class Imager:
    """The operator Φ for one layout, pixel size and method.

    Parameters
    ----------
    layout
        Taxel positions (mm) and the image bounds.
    pixel_mm
        Pixel side in mm (> 0). The study uses 1 mm; the taxel pitch is
        7.5 mm, so 4–6 mm loses little and is much cheaper downstream.
    method
        ``"linear"`` or ``"gaussian"`` (see the module docstring).
    max_edge
        Linear only: longest triangle edge kept, mm (default: 2.5 × the local
        spacing, see the module docstring).
    sigma
        Gaussian only: splat width σ in mm for every taxel (default: half of
        each taxel's local spacing).
    supersample
        Sub-samples per pixel side; ``None`` chooses (see the module docstring).

    Attributes
    ----------
    shape : tuple[int, int]
        ``(H, W)`` of the images.
    coverage : ndarray, float32 (H, W)
        Fraction of each pixel that lies on the skin (0 off the skin).
    """

    def __init__(self, layout: TaxelLayout, *, pixel_mm: float = 1.0,
                 method: str = "linear", max_edge: float | None = None,
                 sigma: float | None = None, supersample: int | None = None) -> None:
        if not isinstance(layout, TaxelLayout):
            raise TypeError(f"layout must be a TaxelLayout, got {type(layout).__name__}")
        self.method = check_choice(method, "imaging method", METHODS)
        self.layout = layout
        self.shape: tuple[int, int] = image_shape(layout, pixel_mm)
        pixel_mm = self.pixel_mm = float(pixel_mm)
        x0, y0, _, _ = layout.bounds
        spacing = layout.median_spacing() or pixel_mm
        self.spacing = spacing
        self.supersample = _supersample(pixel_mm, spacing, supersample)
        h, w = self.shape
        s = self.supersample
        check_budget(BUILD_BYTES_PER_POINT[method] * (h * s) * (w * s),
                     f"imaging at {pixel_mm:g} mm ({h}×{w} px, {method}, {s}×{s} "
                     f"sub-samples per pixel)")
        # sub-sample centres, in row-major pixel order, s*s per pixel
        sub = (np.arange(s) + 0.5) / s
        ys = y0 + (np.arange(h)[:, None] + sub[None, :]).ravel() * pixel_mm
        xs = x0 + (np.arange(w)[:, None] + sub[None, :]).ravel() * pixel_mm
        # each taxel's own spacing: flattened maps are denser at their edges than
        # in the middle, so one median would cut holes where taxels are sparse
        local = local_spacing(layout.positions, fallback=spacing)
        self._local_spacing = local
        if method == "linear":
            rows, cols, vals = _linear_weights(layout.positions, xs, ys, max_edge,
                                               2.5 * local)
        else:
            if sigma is not None:
                sigma = check_positive_float(sigma, "sigma")
            gy, gx = np.meshgrid(ys, xs, indexing="ij")  # (h*s, w*s)
            pts = np.column_stack([gx.ravel(), gy.ravel()])
            sig = np.full(layout.n_taxels, float(sigma)) if sigma is not None else local / 2
            rows, cols, vals = _gaussian_weights(layout.positions, pts, sig, 2.0 * sig)
        # map each sub-sample row to its pixel, and average
        sub_r, sub_c = np.divmod(rows, w * s)
        pix = (sub_r // s) * w + (sub_c // s)
        from scipy import sparse

        n = layout.n_taxels
        mat = sparse.csr_matrix((vals / (s * s), (pix, cols)), shape=(h * w, n),
                                dtype=np.float64)
        mat.sum_duplicates()
        mat.eliminate_zeros()
        self._matrix = mat.astype(np.float32)
        self._matrix_t = self._matrix.T.tocsr()  # (N, P): batch @ this is row-major output
        self.coverage = np.asarray(mat.sum(axis=1), dtype=np.float32).reshape(h, w)
        self._neighbours = None  # built on first missing reading

    def _neighbour_matrix(self):
        """Sparse ``(N, N)`` 0/1 matrix: taxels within 1.5 × local spacing of each other."""
        if self._neighbours is None:
            from scipy import sparse
            from scipy.spatial import cKDTree

            pos, local = self.layout.positions, self._local_spacing
            pairs = cKDTree(pos).query_pairs(1.5 * float(local.max()), output_type="ndarray")
            if len(pairs):
                dist = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1)
                near = dist <= 1.5 * np.maximum(local[pairs[:, 0]], local[pairs[:, 1]])
                pairs = pairs[near]
            pairs = pairs.reshape(-1, 2)
            n = self.n_taxels
            rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
            cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
            self._neighbours = sparse.csr_matrix(
                (np.ones(rows.size, dtype=np.float32), (rows, cols)), shape=(n, n))
        return self._neighbours

    def fill_missing(self, values: np.ndarray) -> np.ndarray:
        """Replace non-finite readings in ``(T, N)`` by their neighbours' mean (or 0)."""
        batch = np.asarray(values, dtype=np.float32)
        finite = np.isfinite(batch)
        if finite.all():
            return batch
        adj = self._neighbour_matrix()
        known = np.where(finite, batch, 0.0).astype(np.float32)
        total = np.asarray(known @ adj)  # adj is symmetric
        count = np.asarray(finite.astype(np.float32) @ adj)
        mean = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
        return np.where(finite, batch, mean).astype(np.float32)

    @property
    def matrix(self):
        """The sparse operator, scipy CSR float32 ``(H·W, N)``."""
        return self._matrix

    @property
    def n_taxels(self) -> int:
        return self.layout.n_taxels

    def apply(self, values: Any) -> np.ndarray:
        """Image of one frame ``(N,)`` → ``(H, W)`` or of frames ``(T, N)`` → ``(T, H, W)``.

        Values are in layout order. Non-finite readings are missing (see the
        module docstring). Returns float32.
        """
        arr = np.asarray(values)
        single = arr.ndim == 1
        if arr.ndim not in (1, 2) or arr.shape[-1] != self.n_taxels:
            raise InputError(f"expected values of shape (N,) or (T, N) with N = "
                             f"{self.n_taxels}, got {arr.shape}")
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
                or arr.dtype == np.bool_):
            raise InputError(f"expected numeric taxel values, got dtype {arr.dtype}")
        if not single:  # the input as float32, and the output (T, H, W) float32
            h, w = self.shape
            check_budget(4 * arr.shape[0] * (self.n_taxels + h * w),
                         f"imaging {arr.shape[0]} frames at {self.pixel_mm:g} mm ({h}×{w} px)")
        batch = np.atleast_2d(arr).astype(np.float32, copy=False)
        if not np.isfinite(batch).all():
            batch = self.fill_missing(batch)
        if single:  # CSR matrix-vector product: the cheapest form for one frame
            return np.asarray(self._matrix @ batch[0], dtype=np.float32).reshape(self.shape)
        # (T, N) @ (N, P) keeps the output row-major (T, P) without a transpose copy
        out = batch @ self._matrix_t
        return np.asarray(out, dtype=np.float32).reshape(-1, *self.shape)

    __call__ = apply

    def __repr__(self) -> str:
        return (f"Imager({self.layout.name or 'layout'}, {self.n_taxels} taxels → "
                f"{self.shape[0]}×{self.shape[1]} px at {self.pixel_mm:g} mm, "
                f"{self.method}, supersample {self.supersample})")


def image_shape(layout: TaxelLayout, pixel_mm: float) -> tuple[int, int]:
    """``(H, W)`` of the images of ``layout`` at ``pixel_mm`` mm per pixel (> 0).

    ``H = ceil(height / pixel_mm)`` rows and ``W = ceil(width / pixel_mm)`` columns of
    the layout's ``bounds``, at least 1 each; a bound that is a whole number of pixels
    (up to 1e-9 pixel of rounding) takes no extra pixel. The one place the image shape
    is computed: :class:`Imager` and ``tactbench layout info`` use it.
    """
    pixel_mm = check_positive_float(pixel_mm, "pixel_mm")
    x0, y0, x1, y1 = layout.bounds
    rows, cols = (y1 - y0) / pixel_mm - 1e-9, (x1 - x0) / pixel_mm - 1e-9
    if not (max(rows, 1.0) * max(cols, 1.0) <= _MAX_PIXELS):  # NaN/inf too: no ceil of inf
        raise InputError(f"pixel size {pixel_mm:g} mm is far too small for a layout of "
                         f"{x1 - x0:g} × {y1 - y0:g} mm ({rows:.3g} × {cols:.3g} px)")
    return max(1, math.ceil(rows)), max(1, math.ceil(cols))


def _supersample(pixel_mm: float, spacing: float, supersample: int | None) -> int:
    if supersample is None:
        ratio = pixel_mm / (spacing / _SUBSAMPLES_PER_SPACING)
        if not ratio <= _MAX_SUPERSAMPLE:  # (beyond any budget; and no ceil of inf)
            raise InputError(f"pixel size {pixel_mm:g} mm is far too large for taxels "
                             f"{spacing:g} mm apart ({ratio:.3g} sub-samples per pixel side)")
        supersample = max(1, math.ceil(ratio - 1e-9))
    return check_positive_int(supersample, "supersample")


def imager_build_bytes(layout: TaxelLayout, pixel_mm: float, method: str = "linear") -> int:
    """Estimated peak memory (bytes) of building the :class:`Imager` of ``layout`` at
    ``pixel_mm``, without building it (see ``Memory`` in the module docstring)."""
    check_choice(method, "imaging method", METHODS)
    h, w = image_shape(layout, pixel_mm)
    s = _supersample(float(pixel_mm), layout.median_spacing() or float(pixel_mm), None)
    return BUILD_BYTES_PER_POINT[method] * (h * s) * (w * s)


def local_spacing(positions: np.ndarray, *, k: int = 3, fallback: float = 1.0) -> np.ndarray:
    """Each taxel's local spacing, mm ``(N,)``: the distance to its ``k``-th nearest
    neighbour (the 3rd by default: on a lattice this is the pitch, also where the
    spacing differs by direction, and also for a taxel on the edge of a hole)."""
    n = len(positions)
    if n < 2:
        return np.full(n, float(fallback))
    from scipy.spatial import cKDTree

    k = min(k, n - 1)
    dist, _ = cKDTree(positions).query(positions, k=k + 1)
    return np.maximum(dist[:, k], 1e-9)


def _linear_weights(taxels: np.ndarray, xs: np.ndarray, ys: np.ndarray,
                    max_edge: float | None, local_max: np.ndarray):
    """Barycentric weights of the grid points ``ys × xs`` (row-major) in the Delaunay
    triangles of the taxels. A triangle is dropped when its longest edge exceeds
    ``max_edge`` or, when that is ``None``, the mean ``local_max`` of its corners.

    Triangles are rasterised directly (each one visits the grid points in its
    bounding box) rather than located with ``Delaunay.find_simplex``, whose walk
    is slow on the regular lattices of CySkin layouts.
    """
    from scipy.spatial import Delaunay, QhullError

    n = len(taxels)
    if n < 3:
        raise InputError(f"linear imaging needs at least 3 taxels, the layout has {n}")
    try:
        tri = Delaunay(taxels)
    except QhullError as exc:
        raise InputError(f"cannot triangulate the layout (taxels collinear or duplicated "
                         f"positions?): {str(exc).splitlines()[0]}") from None
    corners = taxels[tri.simplices]  # (M, 3, 2)
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    # barycentric transforms by hand (Delaunay.transform is slow on degenerate lattices)
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    det = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
    area_ok = np.abs(det) > 1e-9 * np.maximum(edges.max(axis=1), 1e-12) ** 2
    limit = local_max[tri.simplices].mean(axis=1) if max_edge is None else max_edge
    good = np.nonzero((edges.max(axis=1) <= limit) & area_ok)[0]
    corners, simplices = corners[good], tri.simplices[good]
    e1, e2, det = e1[good], e2[good], det[good]
    inv = np.stack([np.stack([e2[:, 1], -e2[:, 0]], axis=1),
                    np.stack([-e1[:, 1], e1[:, 0]], axis=1)], axis=1) / det[:, None, None]
    nx, ny = len(xs), len(ys)
    dx = xs[1] - xs[0] if nx > 1 else 1.0
    dy = ys[1] - ys[0] if ny > 1 else 1.0
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    i0 = np.clip(np.ceil((lo[:, 0] - xs[0]) / dx - 1e-9), 0, nx).astype(np.int64)
    i1 = np.clip(np.floor((hi[:, 0] - xs[0]) / dx + 1e-9), -1, nx - 1).astype(np.int64)
    j0 = np.clip(np.ceil((lo[:, 1] - ys[0]) / dy - 1e-9), 0, ny).astype(np.int64)
    j1 = np.clip(np.floor((hi[:, 1] - ys[0]) / dy + 1e-9), -1, ny - 1).astype(np.int64)
    wide = np.maximum(i1 - i0 + 1, 0)
    tall = np.maximum(j1 - j0 + 1, 0)
    counts = wide * tall
    which = np.repeat(np.arange(len(good)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    ix = i0[which] + local % np.maximum(wide[which], 1)
    iy = j0[which] + local // np.maximum(wide[which], 1)
    pts = np.column_stack([xs[ix], ys[iy]])
    lam = np.einsum("kij,kj->ki", inv[which], pts - corners[which, 0])  # weights of B, C
    bary = np.column_stack([1.0 - lam.sum(axis=1), lam])
    inside = np.all(bary >= -1e-9, axis=1)  # NaN (flat triangles) fails too
    flat = iy * nx + ix
    # a point on a shared edge belongs to one triangle only
    _, first = np.unique(flat[inside], return_index=True)
    keep = np.nonzero(inside)[0][first]
    bary = np.clip(bary[keep], 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    rows = np.repeat(flat[keep], 3)
    cols = simplices[which[keep]].ravel()
    return rows, cols, bary.ravel()


def _gaussian_weights(taxels: np.ndarray, pts: np.ndarray, sigma: np.ndarray,
                      support: np.ndarray):
    """Normalised Gaussian weights (σ per taxel) of the taxels within 3σ of each point,
    for the points whose nearest taxel ``j`` is within ``support[j]``; others get none."""
    from scipy.spatial import cKDTree

    tree = cKDTree(taxels)
    k = min(3, len(taxels))
    dist, which = tree.query(pts, k=k, distance_upper_bound=float(support.max()))
    dist, which = dist.reshape(len(pts), k), which.reshape(len(pts), k)
    found = np.isfinite(dist[:, 0])
    on_skin = np.nonzero(found)[0]
    on_skin = on_skin[dist[on_skin, 0] <= support[which[on_skin, 0]]]
    # search each point as far as 3σ of the widest of its nearest taxels
    near = np.where(np.isfinite(dist[on_skin]), which[on_skin], which[on_skin, :1])
    radius = 3.0 * sigma[near].max(axis=1)
    neigh = tree.query_ball_point(pts[on_skin], r=radius, return_sorted=False)
    counts = np.fromiter((len(nb) for nb in neigh), dtype=np.int64, count=len(neigh))
    rows = np.repeat(on_skin, counts)
    cols = np.fromiter((j for nb in neigh for j in nb), dtype=np.int64, count=int(counts.sum()))
    d2 = ((pts[rows] - taxels[cols]) ** 2).sum(axis=1)
    s2 = sigma[cols] ** 2
    keep = d2 <= 9.0 * s2
    rows, cols, d2, s2 = rows[keep], cols[keep], d2[keep], s2[keep]
    w = np.exp(-0.5 * d2 / s2)
    total = np.bincount(rows, weights=w, minlength=len(pts))
    return rows, cols, w / total[rows]
