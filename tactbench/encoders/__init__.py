"""Built-in encoders, registered through the same hook as third-party ones.

This module only *describes* encoders; each is imported when it is built.
The flow encoders share the conventions in :mod:`tactbench.encoders.flow`.
"""

from __future__ import annotations

from tactbench import hookimpl


@hookimpl
def register_encoders(register):
    register("raw", "tactbench.encoders.simple:Raw",
             summary="pressure image only (the study's baseline), 1 channel")
    register("frame-diff", "tactbench.encoders.simple:FrameDiff",
             summary="pressure + signed difference to the previous frame, 2 channels")
    register("farneback", "tactbench.encoders.farneback:Farneback",
             summary="pressure + Farnebäck flow magnitude and direction (the study's), 3 channels",
             requires=("cv2",))
    register("lucas-kanade", "tactbench.encoders.lucas_kanade:LucasKanade",
             summary="pressure + dense pyramidal Lucas–Kanade flow (OpenCV), 3 channels",
             requires=("cv2",))
    register("kornia-flow", "tactbench.encoders.kornia_flow:KorniaFlow",
             summary="pressure + batched coarse-to-fine LK flow in torch/kornia (CUDA if "
                     "available), 3 channels",
             requires=("torch", "kornia", "cv2"))
    register("dis", "tactbench.encoders.dis:DIS",
             summary="pressure + OpenCV DIS flow (fast, large motions), 3 channels",
             requires=("cv2",))
    register("tvl1", "tactbench.encoders.tvl1:TVL1",
             summary="pressure + OpenCV-contrib dual TV-L1 flow (accurate, slow), 3 channels",
             requires=("cv2",))
