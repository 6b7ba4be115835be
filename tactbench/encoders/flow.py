"""Conventions shared by every optical-flow encoder.

A flow encoder maps a pressure sequence float32 ``(T, H, W)`` in [0, 1] to
float32 ``(T, 3, H, W)`` with the channels

``pressure``
    ``I_k`` itself, in [0, 1].
``magnitude``
    ``|u_k| / max_flow`` clipped to [0, 1], where ``u_k`` is the dense flow from
    ``I_{k-1}`` to ``I_k`` in pixels per frame (of the *input* image, also when
    the flow is computed on a coarser grid) and ``max_flow`` is a fixed scale in
    pixels per frame (default :data:`DEFAULT_MAX_FLOW`). Faster motion saturates
    at 1. The scale is an option, so it is part of the encoder's cache key and
    of :meth:`FlowEncoder.metadata`.
``direction``
    the flow's angle ``atan2(u_y, u_x)`` in image coordinates (x to the right,
    y *down*), mapped from [0, 2π) to [0, 1): 0 = +x (right), 0.25 = +y (down),
    0.5 = −x (left), 0.75 = −y (up). Where ``|u_k| < min_magnitude`` (pixels
    per frame) the direction is set to 0: the angle of noise carries nothing.

The flow ``u_k`` is a *forward* flow on ``I_{k-1}``'s grid:
``I_k(x + u_k(x)) ≈ I_{k-1}(x)``, the convention of OpenCV's estimators.
``I_{-1}`` is all zeros, so frame 0's flow describes the step from an empty
skin to the first contact.

Options every flow encoder accepts:

``max_flow`` (float > 0, px/frame)
    the magnitude normalisation scale.
``min_magnitude`` (float ≥ 0, px/frame)
    below it the direction is 0.
``downscale`` (int ≥ 1)
    compute the flow on a grid ``downscale`` times coarser (area averaging),
    then upsample it bilinearly to the input size and multiply it by the size
    ratio so it stays in input pixels per frame. Tactile images are heavily
    oversampled (FACTS.md), so 2–4 costs little information and much less time.

Images smaller than a method's :attr:`FlowEncoder.min_size` are padded by edge
replication before the flow is computed and the flow is cropped back; a 1 × 1
image has no spatial structure and gets zero flow from every method.

A flow that comes back non-finite is an error (``FloatingPointError``), never
silently repaired: the stability suite (``tactbench stability``) looks for it.
"""

from __future__ import annotations

import inspect
import math
from typing import Any, ClassVar

import numpy as np

from tactbench.contracts import ENCODER
from tactbench.encoders.base import Encoder
from tactbench.errors import InputError, check_at_most, check_positive_float, check_positive_int

#: Default magnitude normalisation: pixels per frame mapped to magnitude 1.
DEFAULT_MAX_FLOW = 8.0
#: Default threshold (pixels per frame) below which the direction is set to 0.
DEFAULT_MIN_MAGNITUDE = 0.05

FLOW_CHANNELS = ("pressure", "magnitude", "direction")
FLOW_RANGES = ((0.0, 1.0), (0.0, 1.0), (0.0, 1.0))


def flow_to_channels(seq: np.ndarray, flow: np.ndarray, *, max_flow: float,
                     min_magnitude: float) -> np.ndarray:
    """Stack pressure, normalised magnitude and direction: ``(T, 3, H, W)`` float32.

    Parameters
    ----------
    seq : float32 ``(T, H, W)`` in [0, 1]
    flow : float ``(T, H, W, 2)``, ``(u_x, u_y)`` in pixels per frame
    max_flow, min_magnitude : pixels per frame (see the module docstring)
    """
    t, h, w = seq.shape
    out = np.empty((t, 3, h, w), dtype=np.float32)
    out[:, 0] = seq
    polar_into(flow, out, max_flow=max_flow, min_magnitude=min_magnitude)
    return out


