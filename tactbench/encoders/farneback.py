"""``farneback``: the study's encoding with OpenCV's Farnebäck dense flow."""

from __future__ import annotations

import numpy as np

from tactbench.encoders.flow import DEFAULT_MAX_FLOW, DEFAULT_MIN_MAGNITUDE, FlowEncoder


class Farneback(FlowEncoder):
    """Pressure, flow magnitude and direction from ``cv2.calcOpticalFlowFarneback``.

    The options are OpenCV's, with its usual defaults (those of the study's
    encoding): ``pyr_scale`` (image scale between pyramid levels, < 1),
    ``levels`` (pyramid levels above the image), ``winsize`` (averaging window,
    px), ``iterations`` (per level), ``poly_n`` (pixel neighbourhood of the
    polynomial expansion, 5 or 7) and ``poly_sigma`` (its Gaussian σ, 1.1 for
    ``poly_n=5``, 1.5 for 7); ``gaussian`` uses a Gaussian instead of a box
    window. Shared flow options (``max_flow``, ``min_magnitude``,
    ``downscale``): see :mod:`tactbench.encoders.flow`.

    Frames are scaled to [0, 255] first: on [0, 1] floats OpenCV's thresholds
    make the flow vanish (FACTS.md).
    """

    name = "farneback"
    version = "1"

    def __init__(self, *, pyr_scale: float = 0.5, levels: int = 3, winsize: int = 15,
                 iterations: int = 3, poly_n: int = 5, poly_sigma: float = 1.2,
                 gaussian: bool = False, max_flow: float = DEFAULT_MAX_FLOW,
                 min_magnitude: float = DEFAULT_MIN_MAGNITUDE, downscale: int = 1) -> None:
        super().__init__(max_flow=max_flow, min_magnitude=min_magnitude, downscale=downscale)
        if not 0 < pyr_scale < 1:
            raise ValueError(f"pyr_scale must lie in (0, 1), got {pyr_scale!r}")
        for key, value, low in (("levels", levels, 0), ("winsize", winsize, 1),
                                ("iterations", iterations, 1)):
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{key} must be an integer ≥ {low}, got {value!r}")
        if poly_n not in (5, 7):
            raise ValueError(f"poly_n must be 5 or 7, got {poly_n!r}")
        if not poly_sigma > 0:
            raise ValueError(f"poly_sigma must be > 0, got {poly_sigma!r}")
        self.pyr_scale = float(pyr_scale)
        self.levels = levels
        self.winsize = winsize
        self.iterations = iterations
        self.poly_n = poly_n
        self.poly_sigma = float(poly_sigma)
        self.gaussian = bool(gaussian)

    def _prepare(self, images: np.ndarray) -> np.ndarray:
        return images * np.float32(255.0)

    def _flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        import cv2

        flags = cv2.OPTFLOW_FARNEBACK_GAUSSIAN if self.gaussian else 0
        out = np.empty((*prev.shape, 2), dtype=np.float32)
        for i in range(prev.shape[0]):
            out[i] = cv2.calcOpticalFlowFarneback(
                prev[i], curr[i], None, self.pyr_scale, self.levels, self.winsize,
                self.iterations, self.poly_n, self.poly_sigma, flags)
        return out
