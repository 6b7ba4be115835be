"""Imaging Φ: the sparse operator from taxel values to tactile images."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.imaging import Imager, image_shape
from tactbench.data.layout import TaxelLayout
from tactbench.datasets.forearm import cyskin_forearm


@pytest.fixture(scope="module")
def forearm():
    return cyskin_forearm()


@pytest.fixture(scope="module")
def grid():
    """A 6 × 5 grid of taxels 7.5 mm apart."""
    yy, xx = np.mgrid[0:5, 0:6]
    pos = np.column_stack([xx.ravel(), yy.ravel()]) * 7.5
    return TaxelLayout(ids=np.arange(30), positions=pos, name="grid")


@pytest.mark.parametrize("pixel_mm, shape", [(1.0, (357, 334)), (4.0, (90, 84)),
                                             (5.0, (72, 67))])
def test_forearm_image_shapes(forearm, pixel_mm, shape):
    assert Imager(forearm, pixel_mm=pixel_mm).shape == shape == image_shape(forearm, pixel_mm)
    assert Imager(forearm, pixel_mm=pixel_mm).apply(np.zeros(1558)).shape == shape


@pytest.mark.parametrize("bounds, pixel_mm, shape", [
    ((0, 0, 10, 20), 5.0, (4, 2)),  # whole pixels: no extra one
    ((0, 0, 10 + 1e-12, 20), 5.0, (4, 2)),  # rounding noise is not a pixel
    ((0, 0, 10.5, 20), 5.0, (4, 3)),  # a part pixel counts
    ((0, 0, 10, 20), 1e6, (1, 1)),  # never empty
])
def test_image_shape_rounds_up_and_is_never_empty(bounds, pixel_mm, shape):
    layout = TaxelLayout(ids=[1, 2, 3], positions=[[1, 1], [9, 1], [1, 19]], bounds=bounds)
    assert image_shape(layout, pixel_mm) == shape
    with pytest.raises(ValueError, match="pixel_mm must be > 0"):
        image_shape(layout, -1.0)


@pytest.mark.parametrize("method", ["linear", "gaussian"])
def test_one_frame_and_batch_agree(grid, method):
    im = Imager(grid, pixel_mm=2.0, method=method)
    rng = np.random.default_rng(0)
    batch = rng.uniform(0, 1, (4, 30)).astype(np.float32)
    out = im.apply(batch)
    assert out.shape == (4, *im.shape) and out.dtype == np.float32
    single = im.apply(batch[2])
    assert single.shape == im.shape
    assert np.allclose(out[2], single, atol=1e-6)


@pytest.mark.parametrize("method", ["linear", "gaussian"])
@pytest.mark.parametrize("pixel_mm", [1.0, 5.0])
def test_constant_field_is_reproduced_on_the_skin_and_zero_off_it(forearm, method, pixel_mm):
    im = Imager(forearm, pixel_mm=pixel_mm, method=method)
    img = im.apply(np.full(forearm.n_taxels, 0.7, dtype=np.float32))
    assert np.all(np.isfinite(img))
    full = im.coverage >= 1 - 1e-6
    assert full.mean() > 0.8  # the generated forearm is mostly skin
    assert np.allclose(img[full], 0.7, atol=1e-5)
    assert np.all(img[im.coverage == 0] == 0)
    assert img.min() >= 0 and img.max() <= 0.7 + 1e-5  # convex combination × coverage


def test_linear_reproduces_a_linear_field_exactly(grid):
    im = Imager(grid, pixel_mm=1.0, method="linear")
    field = (0.01 * grid.positions[:, 0] + 0.02 * grid.positions[:, 1]).astype(np.float32)
    img = im.apply(field)
    x0, y0, _, _ = grid.bounds
    ii, jj = np.nonzero(im.coverage >= 1)
    expect = 0.01 * (x0 + jj + 0.5) + 0.02 * (y0 + ii + 0.5)
    assert np.allclose(img[ii, jj], expect, atol=1e-5)


def test_pixels_outside_the_skin_are_zero(grid):
    im = Imager(grid, pixel_mm=1.0)
    img = im.apply(np.ones(30))
    # bounds are grown by half a spacing: the outer ring of pixels is off the triangulation
    assert np.all(img[0] == 0) and np.all(img[:, -1] == 0)


def test_holes_wider_than_max_edge_are_not_bridged():
    # two patches 40 mm apart: no triangle should span the gap
    a = np.array([[x, y] for x in (0, 7.5, 15) for y in (0, 7.5, 15)], dtype=float)
    lay = TaxelLayout(ids=np.arange(18), positions=np.vstack([a, a + [55, 0]]))
    im = Imager(lay, pixel_mm=1.0)
    x0 = lay.bounds[0]
    assert np.all(im.apply(np.ones(18))[:, int(16 - x0):int(54 - x0)] == 0)
    # the Gaussian splat reaches one local spacing (here 7.5 √2 mm at the corners)
    # beyond the outer taxels
    gauss = Imager(lay, pixel_mm=1.0, method="gaussian").apply(np.ones(18))
    assert np.all(gauss[:, int(27 - x0):int(43 - x0)] == 0)
    assert np.all(gauss[:, int(20 - x0)] > 0)


@pytest.mark.parametrize("method", ["linear", "gaussian"])
def test_missing_taxels_are_filled_from_neighbours(grid, method):
    im = Imager(grid, pixel_mm=1.0, method=method)
    values = np.full(30, 0.5, dtype=np.float32)
    values[[7, 14]] = [np.nan, np.inf]
    img = im.apply(values)
    assert np.all(np.isfinite(img))
    full = im.coverage >= 1 - 1e-6
    assert np.allclose(img[full], 0.5, atol=1e-5)  # neighbours all read 0.5
    allnan = im.apply(np.full(30, np.nan))
    assert np.all(allnan == 0)


def test_missing_taxels_in_a_batch_only_affect_their_frame(grid):
    im = Imager(grid, pixel_mm=2.0)
    batch = np.random.default_rng(1).uniform(0, 1, (3, 30)).astype(np.float32)
    clean = im.apply(batch)
    batch[1, 3] = np.nan
    dirty = im.apply(batch)
    assert np.allclose(dirty[[0, 2]], clean[[0, 2]], atol=1e-6)


def test_coarse_pixels_average_over_their_area(forearm):
    # a single pressed taxel keeps (about) its total weight at any pixel size
    values = np.zeros(forearm.n_taxels, dtype=np.float32)
    values[700] = 1.0
    fine = Imager(forearm, pixel_mm=1.0).apply(values).sum() * 1.0
    for pixel in (4.0, 5.0, 6.0):
        coarse = Imager(forearm, pixel_mm=pixel)
        assert coarse.supersample > 1
        assert coarse.apply(values).sum() * pixel ** 2 == pytest.approx(fine, rel=0.05)


def test_bad_arguments(grid):
    with pytest.raises(ValueError, match="unknown imaging method 'cubic'"):
        Imager(grid, method="cubic")
    with pytest.raises(ValueError, match="pixel_mm must be > 0, got 0"):
        Imager(grid, pixel_mm=0)
    im = Imager(grid, pixel_mm=3)
    with pytest.raises(ValueError,
                       match=r"expected values of shape \(N,\) or \(T, N\) with N = 30"):
        im.apply(np.zeros(29))
    with pytest.raises(ValueError, match="unknown imaging method 'liner'; did you mean 'linear'"):
        Imager(grid, method="liner")
    with pytest.raises(ValueError, match="supersample must be ≥ 1"):
        Imager(grid, supersample=0)
    with pytest.raises(ValueError, match="sigma must be > 0"):
        Imager(grid, method="gaussian", sigma=0.0)
    with pytest.raises(ValueError, match="at least 3 taxels"):
        Imager(TaxelLayout(ids=[1, 2], positions=[[0, 0], [1, 0]]))


def test_matrix_is_sparse(forearm):
    im = Imager(forearm, pixel_mm=1.0)
    assert im.matrix.shape == (357 * 334, 1558)
    assert im.matrix.nnz <= 3 * 357 * 334


def test_a_missing_taxel_reads_its_neighbours_mean(grid):
    im = Imager(grid, pixel_mm=1.0)
    values = np.arange(30, dtype=np.float32) ** 2
    values[8] = np.nan  # row 1, column 2 of the 6-wide grid
    filled = im.fill_missing(values[None])[0]
    # taxels within 1.5 × 7.5 mm: the 4 at 7.5 mm and the 4 diagonal ones at 10.6 mm
    assert filled[8] == pytest.approx(np.mean(np.array([2, 7, 9, 14, 1, 3, 13, 15]) ** 2))
    assert np.array_equal(np.delete(filled, 8), np.delete(values, 8))


@pytest.mark.parametrize("pixel_mm", [1.0, 4.0, 5.0, 6.0])
def test_coarse_images_keep_where_the_pressure_is(forearm, pixel_mm):
    """The pressure-weighted centre of the image matches that of the taxels."""
    xy = forearm.positions
    centre = np.array([150.0, 200.0])
    values = np.exp(-0.5 * ((xy - centre) ** 2).sum(1) / 12.0 ** 2).astype(np.float32)
    im = Imager(forearm, pixel_mm=pixel_mm)
    img = im.apply(values)
    ii, jj = np.mgrid[0:im.shape[0], 0:im.shape[1]]
    x0, y0, _, _ = forearm.bounds
    cx = (img * (x0 + (jj + 0.5) * pixel_mm)).sum() / img.sum()
    cy = (img * (y0 + (ii + 0.5) * pixel_mm)).sum() / img.sum()
    assert np.hypot(cx - centre[0], cy - centre[1]) < 1.5


@pytest.mark.parametrize("method", ["linear", "gaussian"])
def test_no_holes_where_taxels_are_sparser_than_the_median(method):
    # dense at the edges, twice as sparse in the middle (as flattened maps are)
    ticks = np.array([0, 4, 8, 16, 24, 32, 40, 44, 48], dtype=float)
    yy, xx = np.meshgrid(ticks, ticks, indexing="ij")
    lay = TaxelLayout(ids=np.arange(81), positions=np.column_stack([xx.ravel(), yy.ravel()]),
                      bounds=(0, 0, 48, 48))
    assert lay.median_spacing() == pytest.approx(4.0)
    im = Imager(lay, pixel_mm=1.0, method=method)
    assert np.all(im.coverage[1:-1, 1:-1] > 0)


@pytest.mark.parametrize("name", ["ur10e_link1_patch1_flatmap.json",
                                  "ur10e_link2_patch1_flatmap.json", "ur10e_link1_patch1.json"])
@pytest.mark.parametrize("method", ["linear", "gaussian"])
def test_real_layouts_image_without_holes(shared_data, name, method):
    """Flattened maps are denser at their edges: the middle must not fall through."""
    from tactbench.data.layout_io import load_layout

    lay = load_layout(shared_data / "cyskin-layouts" / name)
    im = Imager(lay, pixel_mm=1.0, method=method)
    h, w = im.shape
    centre = im.coverage[h // 10:h - h // 10, w // 10:w - w // 10]
    assert np.all(centre > 0)
    assert (im.coverage > 0).mean() > 0.8


# ------------------------------------------------------------- hardening (issue 11)


def test_an_imager_above_the_memory_budget_is_refused_before_it_allocates(
        forearm, monkeypatch, memory_cap):
    from tactbench.data.imaging import imager_build_bytes
    from tactbench.errors import BudgetError

    estimate = imager_build_bytes(forearm, 0.5)  # measured peak: 125.5 MiB
    assert 125 << 20 < estimate < 160 << 20
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "64")
    with memory_cap(8):
        with pytest.raises(BudgetError, match=r"imaging at 0\.5 mm \(714×668 px, linear, 1×1 "
                                              r"sub-samples per pixel\) would need about "
                                              r"1[45]\d\.\d MiB, more than the memory budget "
                                              r"of 64\.0 MiB"):
            Imager(forearm, pixel_mm=0.5)
    # the study's 0.01 mm typo, under the default budget (half this machine's memory)
    monkeypatch.delenv("TACTBENCH_MEMORY_MIB")
    assert imager_build_bytes(forearm, 0.01) > 300 << 30
    assert imager_build_bytes(forearm, 5.0) < 16 << 20


def test_imaging_a_batch_above_the_memory_budget_is_refused(forearm, monkeypatch):
    from tactbench.errors import BudgetError

    imager = Imager(forearm, pixel_mm=5.0)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "1")
    with pytest.raises(BudgetError, match=r"imaging 100 frames at 5 mm \(72×67 px\)"):
        imager.apply(np.zeros((100, 1558), np.float32))
    assert imager.apply(np.zeros((2, 1558), np.float32)).shape == (2, 72, 67)
    assert imager.apply(np.zeros(1558, np.float32)).shape == (72, 67)


@pytest.mark.parametrize("pixel_mm", [1e-300, 5e-324])
def test_a_pixel_size_far_too_small_is_one_clear_error(forearm, pixel_mm):
    from tactbench.errors import InputError

    with pytest.raises(InputError, match="is far too small for a layout of 334 × 357 mm"):
        image_shape(forearm, pixel_mm)


def test_a_pixel_size_far_too_large_is_one_clear_error(forearm, monkeypatch):
    from tactbench.data.imaging import imager_build_bytes
    from tactbench.errors import BudgetError, InputError

    with pytest.raises(InputError, match=r"pixel size 1e\+155 mm is far too large for taxels"):
        Imager(forearm, pixel_mm=1e155)
    # 10 m pixels: one pixel of 5406 × 5406 sub-samples, ~8.7 GiB to build
    assert imager_build_bytes(forearm, 10_000.0) > 8 << 30
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "4096")
    with pytest.raises(BudgetError, match=r"imaging at 10000 mm \(1×1 px, linear, 5\d+×5\d+ "):
        Imager(forearm, pixel_mm=10_000.0)
