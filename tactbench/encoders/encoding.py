"""Encoding a whole dataset: chunks of samples, every encoder on one pool of threads,
each encoding quantised and handed on as soon as it is made.

The pass streams: the dataset is imaged and encoded a chunk of samples at a time
(:data:`CHUNK_BYTES` of images), and each encoded sequence goes to its encoder's *sink*
(a callable taking float ``(T, ...)`` frames, in sample order) as soon as its chunk is
done, so the memory of encoding is a few chunks whatever the dataset's size. The
runner's cache (:mod:`tactbench.runner.execution.cache`) gives the sinks: the writers of its
entries.

Storage precision (:data:`~tactbench.profiles.PRECISIONS`, :class:`Storage`):
``float32`` keeps the encoder's output exactly; ``float16`` rounds it (relative error
≤ 2⁻¹¹ ≈ 4.9e-4); ``uint8`` maps each channel linearly from the range its encoder
declares (``ENCODER.get(enc, "ranges")``, (0, 1) when it declares none) onto 0..255
with rounding, clipping values outside the range: the error is at most half a quantum,
``(high - low) / 510``, inside the range. A value further outside is clipped to the
range's end (a negative reading of an encoder declaring no range, stored as 0): the
storage counts them (:attr:`Storage.clipped`), and the cache says how many, once per
encoder, in one warning line naming the encoder and the precision that keeps them; the
counts are kept in the entry, so a later run that reads it says the line again.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Iterator, Mapping, Sequence

from tactbench.contracts import ENCODER
from tactbench.encoders.parallel import default_workers, encode_chunks
from tactbench.errors import InputError, check_choice
from tactbench.profiles import PRECISIONS

if TYPE_CHECKING:
    import numpy as np

    from tactbench.ui import Progress

#: Images per chunk when streaming a dataset through its encoders, bytes (float32
#: images). The encodings of a chunk are ``C`` times that per encoder; about three chunks
#: are alive at once (one being imaged, one being encoded, one being stored).
CHUNK_BYTES = 16 * 2 ** 20

#: The largest finite float16; larger values would be stored as infinite.
F16_MAX = 65504.0

#: Where an encoded sequence goes: called once per sample, in sample order.
Sink = Callable[["np.ndarray"], None]


class Storage:
    """How encoded values are stored: a precision and, per channel, scale and offset.

    A stored value ``q`` means ``q · scale + offset`` (float32). ``scale``/``offset``
    hold one number per channel (one for taxel vectors ``(T, N)``, which are one
    channel); they are 1 and 0 for the float precisions.
    """

    def __init__(self, precision: str, scale: Sequence[float], offset: Sequence[float]):
        import numpy as np

        self.precision = check_choice(precision, "precision", PRECISIONS)
        self.dtype = np.dtype(precision)
        self.scale = np.asarray(scale, dtype=np.float32)
        self.offset = np.asarray(offset, dtype=np.float32)
        #: uint8: values stored so far, and those clipped by more than half a quantum
        #: (below the range, above it)
        self.values, self.clipped = 0, [0, 0]

    @classmethod
    def for_channels(cls, precision: str, n_channels: int,
                     ranges: Sequence[Sequence[float]] = ()) -> "Storage":
        """The storage of ``n_channels`` channels whose values lie in ``ranges``
        (``(low, high)`` per channel; empty: (0, 1) each). Only ``uint8`` uses them."""
        if precision != "uint8":
            return cls(precision, [1.0] * n_channels, [0.0] * n_channels)
        ranges = list(ranges) or [(0.0, 1.0)] * n_channels
        if len(ranges) != n_channels:
            raise InputError(f"{len(ranges)} value ranges for {n_channels} channels: "
                             f"uint8 storage needs one (low, high) per channel")
        scale = [(float(hi) - float(lo)) / 255.0 or 1.0 for lo, hi in ranges]
        return cls(precision, scale, [float(lo) for lo, _ in ranges])

    @classmethod
    def from_meta(cls, meta: dict[str, Any], n_channels: int) -> "Storage":
        """The storage a record (:meth:`describe`) names (float32 when it names none)."""
        precision = meta.get("precision", "float32")
        return cls(precision, meta.get("scale", [1.0] * n_channels),
                   meta.get("offset", [0.0] * n_channels))

    def describe(self) -> dict[str, Any]:
        """``precision``, ``dtype`` and per-channel ``scale`` and ``offset``, JSON-ready."""
        return {"precision": self.precision, "dtype": self.dtype.name,
                "scale": [float(x) for x in self.scale],
                "offset": [float(x) for x in self.offset]}

    def _per_channel(self, values: "np.ndarray", ndim: int) -> "np.ndarray":
        # (C,) → (1, C, 1, 1) against (T, C, H, W); one channel: a scalar
        return values.reshape(()) if values.size == 1 else \
            values.reshape((1, -1) + (1,) * (ndim - 2))

    def encode(self, frames: Any) -> "np.ndarray":
        """float ``(T, ...)`` → stored ``(T, ...)`` of :attr:`dtype`, C-contiguous."""
        import numpy as np

        frames = np.asarray(frames)
        if self.precision == "float32":
            return np.ascontiguousarray(frames, dtype=np.float32)
        if self.precision == "float16":
            finite = np.isfinite(frames)
            if (np.abs(frames, where=finite, out=np.zeros(frames.shape)) > F16_MAX).any():
                raise InputError(f"a value of {float(np.abs(frames[finite]).max()):.4g} is "
                                 f"beyond float16's {F16_MAX:g}: it would be stored as "
                                 f"infinite; store with --precision float32")
            return np.ascontiguousarray(frames, dtype=np.float16)
        q = np.subtract(frames, self._per_channel(self.offset, frames.ndim),
                        dtype=np.float32)
        q /= self._per_channel(self.scale, frames.ndim)
        np.rint(q, out=q)
        self.values += q.size
        self.clipped[0] += int(np.count_nonzero(q < 0.0))
        self.clipped[1] += int(np.count_nonzero(q > 255.0))
        np.clip(q, 0.0, 255.0, out=q)
        np.nan_to_num(q, copy=False, nan=0.0)
        return q.astype(np.uint8)

    def clipping(self, name: str) -> str | None:
        """One line saying how many of the values stored so far ``name`` (an encoder)
        gave outside the uint8 range and were clipped, or None when none were."""
        low, high = self.clipped
        if not low + high:
            return None
        span = ", ".join(f"[{o:g}, {o + 255 * c:g}]" for o, c in
                         zip(self.offset.ravel(), self.scale.ravel()))
        return (f"encoder '{name}': {low + high} of {self.values} values lay outside the "
                f"range uint8 storage maps onto 0..255 ({span}; the encoder's declared "
                f"ranges, or (0, 1) where it declares none) and were clipped to its ends "
                f"({low} below, {high} above); store with --precision float16 or float32 "
                f"to keep them")

    def decode(self, stored: "np.ndarray") -> "np.ndarray":
        """Stored ``(T, ...)`` → float32 ``(T, ...)`` (the array itself for float32)."""
        import numpy as np

        if self.precision == "float32":
            return stored
        if self.precision == "float16":
            return stored.astype(np.float32)
        out = np.multiply(stored, self._per_channel(self.scale, stored.ndim),
                          dtype=np.float32)
        out += self._per_channel(self.offset, stored.ndim)
        return out


def image_storage(encoder: Any, precision: str) -> Storage:
    """The storage of ``encoder``'s images: one scale and offset per channel."""
    return Storage.for_channels(precision, len(tuple(ENCODER.get(encoder, "channels"))),
                                tuple(ENCODER.get(encoder, "ranges")))


