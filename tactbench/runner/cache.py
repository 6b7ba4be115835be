"""Encoded datasets on disk, so that each encoding is computed once across cells and runs.

A cache entry is keyed by the dataset's content hash, the imaging identity (vectors, or
images at a pixel size and method), the encoder's canonical spec and version, and the
storage precision (left out of the key for ``float32``, so entries made before
precisions existed keep their keys). The cache root is ``$TACTBENCH_CACHE/encodings``
(see :func:`tactbench.paths.cache_dir`).

Writing streams (:func:`ensure_encodings`): the dataset is imaged and encoded a chunk
of samples at a time (:data:`CHUNK_BYTES` of images), every chunk appended to the
entry's ``frames.npy`` as soon as it is encoded, so the memory of encoding is a few
chunks whatever the dataset's size. The file is written front to back with plain
writes after a ``.npy`` header for the known total shape, never through a writable
memory map (its dirty pages would count as the process's resident memory).

Reading (:func:`load_encoding`) gives :class:`StoredSequence` objects: a sample's frames
read from the file on demand (``os.preadv`` into a fresh array) and turned back into
float32; nothing is memory-mapped, so reading an entry sequence by sequence keeps the
process's resident memory at one sequence.

Storage precision (:data:`~tactbench.profiles.PRECISIONS`): ``float32`` stores the
encoder's output exactly; ``float16`` rounds it (relative error ≤ 2⁻¹¹ ≈ 4.9e-4);
``uint8`` maps each channel linearly from the range its encoder declares
(``ENCODER.get(enc, "ranges")``, (0, 1) when it declares none) onto 0..255 with
rounding, clipping values outside the range: the error is at most half a quantum,
``(high - low) / 510``, inside the range. ``meta.json`` records ``precision``,
``dtype`` and per-channel ``scale`` and ``offset`` (value = stored · scale + offset).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Sequence

from tactbench.errors import InputError, check_choice
from tactbench.paths import atomic_folder, cache_dir
from tactbench.runner.planning import Cell, Plan, digest, imaging_identity, storage_identity
from tactbench.runner.system import now, peak_rss_mb

if TYPE_CHECKING:
    import numpy as np

    from tactbench.ui import Progress

#: Images per chunk when streaming a dataset into the cache, bytes (float32 images). The
#: encodings of a chunk are ``C`` times that per encoder; about three chunks are alive
#: at once (one being imaged, one being encoded, one being written).
CHUNK_BYTES = 16 * 2 ** 20

#: Version of the entry format: 2 added precision, scale and offset (an entry without
#: them is float32, as version 1 wrote them).
FORMAT = 2


# ---------------------------------------------------------------------- precision


class Storage:
    """How an entry's values are stored: a precision and, per channel, scale and offset.

    A stored value ``q`` means ``q · scale + offset`` (float32). ``scale``/``offset``
    hold one number per channel (one for taxel vectors ``(T, N)``, which are one
    channel); they are 1 and 0 for the float precisions.
    """

    def __init__(self, precision: str, scale: Sequence[float], offset: Sequence[float]):
        import numpy as np

        from tactbench.profiles import PRECISIONS

        self.precision = check_choice(precision, "precision", PRECISIONS)
        self.dtype = np.dtype(precision)
        self.scale = np.asarray(scale, dtype=np.float32)
        self.offset = np.asarray(offset, dtype=np.float32)

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
        """The storage ``meta.json`` describes (float32 for an entry of format 1)."""
        precision = meta.get("precision", "float32")
        return cls(precision, meta.get("scale", [1.0] * n_channels),
                   meta.get("offset", [0.0] * n_channels))

    def describe(self) -> dict[str, Any]:
        """What ``meta.json`` records of the storage."""
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
            return np.ascontiguousarray(frames, dtype=np.float16)
        q = np.subtract(frames, self._per_channel(self.offset, frames.ndim),
                        dtype=np.float32)
        q /= self._per_channel(self.scale, frames.ndim)
        np.rint(q, out=q)
        np.clip(q, 0.0, 255.0, out=q)
        np.nan_to_num(q, copy=False, nan=0.0)
        return q.astype(np.uint8)

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


# ------------------------------------------------------------------------ writing


class EntryWriter:
    """Writes one entry's ``frames.npy`` front to back, one sequence at a time.

    The header states the total shape ``(ΣT, *frame_shape)`` up front; :meth:`append`
    stores each sequence (in sample order) with plain file writes. :attr:`meta` is
    written as ``meta.json`` when the entry is complete: add to it while writing.
    """

    def __init__(self, folder: Path, lengths: Sequence[int], frame_shape: Sequence[int],
                 storage: Storage) -> None:
        import numpy as np

        self.lengths = [int(n) for n in lengths]
        self.frame_shape = tuple(int(n) for n in frame_shape)
        self.storage = storage
        self.meta: dict[str, Any] = {}
        self._folder = folder
        self._done = 0
        self._fh = open(folder / "frames.npy", "wb")
        header = {"descr": np.lib.format.dtype_to_descr(storage.dtype),
                  "fortran_order": False, "shape": (sum(self.lengths), *self.frame_shape)}
        np.lib.format.write_array_header_1_0(self._fh, header)

    def append(self, sequence: Any) -> None:
        """Store the next sample's frames, float ``(T_i, *frame_shape)``."""
        i = self._done
        if i >= len(self.lengths):
            raise InputError(f"entry holds {len(self.lengths)} sequences; got one more")
        expected = (self.lengths[i], *self.frame_shape)
        if tuple(sequence.shape) != expected:
            raise InputError(f"sequence {i} has shape {tuple(sequence.shape)}, expected "
                             f"{expected}")
        self._fh.write(self.storage.encode(sequence).reshape(-1).view("u1"))
        self._done += 1

    def discard(self) -> None:
        """Stop writing (the entry's folder is then removed by its caller)."""
        self._fh.close()

    def close(self) -> None:
        """Finish the files; raises when a sequence is missing."""
        import numpy as np

        self._fh.close()
        if self._done != len(self.lengths):
            raise InputError(f"entry got {self._done} of its {len(self.lengths)} sequences")
        offsets = np.concatenate([[0], np.cumsum(self.lengths)]).astype(np.int64)
        np.save(self._folder / "offsets.npy", offsets)
        n_frames = int(offsets[-1])
        meta = {**self.meta, "format": FORMAT, **self.storage.describe(),
                "n_frames": n_frames, "frames": n_frames,
                "frame_shape": list(self.frame_shape), "created": now()}
        (self._folder / "meta.json").write_text(json.dumps(meta, indent=2))


