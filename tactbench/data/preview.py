"""Preview strips: one sample of a dataset as a picture, for a quick look by eye.

:func:`preview_strip` gives a :class:`Preview` whose ``image`` is float32 ``(H, W, 3)``
RGB in [0, 1]:

- with a layout: the sample's tactile images (``pixel_mm``, ``method`` as in
  :class:`~tactbench.data.imaging.Imager`), or an encoder's channels as R, G, B, side by
  side left to right with 2-pixel white gaps, each frame enlarged by a whole factor
  to at least 96 pixels a side (:func:`tile`);
- without a layout: the normalised taxel values over time, frames down and taxels
  across, each frame an 8-pixel band (:func:`taxel_bands`).

Pressure is drawn with matplotlib's ``inferno`` colour map; :func:`write_png` saves the
picture. ``tactbench data preview`` is this module plus option parsing.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from tactbench.budget import check_budget
from tactbench.contracts import ENCODER
from tactbench.data.imaging import image_shape
from tactbench.errors import InputError, check_positive_int, check_shape
from tactbench.integrity import special_file_problem
from tactbench.paths import atomic_write_bytes

#: Colour map for pressure in [0, 1].
COLORMAP = "inferno"
#: Frames are enlarged (by a whole factor) to at least this many pixels a side.
MIN_SIDE_PX = 96
#: White pixels between frames.
GAP_PX = 2
#: Rows per frame in the taxel view.
BAND_PX = 8


@dataclass(frozen=True)
class Preview:
    """A preview picture and what it shows.

    ``image``: float32 ``(H, W, 3)`` in [0, 1]; ``frames``: frames shown;
    ``frame_shape``: ``(h, w)`` pixels of one tactile image before enlarging, or
    ``None`` for the taxel view; ``taxels``: taxels of the sample.
    """

    image: np.ndarray
    frames: int
    frame_shape: tuple[int, int] | None
    taxels: int


def preview_strip(dataset: Any, index: int, *, encoder: Any = None, pixel_mm: float = 4.0,
                  method: str = "linear", max_frames: int = 16) -> Preview:
    """The preview of sample ``index`` of ``dataset`` (see the module docstring).

    ``encoder`` is a built encoder (its ``ranges`` scale each channel to [0, 1]); it
    needs tactile images, so a dataset without a layout refuses it. At most
    ``max_frames`` frames are shown, from the first; the taxel view shows all.
    """
    index = check_positive_int(index, "sample", minimum=0)
    max_frames = check_positive_int(max_frames, "max_frames")
    if index >= len(dataset):
        raise InputError(f"sample {index} is out of range: dataset {dataset.name!r} has "
                         f"{len(dataset)} samples")
    raw = dataset[index].recording.values
    if dataset.layout is None:
        if encoder is not None:
            raise InputError(f"dataset {dataset.name!r} has no taxel layout, so it has no "
                             f"images for an encoder; without one the preview shows its "
                             f"taxel values")
        vectors = np.nan_to_num(dataset.normalise(raw), nan=0.0)
        return Preview(taxel_bands(vectors), int(vectors.shape[0]), None, int(raw.shape[1]))

    h, w = image_shape(dataset.layout, pixel_mm)
    t = int(raw.shape[0])
    c = len(tuple(ENCODER.get(encoder, "channels"))) if encoder is not None else 0
    # the images, their encoding, and the RGB strip of the frames shown
    check_budget(4 * t * h * w * (1 + c) + 12 * min(t, max_frames) * h * w * max(c, 1),
                 f"previewing sample {index} ({t} frames of {h}×{w} px at {pixel_mm:g} mm)")
    seq = dataset.imager(pixel_mm, method).apply(dataset.normalise(raw))
    np.clip(seq, 0.0, 1.0, out=seq)
    if encoder is None:
        frames = colorize(seq[:max_frames])
    else:  # the whole sequence: an encoder may look at earlier frames
        encoded = np.asarray(encoder.encode(seq))
        frames = to_rgb(encoded[:max_frames], ENCODER.get(encoder, "ranges"))
    return Preview(tile(frames), int(frames.shape[0]), tuple(seq.shape[1:]),
                   int(raw.shape[1]))


def colorize(values: np.ndarray) -> np.ndarray:
    """Pressure in [0, 1], any shape ``S`` → float32 RGB ``S + (3,)`` (:data:`COLORMAP`)."""
    from matplotlib import colormaps

    return colormaps[COLORMAP](np.asarray(values))[..., :3].astype(np.float32)


def to_rgb(encoded: np.ndarray, ranges: Sequence[tuple[float, float]] = ()) -> np.ndarray:
    """Encoder output ``(T, C, H, W)`` → float32 ``(T, H, W, 3)`` in [0, 1].

    Channel ``k`` is scaled from ``ranges[k] = (low, high)`` (``(0, 1)`` when the
    encoder declares none) to [0, 1]; one channel is grey, otherwise the first three
    are R, G, B (a missing third stays 0).
    """
    check_shape(encoded, "T C H W", "encoded frames", dtype_kind="fiu")
    t, c, h, w = encoded.shape
    ranges = list(ranges) or [(0.0, 1.0)] * c

    def scaled(k: int) -> np.ndarray:
        lo, hi = ranges[k]
        return np.clip((encoded[:, k] - lo) / ((hi - lo) or 1.0), 0.0, 1.0)

    if c == 1:
        return np.repeat(scaled(0)[..., None], 3, axis=-1).astype(np.float32)
    rgb = np.zeros((t, h, w, 3), dtype=np.float32)
    for k in range(min(c, 3)):
        rgb[..., k] = scaled(k)
    return rgb


def tile(frames: np.ndarray, *, min_side: int = MIN_SIDE_PX, gap: int = GAP_PX) -> np.ndarray:
    """RGB frames ``(T, h, w, 3)`` side by side → float32 ``(s·h, T·(s·w + gap) − gap, 3)``.

    ``s`` is the whole enlargement that brings the longer side to about ``min_side``
    pixels (at least 1); the gaps are white.
    """
    check_shape(frames, "T h w rgb", "frames", rgb=3)
    t, h, w, _ = frames.shape
    scale = max(1, int(round(min_side / max(h, w))))
    if scale > 1:
        frames = frames.repeat(scale, axis=1).repeat(scale, axis=2)
        h, w = h * scale, w * scale
    strip = np.ones((h, t * (w + gap) - gap, 3), dtype=np.float32)
    for k in range(t):
        strip[:, k * (w + gap):k * (w + gap) + w] = frames[k]
    return strip


def taxel_bands(vectors: np.ndarray, *, band: int = BAND_PX) -> np.ndarray:
    """Taxel values ``(T, N)`` in [0, 1] → float32 RGB ``(band·T, N, 3)``: frame ``t`` is
    rows ``band·t`` to ``band·(t+1)``, taxel ``n`` is column ``n``."""
    check_shape(vectors, "T N", "taxel values", dtype_kind="fiu")
    return np.repeat(colorize(vectors), band, axis=0)


def write_png(path: str | Path, image: np.ndarray) -> None:
    """Save an RGB picture ``(H, W, 3)`` in [0, 1] as a PNG file (replaced atomically)."""
    from matplotlib.image import imsave


    check_shape(image, "H W rgb", "image", rgb=3)
    buf = io.BytesIO()
    imsave(buf, np.clip(image, 0.0, 1.0), format="png", metadata={"Software": PNG_MARK})
    atomic_write_bytes(path, buf.getvalue())


#: The PNG text chunk that marks a picture tactbench wrote (it may replace those only).
PNG_MARK = "tactbench"


def written_by_tactbench(path: str | Path) -> bool:
    """Whether ``path`` is a PNG file :func:`write_png` wrote (its Software text chunk)."""
    if special_file_problem(path) is not None:  # a FIFO would block: not ours
        return False
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    return head.startswith(b"\x89PNG") and b"tEXtSoftware\x00" + PNG_MARK.encode() in head
