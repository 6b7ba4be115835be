"""``kornia-flow``: a coarse-to-fine dense Lucas–Kanade flow in torch + kornia.

kornia (0.9) has no optical-flow estimator, so this one is built from its
primitives: a Gaussian pyramid (kornia's ``pyrdown``), Sobel gradients
(``spatial_gradient``), Gaussian windows (``get_gaussian_kernel1d``) and
warping (``kornia.geometry.transform.remap``). The linear filters are applied
as small matrices (see ``_matrix`` below: same numbers as kornia's functions,
checked by the tests, several times faster on tactile-sized images).

Method, per pyramid level from coarse to fine (the flow from the level above
is upsampled and doubled):

1. warp ``I_k`` back by the current flow: ``W(x) = I_k(x + u(x))``;
2. Sobel gradients ``g = (∇I_{k-1} + ∇W) / 2`` (the symmetric average gave a
   lower error than ``∇I_{k-1}`` alone: 0.42 against 0.52 px on 64 × 64
   scenes with two warps per level, during development) and the residual ``e = W - I_{k-1}``;
3. per pixel, solve the Gaussian-windowed 2 × 2 normal equations
   ``(G * g gᵀ + λ I) δ = -G * (g e)``; the ridge term ``λ`` (``reg``) makes
   flat regions (no contact, no texture) return δ = 0 instead of noise;
4. ``u ← u + clip(δ, ±1 px)`` and repeat ``warps`` times.

Unlike a single-scale Horn–Schunck, the pyramid recovers motions of several
pixels (FACTS.md). All frame pairs of a sequence go through the network of
tensor ops as one batch, on CUDA when available (``device="auto"``).
"""

from __future__ import annotations

import math

import numpy as np

from tactbench.encoders.flow import DEFAULT_MAX_FLOW, DEFAULT_MIN_MAGNITUDE, FlowEncoder
from tactbench.errors import InputError, check_choice, check_positive_float, check_positive_int


class KorniaFlow(FlowEncoder):
    """Pressure, flow magnitude and direction from a batched coarse-to-fine dense LK.

    Parameters
    ----------
    levels : int ≥ 1
        Pyramid levels (the image counts as one); fewer are used when a level
        would be smaller than 8 px.
    warps : int ≥ 1
        Warp-and-solve iterations per level. On the 72 × 67 flowbench scenes 1
        gave 0.40 px endpoint error at ~0.6 ms per pair and 2 gave 0.32 px at
        ~1.2 ms (Farnebäck: 0.98 px at ~1.1 ms; CPU time, 1 thread): the default
        is 1, so that kornia-flow is both faster and more accurate than Farnebäck.
    window : float > 0
        σ of the Gaussian window of the local least squares, in pixels of each level.
    reg : float ≥ 0
        Ridge term λ added to the structure tensor (intensity² units, images in [0, 1]).
    device : ``"auto"``, ``"cpu"`` or ``"cuda"``
        Where the tensors live; ``auto`` picks CUDA when torch sees a GPU.
    batch : int ≥ 1
        Frame pairs per batch (bounds memory on large images).
    threads : int ≥ 0
        torch CPU threads while encoding (restored afterwards); 0 keeps torch's
        setting. The default 1 was measured best on the 2-core VM: the batched
        ops on tactile-sized images are too small to split, and with 2 threads
        the encoder ran 3–10× slower whenever other processes shared the cores
        (benchmarks/encoders.py, section kornia).
    max_flow, min_magnitude, downscale
        Shared flow options, see :mod:`tactbench.encoders.flow`.
    """

    name = "kornia-flow"
    version = "1"
    min_size = 4
    batched = True

    image_sized = ("window",)

    def __init__(self, *, levels: int = 4, warps: int = 1, window: float = 3.0,
                 reg: float = 1e-5, device: str = "auto", batch: int = 64, threads: int = 1,
                 max_flow: float = DEFAULT_MAX_FLOW,
                 min_magnitude: float = DEFAULT_MIN_MAGNITUDE, downscale: int = 1) -> None:
        super().__init__(max_flow=max_flow, min_magnitude=min_magnitude, downscale=downscale)
        self.levels = check_positive_int(levels, "levels", maximum=30)
        self.warps = check_positive_int(warps, "warps", maximum=10_000)
        self.window = check_positive_float(window, "window (Gaussian σ, px)")
        self.reg = check_positive_float(reg, "reg", allow_zero=True)
        self.device = check_choice(device, "device", ["auto", "cpu", "cuda"])
        self.batch = check_positive_int(batch, "batch")
        self.threads = check_positive_int(threads, "threads (0: torch's setting)", minimum=0)

    def torch_device(self):
        import torch

        if self.device == "auto":
            return torch.device("cuda" if torch.cuda.is_available() else "cpu")
        if self.device == "cuda" and not torch.cuda.is_available():
            raise InputError("kornia-flow: device='cuda' but torch sees no CUDA GPU")
        return torch.device(self.device)

    def _flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        import torch

        dev = self.torch_device()
        out = np.empty((*prev.shape, 2), dtype=np.float32)
        old_threads = torch.get_num_threads()
        if self.threads and dev.type == "cpu" and self.threads != old_threads:
            torch.set_num_threads(self.threads)
        try:
            self._run(prev, curr, out, dev)
        finally:
            if torch.get_num_threads() != old_threads:
                torch.set_num_threads(old_threads)
        return out

    def _run(self, prev: np.ndarray, curr: np.ndarray, out: np.ndarray, dev) -> None:
        import torch

        with torch.inference_mode():
            for start in range(0, prev.shape[0], self.batch):
                stop = min(start + self.batch, prev.shape[0])
                p = torch.from_numpy(prev[start:stop, None]).to(dev)
                c = torch.from_numpy(curr[start:stop, None]).to(dev)
                flow = dense_lk(p, c, levels=self.levels, warps=self.warps,
                                window=self.window, reg=self.reg)
                out[start:stop] = flow.permute(0, 2, 3, 1).cpu().numpy()