def polar_into(flow: np.ndarray, out: np.ndarray, *, max_flow: float,
               min_magnitude: float) -> None:
    """Write magnitude and direction of ``flow`` ``(T, H, W, 2)`` into ``out[:, 1:3]``."""
    import cv2

    t, h, w = flow.shape[:3]
    scale = np.float32(1.0 / max_flow)
    turn = np.float32(1.0 / (2.0 * math.pi))
    flow = np.asarray(flow, dtype=np.float32)
    # In chunks of frames of ~256 k pixels: few calls on small images, and no
    # full-size temporaries on large ones (on a VM each fresh large array costs
    # page faults, ~5 % of a Farnebäck encode at 357 × 334). OpenCV's polar
    # conversion is SIMD, ~8× faster than numpy's hypot/arctan2; its angles are
    # within 3e-5 turn of arctan2.
    step = max(1, CHUNK_PIXELS // (h * w))
    for k0 in range(0, t, step):
        k1 = min(t, k0 + step)
        n = k1 - k0
        fx = np.ascontiguousarray(flow[k0:k1, ..., 0]).reshape(n * h, w)
        fy = np.ascontiguousarray(flow[k0:k1, ..., 1]).reshape(n * h, w)
        # Flow components below 1e-9 px/frame are zero in all but name; left as
        # they are, their squares are float32 denormals, which made the polar
        # conversion ~6× slower on real Farnebäck output.
        fx[np.abs(fx) < TINY_FLOW] = 0.0
        fy[np.abs(fy) < TINY_FLOW] = 0.0
        mag, angle = cv2.cartToPolar(fx, fy)  # angle in [0, 2π]
        mag, angle = mag.reshape(n, h, w), angle.reshape(n, h, w)
        magnitude, direction = out[k0:k1, 1], out[k0:k1, 2]
        np.multiply(mag, scale, out=magnitude)
        np.minimum(magnitude, np.float32(1.0), out=magnitude)
        np.multiply(angle, turn, out=direction)
        # An angle of (or rounding to) 2π is the same direction as 0.
        still = mag < min_magnitude
        still |= direction >= 1.0
        direction[still] = 0.0


#: Pixels per chunk of frame pairs in :meth:`FlowEncoder.encode` for per-pair methods.
CACHE_PIXELS = 1 << 15
#: Flow components smaller than this (px/frame) are set to 0 before the polar conversion.
TINY_FLOW = 1e-9
#: Pixels per chunk in :func:`flow_to_channels`.
CHUNK_PIXELS = 1 << 18


def resize_stack(images: np.ndarray, size: tuple[int, int], *, area: bool) -> np.ndarray:
    """Resize every image of ``(N, h, w[, 2])`` to ``size = (H, W)``.

    ``area=True`` averages (for shrinking), otherwise bilinear (for enlarging).
    """
    import cv2

    hh, ww = size
    if images.shape[1:3] == (hh, ww):
        return images
    interp = cv2.INTER_AREA if area else cv2.INTER_LINEAR
    out = np.empty((images.shape[0], hh, ww, *images.shape[3:]), dtype=images.dtype)
    for i, img in enumerate(images):
        res = cv2.resize(img, (ww, hh), interpolation=interp)
        out[i] = res.reshape(out.shape[1:])
    return out


class FlowEncoder(Encoder):
    """Base for dense-flow encoders: pressure, magnitude, direction (3 channels).

    Subclasses write :meth:`_flow` for a batch of frame pairs at the working
    resolution and call ``super().__init__(max_flow=..., min_magnitude=...,
    downscale=...)``; everything in the module docstring is done here.
    """

    channels = FLOW_CHANNELS
    ranges = FLOW_RANGES
    #: Images with a side below this are edge-padded to it before :meth:`_flow`.
    min_size: ClassVar[int] = 1
    #: True for methods that process many pairs in one call (see :meth:`_pairs_per_call`).
    batched: ClassVar[bool] = False
    #: Options that are sizes in pixels of the working image (windows, patches, filter
    #: sizes): one larger than the image is an error naming both, checked at planning
    #: (:meth:`check_image_size`) and before each encoding; the method would otherwise
    #: compute for minutes over padding.
    image_sized: ClassVar[tuple[str, ...]] = ()

    def __init__(self, *, max_flow: float = DEFAULT_MAX_FLOW,
                 min_magnitude: float = DEFAULT_MIN_MAGNITUDE, downscale: int = 1) -> None:
        self.max_flow = check_positive_float(max_flow, "max_flow (px/frame)")
        self.min_magnitude = check_positive_float(min_magnitude, "min_magnitude (px/frame)",
                                                  allow_zero=True)
        self.downscale = check_positive_int(downscale, "downscale")

    # ------------------------------------------------------------------ public

    def flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        """Dense forward flow for each pair: float32 ``(N, H, W, 2)`` in px/frame.

        ``prev`` and ``curr`` are float32 ``(N, H, W)`` in [0, 1] (already
        checked; :meth:`encode` does that). ``flow[i, y, x] = (u_x, u_y)`` with
        ``curr[i](x + u) ≈ prev[i](x)``.
        """
        prev, curr = np.asarray(prev), np.asarray(curr)
        if prev.shape != curr.shape or prev.ndim != 3:
            raise InputError(f"prev and curr must both be (N, H, W); got {prev.shape} "
                             f"and {curr.shape}")
        if prev.shape[0] == 0:
            return np.zeros((*prev.shape, 2), dtype=np.float32)
        size = prev.shape[1:]
        self.check_image_size(*size)
        return self._finish(self._flow(self._to_grid(prev), self._to_grid(curr)), size)

    def metadata(self) -> dict[str, Any]:
        """What a reader of the encoded array needs: channels, ranges, scales, conventions."""
        return {
            **super().metadata(),
            "magnitude_scale_px_per_frame": self.max_flow,
            "direction": "atan2(u_y, u_x) in image coordinates (y down), [0, 2π) → [0, 1); "
                         f"0 where |u| < {self.min_magnitude} px/frame",
            "flow": "forward, from I_{k-1} to I_k, I_{-1} = 0",
        }

    def check_image_size(self, h: int, w: int) -> None:
        """Refuse an option of :attr:`image_sized` larger than an ``h × w`` image (at the
        working size, after ``downscale``, with any padding the method adds), naming
        both. Values up to the option's default are always accepted: the methods handle
        images smaller than their default windows."""
        hs, ws = self._grid_size((h, w))
        side = max(hs, ws, self.min_size) + 2 * int(getattr(self, "margin", 0) or 0)
        defaults = inspect.signature(type(self).__init__).parameters
        for name in self.image_sized:
            value = getattr(self, name, None)
            default = getattr(defaults.get(name), "default", None)
            limit = max(side, default if isinstance(default, (int, float)) else 0)
            if value is not None:
                where = f" at downscale {self.downscale}" if self.downscale > 1 else ""
                check_at_most(value, limit, f"{self.name or type(self).__name__} {name}",
                              f"the image ({hs}×{ws} px{where}); use at most {limit:g}")

    # ------------------------------------------------------------------ internals

    def _encode(self, seq: np.ndarray) -> np.ndarray:
        t, h, w = seq.shape
        self.check_image_size(h, w)
        grid = self._to_grid(np.concatenate([np.zeros_like(seq[:1]), seq]))
        out = np.empty((t, 3, h, w), dtype=np.float32)
        out[:, 0] = seq
        step = max(1, self._pairs_per_call(h, w) or t)
        for k0 in range(0, t, step):
            k1 = min(t, k0 + step)
            flow = self._finish(self._flow(grid[k0:k1], grid[k0 + 1:k1 + 1]), (h, w))
            polar_into(flow, out[k0:k1], max_flow=self.max_flow,
                       min_magnitude=self.min_magnitude)
        return out

    def _pairs_per_call(self, h: int, w: int) -> int | None:
        """Frame pairs :meth:`encode` hands to :meth:`_flow` at once (None: all).

        Methods that loop over pairs anyway get chunks of ~32 k pixels, so each
        chunk's flow is converted while it is still in the CPU cache (about 2
        points of Farnebäck's overhead); batched methods (:attr:`batched`, such
        as ``kornia-flow``) get the whole sequence.
        """
        return None if self.batched else max(1, CACHE_PIXELS // (h * w))

    def _grid_size(self, size: tuple[int, int]) -> tuple[int, int]:
        h, w = size
        return max(1, round(h / self.downscale)), max(1, round(w / self.downscale))

    def _to_grid(self, images: np.ndarray) -> np.ndarray:
        """Downscale, edge-pad to :attr:`min_size`, then :meth:`_prepare`."""
        hs, ws = self._grid_size(images.shape[1:])
        out = resize_stack(np.ascontiguousarray(images, dtype=np.float32), (hs, ws), area=True)
        ph, pw = max(0, self.min_size - hs), max(0, self.min_size - ws)
        if ph or pw:
            out = np.pad(out, ((0, 0), (0, ph), (0, pw)), mode="edge")
        return self._prepare(out)

    def _finish(self, flow: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Crop the padding, upsample to ``size`` (in input px/frame), check finiteness."""
        h, w = size
        hs, ws = self._grid_size(size)
        if h == 1 and w == 1:  # no spatial structure: no motion can be seen
            return np.zeros((flow.shape[0], 1, 1, 2), dtype=np.float32)
        f = np.asarray(flow, dtype=np.float32)[:, :hs, :ws]
        if (hs, ws) != (h, w):
            f = resize_stack(np.ascontiguousarray(f), (h, w), area=False)
            f[..., 0] *= w / ws
            f[..., 1] *= h / hs
        # One pass, no temporary: NaN and ±Inf propagate into the sum (flow values
        # are bounded by the image size, so a finite field cannot overflow it).
        if not np.isfinite(np.add.reduce(f, axis=None)):
            raise FloatingPointError(f"{self.name or type(self).__name__}: the flow "
                                     f"estimator returned non-finite values")
        return f

    def _prepare(self, images: np.ndarray) -> np.ndarray:
        """Convert ``(N, h, w)`` float32 [0, 1] frames to what :meth:`_flow` wants."""
        return images

    def _flow(self, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
        """Flow for prepared ``(N, h, w)`` pairs at the working size: ``(N, h, w, 2)``."""
        raise NotImplementedError


def is_flow_encoder(encoder: Any) -> bool:
    """Whether ``encoder`` is a dense-flow encoder, the one definition tactbench uses.

    A flow encoder has ``magnitude`` and ``direction`` channels, a public
    ``flow(prev, curr) → (N, H, W, 2)`` in px/frame, and the scales ``max_flow`` and
    ``min_magnitude`` that turn that flow into channels (:func:`flow_to_channels`).
    Every :class:`FlowEncoder` is one; a plugin is one when it has all of these.
    """
    if isinstance(encoder, FlowEncoder):
        return True
    channels = tuple(ENCODER.get(encoder, "channels"))
    return ("magnitude" in channels and "direction" in channels
            and callable(ENCODER.get(encoder, "flow"))
            and all(isinstance(ENCODER.get(encoder, a), (int, float))
                    for a in ("max_flow", "min_magnitude")))
