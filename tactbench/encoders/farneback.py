"""``farneback``: the study's encoding with OpenCV's Farnebäck dense flow."""

from __future__ import annotations

import numpy as np

from tactbench.encoders.flow import DEFAULT_MAX_FLOW, DEFAULT_MIN_MAGNITUDE, FlowEncoder
from tactbench.errors import InputError, check_positive_float, check_positive_int


#: Upper bounds that follow from no image (a pyramid of 30 halvings is below one pixel
#: for any image; iterations beyond thousands are a typo, and each costs a full pass).
MAX_LEVELS = 30
MAX_ITERATIONS = 10_000
MAX_MARGIN = 1024


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

    ``margin`` (px): a frame pair with pressure on the image border, or
    smaller than 24 px, is padded on every side by edge replication before the
    flow is computed, then cropped. Without it OpenCV's Farnebäck reports
    motion between *identical* frames wherever pressure touches the border (up
    to 0.24 px/frame on 40 × 40 contact images, ~1 px/frame on images ≤ 9 px;
    found by ``tactbench stability``); 8 px of replication brings that below
    2e-4 px/frame. Pairs with a blank border, the usual case, pay nothing;
    others pay for the extra pixels (+56 % at 64 × 64, +10 % at 357 × 334).
    ``margin=0`` is OpenCV's behaviour.
    """

    name = "farneback"
    version = "2"

    image_sized = ("winsize",)

    def __init__(self, *, pyr_scale: float = 0.5, levels: int = 3, winsize: int = 15,
                 iterations: int = 3, poly_n: int = 5, poly_sigma: float = 1.2,
                 gaussian: bool = False, margin: int = 8, max_flow: float = DEFAULT_MAX_FLOW,
                 min_magnitude: float = DEFAULT_MIN_MAGNITUDE, downscale: int = 1) -> None:
        super().__init__(max_flow=max_flow, min_magnitude=min_magnitude, downscale=downscale)
        self.pyr_scale = check_positive_float(pyr_scale, "pyr_scale")
        if self.pyr_scale >= 1:
            raise InputError(f"pyr_scale must lie in (0, 1), got {pyr_scale!r}")
        self.levels = check_positive_int(levels, "levels", minimum=0, maximum=MAX_LEVELS)
        self.winsize = check_positive_int(winsize, "winsize")
        self.iterations = check_positive_int(iterations, "iterations",
                                             maximum=MAX_ITERATIONS)
        if poly_n not in (5, 7):
            raise InputError(f"poly_n must be 5 or 7, got {poly_n!r}")
        self.poly_n = poly_n
        self.poly_sigma = check_positive_float(poly_sigma, "poly_sigma")
        self.gaussian = bool(gaussian)
        self.margin = check_positive_int(margin, "margin", minimum=0, maximum=MAX_MARGIN)

    def _prepare(self, images: np.ndarray) -> np.ndarray:
        return images * np.float32(255.0)

    def _flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        import cv2

        flags = cv2.OPTFLOW_FARNEBACK_GAUSSIAN if self.gaussian else 0
        out = np.empty((*prev.shape, 2), dtype=np.float32)
        m = self.margin
        if m == 0:
            pads = np.zeros(prev.shape[0], dtype=bool)
        elif min(prev.shape[1:]) < SMALL_IMAGE:
            pads = np.ones(prev.shape[0], dtype=bool)
        else:
            pads = np.maximum(_border_max(prev), _border_max(curr)) >= BORDER_LEVEL
        for i, pad in enumerate(pads.tolist()):
            a, b = prev[i], curr[i]
            if pad:
                a, b = np.pad(a, m, mode="edge"), np.pad(b, m, mode="edge")
            if pad:
                f = cv2.calcOpticalFlowFarneback(
                    a, b, None, self.pyr_scale, self.levels, self.winsize,
                    self.iterations, self.poly_n, self.poly_sigma, flags)
                out[i] = f[m:-m, m:-m]
            else:  # written in place: no per-pair copy
                cv2.calcOpticalFlowFarneback(
                    a, b, out[i], self.pyr_scale, self.levels, self.winsize,
                    self.iterations, self.poly_n, self.poly_sigma, flags)
        return out


#: Image side below which Farnebäck pairs are always padded (border artefacts).
SMALL_IMAGE = 24


#: Border pressure (in 0..255 units) from which a pair is padded; fainter than
#: this, OpenCV's regularised solve already returns ~0 (checked in the tests).
BORDER_LEVEL = 0.25


def _border_max(images: np.ndarray) -> np.ndarray:
    """Largest value on each image's outer rows and columns: ``(N, h, w)`` → ``(N,)``."""
    return np.maximum(np.maximum(images[:, 0].max(1), images[:, -1].max(1)),
                      np.maximum(images[:, :, 0].max(1), images[:, :, -1].max(1)))