def dense_lk(prev, curr, *, levels: int, warps: int, window: float, reg: float):
    """Coarse-to-fine dense LK: ``(B, 1, H, W)`` tensors → flow ``(B, 2, H, W)`` px/frame."""
    import torch

    pyr0, pyr1 = [prev[:, 0]], [curr[:, 0]]
    for _ in range(levels - 1):
        h, w = pyr0[-1].shape[-2:]
        if min(h, w) < 16:  # the next level would be < 8 px: too little to see
            break
        down_y, down_x_t = _pyrdown_operators(h, w, prev.dtype, prev.device)
        pyr0.append(down_y @ pyr0[-1] @ down_x_t)
        pyr1.append(down_y @ pyr1[-1] @ down_x_t)

    flow = None
    for a, b in zip(reversed(pyr0), reversed(pyr1)):
        h, w = a.shape[-2:]
        if flow is None:
            flow = a.new_zeros((a.shape[0], 2, h, w))
        else:
            fh, fw = flow.shape[-2:]
            up_y = _matrix(("bilinear", h, fh), a.dtype, a.device)
            up_x_t = _matrix(("bilinear-t", w, fw), a.dtype, a.device)
            flow = up_y @ flow @ up_x_t
            flow = flow * torch.tensor([w / fw, h / fh], dtype=flow.dtype,
                                       device=flow.device).view(1, 2, 1, 1)
        flow = _refine(a, b, flow, warps=warps, window=window, reg=reg)
    return flow


def _refine(a, b, flow, *, warps: int, window: float, reg: float):
    """``warps`` Gauss–Newton steps of windowed LK at one level; ``a``, ``b``: ``(B, H, W)``."""
    import torch
    from kornia.geometry.transform import remap

    h, w = a.shape[-2:]
    dt, dev = a.dtype, a.device
    gauss_y = _matrix(("gauss", h, window), dt, dev)
    gauss_x_t = _matrix(("gauss-t", w, window), dt, dev)
    ys, xs = torch.meshgrid(torch.arange(h, dtype=dt, device=dev),
                            torch.arange(w, dtype=dt, device=dev), indexing="ij")
    ga = _sobel(a, dt, dev)
    for _ in range(warps):
        warped = remap(b[:, None], xs + flow[:, 0], ys + flow[:, 1], mode="bilinear",
                       padding_mode="border", align_corners=True)[:, 0]
        gw = _sobel(warped, dt, dev)
        gx, gy = 0.5 * (ga[0] + gw[0]), 0.5 * (ga[1] + gw[1])
        err = warped - a
        prods = torch.stack([gx * gx, gx * gy, gy * gy, gx * err, gy * err], dim=1)
        sxx, sxy, syy, sxe, sye = (gauss_y @ prods @ gauss_x_t).unbind(1)
        sxx = sxx + reg
        syy = syy + reg
        # det ≥ reg² > 0 for reg > 0 (the tensor is positive semi-definite). With
        # reg = 0 a flat window has det = 0 but also a zero right-hand side, so
        # the floor turns 0/0 into 0 instead of NaN.
        det = (sxx * syy - sxy * sxy).clamp_min_(1e-20)
        du = (sxy * sye - syy * sxe) / det
        dv = (sxy * sxe - sxx * sye) / det
        flow = flow + torch.stack([du, dv], dim=1).clamp_(-1.0, 1.0)
    return flow


