"""kornia-flow: the matrix filters equal kornia's ops; the pyramid recovers large motion."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
kornia = pytest.importorskip("kornia")

from tactbench.encoders import kornia_flow as kf  # noqa: E402
from tactbench.encoders.evaluation.conformance import contact_sequence  # noqa: E402


@pytest.fixture
def images():
    g = torch.Generator().manual_seed(0)
    return torch.rand((3, 1, 21, 26), generator=g, dtype=torch.float64)


def test_sobel_matrices_equal_kornia_spatial_gradient(images):
    ref = kornia.filters.spatial_gradient(images, mode="sobel", order=1, normalized=True)
    gx, gy = kf._sobel(images[:, 0], torch.float64, "cpu")
    torch.testing.assert_close(gx, ref[:, 0, 0])
    torch.testing.assert_close(gy, ref[:, 0, 1])


def test_gaussian_matrices_equal_kornia_gaussian_blur(images):
    sigma = 2.0
    radius = int(np.ceil(3 * sigma))
    ref = kornia.filters.gaussian_blur2d(images, (2 * radius + 1,) * 2, (sigma, sigma),
                                         border_type="replicate")
    h, w = images.shape[-2:]
    got = (kf._matrix(("gauss", h, sigma), torch.float64, "cpu") @ images[:, 0]
           @ kf._matrix(("gauss-t", w, sigma), torch.float64, "cpu"))
    torch.testing.assert_close(got, ref[:, 0])


@pytest.mark.parametrize("size", [(21, 26), (32, 32), (17, 9)])
def test_pyrdown_matrices_equal_kornia_pyrdown(size):
    img = torch.rand((2, 1, *size), dtype=torch.float64,
                     generator=torch.Generator().manual_seed(1))
    ref = kornia.geometry.transform.pyrdown(img)
    down_y, down_x_t = kf._pyrdown_operators(*size, torch.float64, "cpu")
    torch.testing.assert_close(down_y @ img[:, 0] @ down_x_t, ref[:, 0])


def test_bilinear_matrices_equal_torch_interpolate():
    img = torch.rand((2, 1, 7, 9), dtype=torch.float64,
                     generator=torch.Generator().manual_seed(2))
    ref = torch.nn.functional.interpolate(img, size=(15, 19), mode="bilinear",
                                          align_corners=False)
    got = kf._bilinear(15, 7) @ img[:, 0] @ kf._bilinear(19, 9).T
    torch.testing.assert_close(got, ref[:, 0])


@pytest.mark.parametrize("shift", [0.5, 3.0, 6.0])
def test_pyramid_recovers_motion_a_single_level_misses(shift):
    seq = contact_sequence((64, 64), 2, shift=shift, angle=0.0, sigma=5.0)
    mask = np.minimum(seq[0], seq[1]) > 0.3
    pyramid = kf.KorniaFlow().flow(seq[:1], seq[1:])
    assert np.median(pyramid[0, ..., 0][mask]) == pytest.approx(shift, rel=0.1, abs=0.05)
    if shift > 2:  # one level, as a single-scale method: it falls short of the motion
        single = kf.KorniaFlow(levels=1).flow(seq[:1], seq[1:])
        assert np.median(single[0, ..., 0][mask]) < 0.8 * shift


def test_batches_do_not_mix_pairs():
    seq = contact_sequence((32, 32), 6, shift=1.5, angle=1.0)
    prev, curr = seq[:-1], seq[1:]
    whole = kf.KorniaFlow(batch=64).flow(prev, curr)
    split = kf.KorniaFlow(batch=2).flow(prev, curr)
    np.testing.assert_allclose(whole, split, atol=1e-5)


def test_zero_ridge_does_not_divide_by_zero():
    seq = np.zeros((3, 16, 16), np.float32)
    seq[1:, 5:9, 5:9] = 0.7
    out = kf.KorniaFlow(reg=0.0).encode(seq)
    assert np.isfinite(out).all()


def test_cuda_request_without_gpu_is_a_clear_error():
    if torch.cuda.is_available():
        pytest.skip("a GPU is present")
    with pytest.raises(ValueError, match="CUDA"):
        kf.KorniaFlow(device="cuda").encode(np.zeros((2, 8, 8), np.float32))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA GPU")
def test_cuda_matches_cpu():
    seq = contact_sequence((48, 48), 4, shift=2.0, angle=0.7)
    cpu = kf.KorniaFlow(device="cpu").encode(seq)
    gpu = kf.KorniaFlow(device="cuda").encode(seq)
    np.testing.assert_allclose(cpu, gpu, atol=1e-3)