class EncodingCache:
    """Encoded datasets on disk: one folder per (dataset, imaging, encoder, version,
    precision).

    A folder holds ``frames.npy`` (all frames stacked, ``(ΣT, C, H, W)`` or ``(ΣT, N)``
    in the entry's storage dtype), ``offsets.npy`` (int64 ``(n + 1,)``: sample i is
    ``frames[o[i]:o[i+1]]``) and ``meta.json``. It is written with :func:`atomic_folder`,
    so a folder that exists is complete.
    """

    def __init__(self, root: str | Path | None = None) -> None:
        self.root = Path(root) if root is not None else cache_dir("encodings")
        self.root.mkdir(parents=True, exist_ok=True)

    def key(self, dataset_hash: str, imaging: dict[str, Any], encoder: str,
            version: str, precision: str = "float32") -> str:
        return digest({"dataset": dataset_hash, "imaging": imaging, "encoder": encoder,
                       "version": version, **storage_identity(precision)}, 24)

    def path(self, key: str) -> Path:
        return self.root / key

    def has(self, key: str) -> bool:
        return (self.path(key) / "meta.json").is_file()

    @contextlib.contextmanager
    def entry(self, key: str, lengths: Sequence[int], frame_shape: Sequence[int],
              storage: Storage) -> Iterator[EntryWriter]:
        """Write the entry ``key`` sequence by sequence: the block gets an
        :class:`EntryWriter`; the entry appears, complete, when the block ends without
        an error (and not at all otherwise)."""
        with atomic_folder(self.path(key)) as tmp:
            writer = EntryWriter(tmp, lengths, frame_shape, storage)
            try:
                yield writer
            except BaseException:
                writer.discard()
                raise
            writer.close()

    def write(self, key: str, sequences: Sequence[Any], meta: dict[str, Any], *,
              precision: str = "float32", ranges: Sequence[Sequence[float]] = ()) -> Path:
        """Store ``sequences`` (each float ``(T, ...)``, same trailing shape) under ``key``
        at ``precision`` (``ranges``: per channel, for uint8; see :class:`Storage`)."""
        frame_shape = tuple(sequences[0].shape[1:])
        channels = frame_shape[0] if len(frame_shape) == 3 else 1
        with self.entry(key, [len(s) for s in sequences], frame_shape,
                        Storage.for_channels(precision, channels, ranges)) as writer:
            writer.meta.update(meta)
            for seq in sequences:
                writer.append(seq)
        return self.path(key)

    def entries(self) -> list[dict[str, Any]]:
        """``meta.json`` of every entry, with its ``key``, size in ``bytes`` and
        ``precision`` (float32 for entries older than precisions)."""
        out = []
        for meta_path in sorted(self.root.glob("*/meta.json")):
            meta = json.loads(meta_path.read_text())
            size = sum(f.stat().st_size for f in meta_path.parent.iterdir())
            out.append({"key": meta_path.parent.name, "bytes": size,
                        "precision": "float32", **meta})
        return out

    def clear(self) -> int:
        """Delete every entry; returns how many."""
        n = 0
        for child in self.root.iterdir():
            if child.is_dir():
                shutil.rmtree(child)
                n += 1
        return n