def _sobel(img, dtype, device):
    """kornia's normalised Sobel gradients of ``(B, H, W)``, replicate border: ``(gx, gy)``."""
    h, w = img.shape[-2:]
    gx = _matrix(("smooth", h), dtype, device) @ img @ _matrix(("diff-t", w), dtype, device)
    gy = _matrix(("diff", h), dtype, device) @ img @ _matrix(("smooth-t", w), dtype, device)
    return gx, gy


def _pyrdown_operators(h: int, w: int, dtype, device):
    """kornia's ``pyrdown`` (5-tap binomial blur, reflect border, then bilinear
    resampling to ``(h // 2, w // 2)``) as two matrices: ``down_y @ img @ down_x_t``."""
    return (_matrix(("pyrdown", h), dtype, device), _matrix(("pyrdown-t", w), dtype, device))


# Separable filters as matrices.
#
# A 1-D linear filter along x is ``image @ K.T`` where ``K[i, j]`` is the weight
# of input pixel ``j`` in output pixel ``i``; the border rule (replicate,
# reflect) folds into ``K``, so the result is exact, and one batched matmul
# per axis replaces a convolution. On tactile-sized images this is what makes
# the batched CPU flow fast: 16 × 5 × 64 × 64 with a 13-tap Gaussian took
# 0.3 ms as two matmuls against 2.5 ms as a depthwise convolution and 16 ms
# through ``kornia.filters.gaussian_blur2d`` (2 CPU threads, noisy machine).
# tests/test_encoders_kornia.py checks these matrices against kornia's
# ``spatial_gradient``, ``gaussian_blur2d`` and ``pyrdown``.

_MATRICES: dict = {}


def _matrix(key: tuple, dtype, device):
    full = (key, dtype, str(device))
    m = _MATRICES.get(full)
    if m is None:
        if len(_MATRICES) > 256:  # bounded: the image sizes of one run are few
            _MATRICES.clear()
        kind = key[0]
        transpose = kind.endswith("-t")
        m = _build(kind.removesuffix("-t"), *key[1:])
        if transpose:
            m = m.T
        m = _MATRICES[full] = m.contiguous().to(dtype=dtype, device=device)
    return m


def _build(kind: str, *args):
    import torch

    if kind == "gauss":
        n, sigma = args
        from kornia.filters import get_gaussian_kernel1d

        radius = max(1, math.ceil(3 * sigma))
        taps = get_gaussian_kernel1d(2 * radius + 1, sigma, dtype=torch.float64)[0].tolist()
        return _band(n, taps, "replicate")
    if kind == "diff":
        return _band(args[0], [-0.5, 0.0, 0.5], "replicate")
    if kind == "smooth":
        return _band(args[0], [0.25, 0.5, 0.25], "replicate")
    if kind == "pyrdown":
        n = args[0]
        blur = _band(n, [x / 16.0 for x in (1.0, 4.0, 6.0, 4.0, 1.0)], "reflect")
        return _bilinear(n // 2, n) @ blur
    if kind == "bilinear":
        return _bilinear(*args)
    raise KeyError(kind)


def _band(n: int, taps: list[float], border: str):
    """``(n, n)`` float64 matrix of a centred 1-D filter with the given border rule."""
    import torch

    r = (len(taps) - 1) // 2
    m = torch.zeros((n, n), dtype=torch.float64)
    for i in range(n):
        for j, tap in enumerate(taps):
            k = i + j - r
            if border == "replicate" or n == 1:
                k = min(max(k, 0), n - 1)
            else:  # reflect without repeating the edge: -1 → 1, n → n - 2
                while k < 0 or k > n - 1:
                    k = -k if k < 0 else 2 * (n - 1) - k
            m[i, k] += tap
    return m


def _bilinear(n_out: int, n_in: int):
    """``(n_out, n_in)`` linear resampling, ``align_corners=False`` (torch's rule)."""
    import torch

    m = torch.zeros((n_out, n_in), dtype=torch.float64)
    scale = n_in / n_out
    for i in range(n_out):
        src = max((i + 0.5) * scale - 0.5, 0.0)
        lo = min(int(math.floor(src)), n_in - 1)
        hi = min(lo + 1, n_in - 1)
        frac = src - lo
        m[i, lo] += 1.0 - frac
        m[i, hi] += frac
    return m
