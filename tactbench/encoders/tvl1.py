"""``tvl1``: OpenCV-contrib's dual TV-L1 flow (accurate, slow)."""

from __future__ import annotations

import numpy as np

from tactbench.encoders.flow import DEFAULT_MAX_FLOW, DEFAULT_MIN_MAGNITUDE, FlowEncoder
from tactbench.errors import check_positive_float, check_positive_int


class TVL1(FlowEncoder):
    """Pressure, flow magnitude and direction from ``cv2.optflow.DualTVL1OpticalFlow``.

    Options are OpenCV's: ``tau`` (time step), ``lam`` (data-term weight,
    OpenCV's ``lambda``; smaller = smoother flow), ``theta``, ``scales``
    (pyramid levels), ``warps`` (per level), ``epsilon`` (stopping tolerance),
    ``iterations`` (outer iterations), ``inner_iterations``, ``median`` (median-filter size, 0/1 off).
    Frames are scaled to [0, 255], the intensity range OpenCV's defaults are
    tuned for. Defaults are OpenCV's except the iteration counts: 1 outer × 10
    inner iterations instead of 10 × 30 gave a lower endpoint error on the
    64 px tactile scenes of ``tactbench flowbench`` (0.58 against 0.73 px) in
    about half the time. Shared flow options: see :mod:`tactbench.encoders.flow`.
    """

    name = "tvl1"
    version = "1"

    image_sized = ("median",)

    def __init__(self, *, tau: float = 0.25, lam: float = 0.15, theta: float = 0.3,
                 scales: int = 5, warps: int = 5, epsilon: float = 0.01,
                 iterations: int = 1, inner_iterations: int = 10, median: int = 5,
                 max_flow: float = DEFAULT_MAX_FLOW,
                 min_magnitude: float = DEFAULT_MIN_MAGNITUDE, downscale: int = 1) -> None:
        super().__init__(max_flow=max_flow, min_magnitude=min_magnitude, downscale=downscale)
        self.tau = check_positive_float(tau, "tau")
        self.lam = check_positive_float(lam, "lam")
        self.theta = check_positive_float(theta, "theta")
        self.scales = check_positive_int(scales, "scales", maximum=30)
        self.warps = check_positive_int(warps, "warps", maximum=10_000)
        self.epsilon = check_positive_float(epsilon, "epsilon")
        self.iterations = check_positive_int(iterations, "iterations", maximum=10_000)
        self.inner_iterations = check_positive_int(inner_iterations, "inner_iterations",
                                                   maximum=10_000)
        self.median = check_positive_int(median, "median", minimum=0)

    def _prepare(self, images: np.ndarray) -> np.ndarray:
        return images * np.float32(255.0)

    def _flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        import cv2

        tv = cv2.optflow.DualTVL1OpticalFlow_create(
            tau=self.tau, lambda_=self.lam, theta=self.theta, nscales=self.scales,
            warps=self.warps, epsilon=self.epsilon, outerIterations=self.iterations,
            innnerIterations=self.inner_iterations,
            medianFiltering=max(1, self.median))
        out = np.empty((*prev.shape, 2), dtype=np.float32)
        for i in range(prev.shape[0]):
            out[i] = tv.calc(prev[i], curr[i], None)
        return out