# ------------------------------------------------------------------------ reading


class EntryFile:
    """An entry's ``frames.npy``, read by frame range; safe to share between threads
    and to pickle (the file is opened again, lazily, where it is unpickled)."""

    def __init__(self, path: str | Path, storage: Storage) -> None:
        import numpy as np

        self.path = str(path)
        self.storage = storage
        fmt = np.lib.format
        with open(self.path, "rb") as fh:
            version = fmt.read_magic(fh)
            read_header = fmt.read_array_header_1_0 if version == (1, 0) \
                else fmt.read_array_header_2_0
            shape, fortran, dtype = read_header(fh)
            self.data_offset = fh.tell()
        if fortran or dtype != storage.dtype:
            raise InputError(f"{self.path}: stored as {dtype}{' (Fortran order)' * fortran}"
                             f", but its meta.json says {storage.dtype}")
        self.shape = tuple(shape)
        self.frame_bytes = int(np.prod(self.shape[1:], dtype=np.int64)) * dtype.itemsize
        self._open()

    def _open(self) -> None:
        self._fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_BINARY", 0))
        self._lock = threading.Lock()  # only for systems without os.preadv

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k not in ("_fd", "_lock")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._open()

    def __del__(self) -> None:
        if getattr(self, "_fd", None) is not None:
            os.close(self._fd)

    def read(self, start: int, stop: int) -> "np.ndarray":
        """Frames ``start:stop`` as float32 ``(stop - start, *frame_shape)``, a fresh array."""
        import numpy as np

        stored = np.empty((max(0, stop - start), *self.shape[1:]), dtype=self.storage.dtype)
        buffer = memoryview(stored.reshape(-1).view(np.uint8))
        position = self.data_offset + start * self.frame_bytes
        got = 0
        while got < len(buffer):
            if hasattr(os, "preadv"):  # no shared file position: threads read at once
                n = os.preadv(self._fd, [buffer[got:]], position + got)
            else:
                with self._lock:
                    os.lseek(self._fd, position + got, os.SEEK_SET)
                    n = os.readv(self._fd, [buffer[got:]])
            if n == 0:
                raise InputError(f"{self.path} is shorter than its header says; delete the "
                                 f"entry (tactbench cache clear) to recompute it")
            got += n
        return self.storage.decode(stored)