def vector_storage(encoder: Any, precision: str) -> Storage:
    """The storage of ``encoder``'s taxel vectors ``(T, C·N)``: one channel whose range
    spans every channel's."""
    ranges = tuple(ENCODER.get(encoder, "ranges"))
    if ranges:
        ranges = ((min(lo for lo, _ in ranges), max(hi for _, hi in ranges)),)
    return Storage.for_channels(precision, 1, ranges)


def vector_width(encoder: Any, n_taxels: int) -> int:
    """The width ``C·N`` of ``encoder``'s encoding of ``n_taxels``-taxel vectors."""
    return n_taxels * max(1, len(ENCODER.get(encoder, "channels")))


def chunk_bounds(lengths: Sequence[int], frame_bytes: int,
                 budget: int = CHUNK_BYTES) -> list[tuple[int, int]]:
    """Consecutive sample ranges ``(a, b)`` covering ``lengths`` (frames per sample),
    each holding at most ``budget`` bytes of ``frame_bytes``-byte frames, and at least
    one sample (a longer sample is a chunk of its own)."""
    bounds: list[tuple[int, int]] = []
    start, size = 0, 0
    for i, n in enumerate(lengths):
        nbytes = int(n) * int(frame_bytes)
        if i > start and size + nbytes > budget:
            bounds.append((start, i))
            start, size = i, 0
        size += nbytes
    if start < len(lengths):
        bounds.append((start, len(lengths)))
    return bounds


