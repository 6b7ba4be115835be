"""``lucas-kanade``: OpenCV's pyramidal Lucas–Kanade, tracked from every grid point.

Of the three dense Lucas–Kanade routes available here this one was chosen by
measurement (benchmarks/encoders.py, docs/encoders.md, "Choosing lucas-kanade"):

- ``cv2.optflow.calcOpticalFlowSparseToDense`` returned NaN on tactile frames
  (flat zero background) and raised on an all-zero frame, which every
  sequence starts with (``I_{-1} = 0``): unusable without repairs.
- scikit-image's ``optical_flow_ilk`` (radius 7 / 4) has no pyramid: on the
  72 × 67 scenes its endpoint error was 1.21 / 1.18 px at ≈ 50 ms per pair; at
  357 × 334 it was the most accurate LK (0.77 px) but took ≈ 0.8 s per pair.
- ``cv2.calcOpticalFlowPyrLK`` started from every ``step``-th pixel and
  interpolated: 0.86 px at 72 × 67 in ≈ 9 ms per pair (window 21, step 2,
  10 iterations), 1.09 px at 357 × 334 in ≈ 70 ms (step 4). Tracking every
  pixel (step 1) was no more accurate and 3–4× slower.

The pyramidal route is the default's choice: the most accurate at the default
resolution and 3–11× faster everywhere (benchmarks/encoders.py, section
lucas-kanade; a loaded 2-core VM, 2026-11-21, timings ±40 %). At full
resolution ``step=4`` or ``downscale=2`` is the practical setting.

Points whose window has no texture (OpenCV's status 0: minimum eigenvalue of
the structure tensor below ``min_eigen``) get zero flow: nothing can be seen
moving there.
"""

from __future__ import annotations

import numpy as np

from tactbench.encoders.dis import to_uint8
from tactbench.encoders.flow import DEFAULT_MAX_FLOW, DEFAULT_MIN_MAGNITUDE, FlowEncoder
from tactbench.errors import check_positive_float, check_positive_int


class LucasKanade(FlowEncoder):
    """Pressure, flow magnitude and direction from dense pyramidal Lucas–Kanade.

    Parameters
    ----------
    winsize : int ≥ 3
        Side of the square LK window, pixels.
    levels : int ≥ 0
        Pyramid levels above the image (OpenCV's ``maxLevel``).
    iterations : int ≥ 1
        Iterations per level (stops earlier when the update is below 0.01 px).
    step : int ≥ 1
        Track every ``step``-th pixel in each direction and interpolate
        bilinearly in between (1 = every pixel).
    min_eigen : float > 0
        OpenCV's ``minEigThreshold``: windows flatter than this get zero flow.
    max_flow, min_magnitude, downscale
        Shared flow options, see :mod:`tactbench.encoders.flow`.

    OpenCV's LK works on 8-bit images, so frames are quantised to 256 levels.
    """

    name = "lucas-kanade"
    version = "1"
    min_size = 2

    image_sized = ("winsize", "step")

    def __init__(self, *, winsize: int = 21, levels: int = 3, iterations: int = 10,
                 step: int = 2, min_eigen: float = 1e-4, max_flow: float = DEFAULT_MAX_FLOW,
                 min_magnitude: float = DEFAULT_MIN_MAGNITUDE, downscale: int = 1) -> None:
        super().__init__(max_flow=max_flow, min_magnitude=min_magnitude, downscale=downscale)
        self.winsize = check_positive_int(winsize, "winsize", minimum=3)
        self.levels = check_positive_int(levels, "levels", minimum=0, maximum=30)
        self.iterations = check_positive_int(iterations, "iterations", maximum=10_000)
        self.step = check_positive_int(step, "step")
        self.min_eigen = check_positive_float(min_eigen, "min_eigen")

    def _prepare(self, images: np.ndarray) -> np.ndarray:
        return to_uint8(images)

    def _flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        import cv2

        n, h, w = prev.shape
        ys, xs = np.mgrid[0:h:self.step, 0:w:self.step]
        gh, gw = ys.shape
        points = np.stack([xs.ravel(), ys.ravel()], axis=-1).astype(np.float32)[:, None]
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, self.iterations, 0.01)
        out = np.empty((n, h, w, 2), dtype=np.float32)
        if self.step > 1:
            # grid point (i, j) sits at pixel (i * step, j * step): sample the
            # coarse field at fractional positions for an exact bilinear fill.
            my, mx = np.mgrid[0:h, 0:w].astype(np.float32) / self.step
        for i in range(n):
            moved, status, _err = cv2.calcOpticalFlowPyrLK(
                prev[i], curr[i], points, None, winSize=(self.winsize, self.winsize),
                maxLevel=self.levels, criteria=criteria, minEigThreshold=self.min_eigen)
            d = (moved - points).reshape(gh, gw, 2)
            d[status.reshape(gh, gw) == 0] = 0.0
            if self.step > 1:
                out[i] = cv2.remap(d, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            else:
                out[i] = d
        return out