class StoredSequence:
    """One sample's frames in a cache entry, read from disk when asked for.

    Behaves as a read-only float32 array ``(T, C, H, W)`` or ``(T, N)`` where the runner
    needs one: ``shape``, ``dtype``, ``ndim``, ``len``; ``s[a:b]`` (any index whose
    first item picks frames) reads just those frames; ``np.asarray(s)`` reads all.
    Every read returns a fresh, writable float32 array, already dequantized.
    """

    __slots__ = ("_file", "_start", "shape")

    def __init__(self, file: EntryFile, start: int, stop: int) -> None:
        self._file = file
        self._start = int(start)
        self.shape: tuple[int, ...] = (int(stop) - int(start), *file.shape[1:])

    @property
    def dtype(self) -> "np.dtype":
        import numpy as np

        return np.dtype(np.float32)

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        import math

        return math.prod(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return (f"StoredSequence({self.shape}, {self._file.storage.precision} in "
                f"{self._file.path})")

    def _read(self, start: int, stop: int) -> "np.ndarray":
        return self._file.read(self._start + start, self._start + stop)

    def __getitem__(self, index: Any) -> "np.ndarray":
        import numpy as np

        head, rest = (index[0], index[1:]) if isinstance(index, tuple) and index \
            else (index, ())
        n = len(self)
        if head is Ellipsis:
            return self._read(0, n)[index]
        if isinstance(head, (int, np.integer)):
            i = int(head) + n if int(head) < 0 else int(head)
            if not 0 <= i < n:
                raise IndexError(f"frame {int(head)} of a sequence of {n} frames")
            frame = self._read(i, i + 1)[0]
            return frame[rest] if rest else frame
        if isinstance(head, slice) and head.step in (None, 1):
            start, stop, _ = head.indices(n)
            frames = self._read(start, max(start, stop))
        else:  # a stepped slice or an array of frame indices
            picked = np.arange(n)[head]
            if picked.size == 0:
                frames = self._read(0, 0)
            else:
                lo = int(picked.min())
                frames = self._read(lo, int(picked.max()) + 1)[picked - lo]
        return frames[(slice(None), *rest)] if rest else frames

    def __array__(self, dtype: Any = None, copy: Any = None) -> "np.ndarray":
        whole = self._read(0, len(self))
        return whole if dtype is None else whole.astype(dtype, copy=False)


_LOADED: dict[str, tuple[list[StoredSequence], dict[str, Any]]] = {}


def load_encoding(folder: str | Path) -> tuple[list[StoredSequence], dict[str, Any]]:
    """The cached sequences (read from disk on demand, float32) and metadata of an entry.

    Memoised per process: the cells of one process that read the same entry share its
    open file. Reading costs a ``preadv`` per slice plus, for float16 and uint8, one
    pass to float32; nothing stays resident after a read but the array it returns.
    """
    import numpy as np

    folder = str(folder)
    if folder not in _LOADED:
        meta = json.loads((Path(folder) / "meta.json").read_text())
        offsets = np.load(Path(folder) / "offsets.npy")
        frame_shape = meta.get("frame_shape")
        channels = frame_shape[0] if frame_shape and len(frame_shape) == 3 else 1
        file = EntryFile(Path(folder) / "frames.npy", Storage.from_meta(meta, channels))
        seqs = [StoredSequence(file, a, b) for a, b in zip(offsets[:-1], offsets[1:])]
        _LOADED[folder] = (seqs, meta)
    return _LOADED[folder]


# ----------------------------------------------------------------------- encoding


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


def ensure_encodings(plan_: Plan, cache: EncodingCache, pending: Sequence[Cell],
                     progress: "Progress | None" = None, *,
                     chunk_bytes: int = CHUNK_BYTES) -> dict[tuple[str, str], str]:
    """Make sure every (encoder, input kind) the pending cells need is cached.

    Returns ``(encoder spec, input kind) → cache folder`` for every pair the *plan*
    uses. Missing image encodings are made in one streaming pass over the dataset
    (each chunk of ``chunk_bytes`` of images is imaged once and encoded by every
    missing encoder); missing taxel-vector entries in another.
    """
    scene = plan_.scene
    precision = scene.resolved_precision()
    needed = {(c.encoder, plan_.input_kind[c.classifier]) for c in plan_.cells}
    pending_pairs = {(c.encoder, plan_.input_kind[c.classifier]) for c in pending}
    folders: dict[tuple[str, str], str] = {}
    missing: dict[str, dict[str, str]] = {"images": {}, "vectors": {}}  # kind → enc → key
    for enc, kind in sorted(needed):
        imaging = imaging_identity(scene, kind)
        key = cache.key(plan_.dataset_hash, imaging, enc, plan_.encoder_versions[enc],
                        precision)
        folders[(enc, kind)] = str(cache.path(key))
        if not cache.has(key) and (enc, kind) in pending_pairs:
            missing[kind][enc] = key
    if missing["vectors"]:
        _store_vectors(plan_, cache, missing["vectors"], precision, chunk_bytes)
    if missing["images"]:
        _encode_images(plan_, cache, missing["images"], precision, progress, chunk_bytes)
    return folders


def _common_meta(plan_: Plan, enc: str, kind: str) -> dict[str, Any]:
    from tactbench.contracts import ENCODER

    return {"encoder": enc, "encoder_version": plan_.encoder_versions[enc],
            "channels": list(ENCODER.get(plan_.encoders[enc], "channels")),
            "imaging": imaging_identity(plan_.scene, kind),
            "dataset": plan_.dataset.name, "dataset_hash": plan_.dataset_hash}


def _store_vectors(plan_: Plan, cache: EncodingCache, keys: dict[str, str],
                   precision: str, chunk_bytes: int) -> None:
    """The taxel-vector entries: no imaging and no encoder (raw passes vectors through;
    planning refuses any other encoder on vectors). One channel, in [0, 1]."""
    from tactbench.contracts import ENCODER

    dataset = plan_.dataset
    lengths = dataset.lengths()
    for enc, key in keys.items():
        ranges = tuple(ENCODER.get(plan_.encoders[enc], "ranges"))[:1]
        storage = Storage.for_channels(precision, 1, ranges)
        t0 = time.perf_counter()
        with cache.entry(key, lengths, (dataset.n_taxels,), storage) as writer:
            for a, b in chunk_bounds(lengths, 4 * dataset.n_taxels, chunk_bytes):
                for vec in dataset.vectors(range(a, b)):
                    writer.append(vec)
            writer.meta.update({**_common_meta(plan_, enc, "vectors"),
                                "encode_seconds": 0.0, "encode_cpu_seconds": 0.0,
                                "imaging_seconds": 0.0, "workers": 1,
                                "wall_seconds": time.perf_counter() - t0,
                                "peak_rss_mb": peak_rss_mb()})


def _encode_images(plan_: Plan, cache: EncodingCache, keys: dict[str, str], precision: str,
                   progress: "Progress | None", chunk_bytes: int) -> None:
    """One streaming pass: image a chunk, encode it with every encoder of ``keys``,
    append each encoding to its entry; all entries appear together at the end."""
    from tactbench.contracts import ENCODER
    from tactbench.encoders.parallel import default_workers, encode_chunks

    scene, dataset = plan_.scene, plan_.dataset
    pixel_mm, method = scene.resolved_pixel_mm(), scene.imaging
    h, w = dataset.image_shape(pixel_mm, method)
    lengths = dataset.lengths()
    n = len(lengths)
    encoders = {enc: plan_.encoders[enc] for enc in keys}
    workers = default_workers()
    imaging_s = 0.0
    image_task = progress.add(f"tactile images at {pixel_mm:g} mm", total=n) \
        if progress else None
    bars = {enc: progress.callback(f"encode {enc}", total=n) for enc in keys} \
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

    cpu = dict.fromkeys(keys, 0.0)
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        writers = {}
        for enc, key in keys.items():
            channels = tuple(ENCODER.get(encoders[enc], "channels"))
            storage = Storage.for_channels(precision, len(channels),
                                           tuple(ENCODER.get(encoders[enc], "ranges")))
            writers[enc] = stack.enter_context(
                cache.entry(key, lengths, (len(channels), h, w), storage))
        stream = stack.enter_context(contextlib.closing(
            encode_chunks(encoders, images(), workers=workers, total=n, progress=report)))
        for chunk in stream:
            for enc, encoded in chunk.encoded.items():
                for i, seq in enumerate(encoded):
                    try:
                        writers[enc].append(seq)
                    except InputError as exc:
                        raise InputError(f"encoder '{enc}', sample {chunk.start + i}: "
                                         f"{exc}") from None
                cpu[enc] += chunk.cpu_seconds[enc]
        wall = time.perf_counter() - t0
        for enc, writer in writers.items():
            writer.meta.update({
                **_common_meta(plan_, enc, "images"),
                "imaging_seconds": imaging_s,
                # one core's CPU time over the workers: the wall time the encoding
                # alone takes on `workers` cores (cell rows: × workers / frames)
                "encode_seconds": cpu[enc] / workers,
                "encode_cpu_seconds": cpu[enc],
                "workers": workers,
                "wall_seconds": wall,  # imaging and every encoder of this pass
                "chunk_bytes": chunk_bytes,
                "peak_rss_mb": peak_rss_mb(),
            })