@dataclass
class PassTimes:
    """What an encoding pass took: seconds imaging, CPU seconds per encoder (summed over
    the workers), the workers, and the wall time of the whole pass."""

    imaging_seconds: float
    cpu_seconds: dict[str, float]
    workers: int
    wall_seconds: float


def encode_vectors(dataset: Any, name: str, encoder: Any, sink: Sink, *,
                   chunk_bytes: int = CHUNK_BYTES) -> float:
    """Encode every sample's taxel vectors with ``encoder``'s ``encode_vectors``
    (``(T, N)`` → ``(T, C·N)``, see :data:`~tactbench.contracts.ENCODER`) into ``sink``, a
    chunk of samples at a time; returns the seconds spent encoding. ``name`` (the
    encoder's spec) names it in messages."""
    encode = ENCODER.get(encoder, "encode_vectors")
    if encode is None:
        raise InputError(f"encoder '{name}' encodes only images, not taxel vectors")
    lengths = dataset.lengths()
    width = vector_width(encoder, dataset.n_taxels)
    seconds = 0.0
    for a, b in chunk_bounds(lengths, 4 * width, chunk_bytes):
        for vec in dataset.vectors(range(a, b)):
            t0 = time.perf_counter()
            vec = encode(vec)
            seconds += time.perf_counter() - t0
            sink(vec)  # the runner's sink checks it (tactbench.boundary.EncoderGuard)
    return seconds


def encode_images(dataset: Any, encoders: Mapping[str, Any], sinks: Mapping[str, Sink], *,
                  pixel_mm: float, method: str, progress: "Progress | None" = None,
                  chunk_bytes: int = CHUNK_BYTES) -> PassTimes:
    """One streaming pass over ``dataset``: image a chunk at ``pixel_mm`` / ``method``,
    encode it with every encoder of ``encoders`` (spec → encoder) on one pool of
    threads (:func:`~tactbench.encoders.parallel.encode_chunks`), hand each encoded
    sequence to the encoder's sink; ``progress`` shows a bar for the imaging and one per
    encoder."""
    lengths = dataset.lengths()
    n = len(lengths)
    h, w = dataset.image_shape(pixel_mm, method)
    workers = default_workers()
    imaging_s = 0.0
    image_task = progress.add(f"tactile images at {pixel_mm:g} mm", total=n) \
        if progress else None
    bars = {enc: progress.callback(f"encode {enc}", total=n) for enc in encoders} \
        if progress else {}

    def images() -> Iterator[list["np.ndarray"]]:
        nonlocal imaging_s
        for a, b in chunk_bounds(lengths, 4 * h * w, chunk_bytes):
            t0 = time.perf_counter()
            chunk = dataset.images(pixel_mm, method, indices=range(a, b))
            imaging_s += time.perf_counter() - t0
            if progress:
                progress.update(image_task, b)
            yield chunk

    def report(done: int, total: int | None, encoder: str) -> None:
        if bars.get(encoder):
            bars[encoder](done, total)

    cpu = dict.fromkeys(encoders, 0.0)
    t0 = time.perf_counter()
    with contextlib.closing(encode_chunks(encoders, images(), workers=workers, total=n,
                                          progress=report)) as stream:
        for chunk in stream:
            for enc, encoded in chunk.encoded.items():
                for i, seq in enumerate(encoded):
                    try:
                        sinks[enc](seq)
                    except InputError as exc:
                        raise InputError(f"encoder '{enc}', sample {chunk.start + i}: "
                                         f"{exc}") from None
                cpu[enc] += chunk.cpu_seconds[enc]
    return PassTimes(imaging_s, cpu, workers, time.perf_counter() - t0)
