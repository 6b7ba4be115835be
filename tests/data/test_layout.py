"""TaxelLayout: ids and positions in mm, bounds, queries; unroll of 3-D positions."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.layout import TaxelLayout, unroll
from tactbench.errors import InputError

# ------------------------------------------------------------- the contract


def test_layout_normalises_types_and_default_bounds():
    lay = TaxelLayout(ids=[3, 1, 2], positions=[[0, 0], [10, 0], [0, 10]])
    assert lay.ids.dtype == np.int64 and lay.positions.dtype == np.float64
    assert lay.positions.shape == (3, 2) and len(lay) == 3
    spacing = lay.median_spacing()
    assert spacing == pytest.approx(10.0)
    assert lay.bounds == pytest.approx((-5, -5, 15, 15))  # box grown by half a spacing


@pytest.mark.parametrize("kwargs, message", [
    (dict(ids=[1, 1], positions=[[0, 0], [1, 1]]), "duplicate taxel ids 1"),
    (dict(ids=[1, 2], positions=[[0, 0]]), r"positions must be \(N=2, D=2\), got \(1, 2\)"),
    (dict(ids=[1, 2], positions=[[0, 0], [np.nan, 1]]), "NaN or Inf"),
    (dict(ids=[], positions=np.zeros((0, 2))), "non-empty"),
    (dict(ids=[1, 2], positions=[[0, 0], [1, 1]], bounds=(0, 0, -1, 1)), "bounds"),
])
def test_bad_layouts_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TaxelLayout(**kwargs)


def test_indices_of_names_ids_missing_from_the_layout():
    lay = TaxelLayout(ids=[10, 11, 12], positions=[[0, 0], [1, 0], [0, 1]], name="patch")
    assert lay.indices_of([12, 10]).tolist() == [2, 0]
    with pytest.raises(ValueError, match=r"not in layout patch: 99"):
        lay.indices_of([10, 99])


def test_layout_refuses_positions_that_are_not_numbers():
    with pytest.raises(ValueError, match="positions must be numbers"):
        TaxelLayout(ids=[1, 2], positions=[["a", "b"], ["c", "d"]])


def test_subset_keeps_order_and_bounds():
    lay = TaxelLayout(ids=[10, 11, 12], positions=[[0, 0], [1, 0], [0, 1]],
                      positions_3d=[[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    sub = lay.subset([12, 10])
    assert sub.ids.tolist() == [12, 10] and sub.bounds == lay.bounds
    assert sub.positions_3d.tolist() == [[0, 1, 0], [0, 0, 0]]


def test_unroll_flat_patch_keeps_distances():
    rng = np.random.default_rng(0)
    flat = rng.uniform(0, 50, (30, 2))
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    pts = np.column_stack([flat, np.zeros(30)]) @ rot.T
    out = unroll(pts, None)
    d_in = np.linalg.norm(flat[:, None] - flat[None], axis=2)
    d_out = np.linalg.norm(out[:, None] - out[None], axis=2)
    assert d_out == pytest.approx(d_in, abs=1e-9)


def test_grid_layout_is_row_major_with_half_pitch_bounds():
    lay = TaxelLayout.grid(3, 4, 2.5)
    assert lay.name == "grid-3x4" and lay.n_taxels == 12
    # taxel r * cols + c sits at x = c * pitch, y = r * pitch
    np.testing.assert_array_equal(lay.positions[6], [2 * 2.5, 1 * 2.5])
    np.testing.assert_array_equal(lay.ids, np.arange(12))
    assert lay.bounds == (-1.25, -1.25, 3 * 2.5 + 1.25, 2 * 2.5 + 1.25)
    from tactbench.data.imaging import image_shape

    assert image_shape(lay, 2.5) == (3, 4)  # one pixel per cell at pixel == pitch
    one = TaxelLayout.grid(1, 1, 4.0)
    assert one.bounds == (-2.0, -2.0, 2.0, 2.0)
    for bad in [(0, 4, 1.0), (3, 4, 0.0), (2.5, 4, 1.0)]:
        with pytest.raises(InputError):
            TaxelLayout.grid(*bad)
