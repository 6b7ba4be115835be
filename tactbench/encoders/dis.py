"""``dis``: OpenCV's Dense Inverse Search flow (fast, strong at large motion)."""

from __future__ import annotations

import numpy as np

from tactbench.encoders.flow import DEFAULT_MAX_FLOW, DEFAULT_MIN_MAGNITUDE, FlowEncoder
from tactbench.errors import check_choice, check_positive_int

PRESETS = {"ultrafast": 0, "fast": 1, "medium": 2}


class DIS(FlowEncoder):
    """Pressure, flow magnitude and direction from ``cv2.DISOpticalFlow``.

    ``preset`` is OpenCV's (``ultrafast``, ``fast``, ``medium``); ``patch_size``
    and ``variational_iterations`` override the preset's values when given.
    DIS works on 8-bit images, so frames are quantised to 256 levels (motion of
    features fainter than 1/255 is not seen). Images smaller than 16 px are
    edge-padded (OpenCV rejects them). Shared flow options: see
    :mod:`tactbench.encoders.flow`.
    """

    name = "dis"
    version = "1"
    min_size = 16

    image_sized = ("patch_size",)

    def __init__(self, *, preset: str = "medium", patch_size: int | None = None,
                 variational_iterations: int | None = None,
                 max_flow: float = DEFAULT_MAX_FLOW,
                 min_magnitude: float = DEFAULT_MIN_MAGNITUDE, downscale: int = 1) -> None:
        super().__init__(max_flow=max_flow, min_magnitude=min_magnitude, downscale=downscale)
        self.preset = check_choice(preset, "preset", list(PRESETS))
        self.patch_size = (None if patch_size is None
                           else check_positive_int(patch_size, "patch_size", minimum=2))
        self.variational_iterations = (
            None if variational_iterations is None
            else check_positive_int(variational_iterations, "variational_iterations", minimum=0,
                                    maximum=10_000))

    def _make(self):
        import cv2

        dis = cv2.DISOpticalFlow_create(PRESETS[self.preset])
        if self.patch_size is not None:
            dis.setPatchSize(self.patch_size)
            dis.setPatchStride(max(1, self.patch_size // 2))
        if self.variational_iterations is not None:
            dis.setVariationalRefinementIterations(self.variational_iterations)
        return dis

    def _prepare(self, images: np.ndarray) -> np.ndarray:
        return to_uint8(images)

    def _flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        dis = self._make()  # a fresh estimator: no state carried between sequences
        out = np.empty((*prev.shape, 2), dtype=np.float32)
        for i in range(prev.shape[0]):
            out[i] = dis.calc(prev[i], curr[i], None)
        return out


def to_uint8(images: np.ndarray) -> np.ndarray:
    """[0, 1] floats → uint8 0..255, rounded."""
    return np.rint(images * np.float32(255.0)).astype(np.uint8)
