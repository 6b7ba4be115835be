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

Verification (:func:`check_entry`): ``meta.json`` also records what the entry is (its
key and the identity the key is the digest of, encoder, versions, shapes) and the sizes
and SHA-256 of ``frames.npy`` and ``offsets.npy`` (hashed while they are written), and
seals itself with ``meta_checksum``. Every open checks the cheap part (identity, sizes,
headers, offsets); the checksum of ``frames.npy`` is read once per process for each
version of the file. :func:`ensure_encodings` reports a damaged entry in one warning
line and encodes it again; :func:`load_encoding` raises :class:`CorruptArtefactError`.
Writers of one key race safely: the first complete folder renamed into place wins, the
others verify and use it; temporaries of dead writers are removed by the next run.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Sequence

from tactbench.errors import CorruptArtefactError, InputError, check_choice
from tactbench.paths import (
    Temporary,
    atomic_folder,
    cache_dir,
    discard,
    parse_temporary,
    remove_orphans,
    remove_path,
    temporaries,
)
from tactbench.runner.planning import Cell, Plan, digest, imaging_identity, storage_identity
from tactbench.runner.system import now, peak_rss_mb

if TYPE_CHECKING:
    import numpy as np

    from tactbench.ui import Progress

log = logging.getLogger("tactbench.runner.cache")

#: Images per chunk when streaming a dataset into the cache, bytes (float32 images). The
#: encodings of a chunk are ``C`` times that per encoder; about three chunks are alive
#: at once (one being imaged, one being encoded, one being written).
CHUNK_BYTES = 16 * 2 ** 20

#: Version of the entry format: 2 added precision, scale and offset; 3 added the entry's
#: key and identity, the sizes and checksums of its files and of ``meta.json`` itself.
#: Entries of another format are rebuilt.
FORMAT = 3


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


def _canonical(obj: Any) -> bytes:
    """The bytes a JSON document's checksum is taken of: sorted keys, no spaces."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()


def seal(meta: dict[str, Any]) -> dict[str, Any]:
    """``meta`` with ``meta_checksum``: the checksum of everything else in it."""
    from tactbench.integrity import hash_bytes

    body = {k: v for k, v in meta.items() if k != "meta_checksum"}
    return {**body, "meta_checksum": hash_bytes(_canonical(body))}


class EntryWriter:
    """Writes one entry's ``frames.npy`` front to back, one sequence at a time.

    The header states the total shape ``(ΣT, *frame_shape)`` up front; :meth:`append`
    stores each sequence (in sample order) with plain file writes, hashing the bytes as
    they are written (so the checksum costs no second read). :attr:`meta` is written as
    ``meta.json`` when the entry is complete: add to it while writing.
    """

    def __init__(self, folder: Path, lengths: Sequence[int], frame_shape: Sequence[int],
                 storage: Storage, key: str | None = None) -> None:
        import io

        import numpy as np

        from tactbench.integrity import new_hasher

        self.lengths = [int(n) for n in lengths]
        self.frame_shape = tuple(int(n) for n in frame_shape)
        self.storage = storage
        self.meta: dict[str, Any] = {}
        self.key = key if key is not None else folder.name
        self._folder = folder
        self._done = 0
        self._hash = new_hasher()
        self._bytes = 0
        self._fh = open(folder / "frames.npy", "wb")
        header = {"descr": np.lib.format.dtype_to_descr(storage.dtype),
                  "fortran_order": False, "shape": (sum(self.lengths), *self.frame_shape)}
        buffer = io.BytesIO()
        np.lib.format.write_array_header_1_0(buffer, header)
        self._write(buffer.getvalue())

    def _write(self, data: Any) -> None:
        self._hash.update(data)
        self._fh.write(data)
        self._bytes += memoryview(data).nbytes

    def append(self, sequence: Any) -> None:
        """Store the next sample's frames, float ``(T_i, *frame_shape)``."""
        i = self._done
        if i >= len(self.lengths):
            raise InputError(f"entry holds {len(self.lengths)} sequences; got one more")
        expected = (self.lengths[i], *self.frame_shape)
        if tuple(sequence.shape) != expected:
            raise InputError(f"sequence {i} has shape {tuple(sequence.shape)}, expected "
                             f"{expected}")
        self._write(self.storage.encode(sequence).reshape(-1).view("u1"))
        self._done += 1

    def discard(self) -> None:
        """Stop writing (the entry's folder is then removed by its caller)."""
        self._fh.close()

    def close(self) -> None:
        """Finish the files; raises when a sequence is missing."""
        import io

        import numpy as np

        from tactbench import __version__
        from tactbench.integrity import ALGORITHM, hash_bytes

        self._fh.close()
        if self._done != len(self.lengths):
            raise InputError(f"entry got {self._done} of its {len(self.lengths)} sequences")
        offsets = np.concatenate([[0], np.cumsum(self.lengths)]).astype(np.int64)
        buffer = io.BytesIO()
        np.save(buffer, offsets)
        offsets_bytes = buffer.getvalue()
        (self._folder / "offsets.npy").write_bytes(offsets_bytes)
        n_frames = int(offsets[-1])
        meta = {**self.meta, "format": FORMAT, "key": self.key, "tactbench": __version__,
                **self.storage.describe(), "n_frames": n_frames, "frames": n_frames,
                "n_sequences": len(self.lengths), "frame_shape": list(self.frame_shape),
                "algorithm": ALGORITHM,
                "files": {"frames.npy": {"bytes": self._bytes,
                                         "checksum": self._hash.hexdigest()},
                          "offsets.npy": {"bytes": len(offsets_bytes),
                                          "checksum": hash_bytes(offsets_bytes)}},
                "created": now()}
        (self._folder / "meta.json").write_text(json.dumps(seal(meta), indent=2))


class EncodingCache:
    """Encoded datasets on disk: one folder per (dataset, imaging, encoder, version,
    precision).

    A folder holds ``frames.npy`` (all frames stacked, ``(ΣT, C, H, W)`` or ``(ΣT, N)``
    in the entry's storage dtype), ``offsets.npy`` (int64 ``(n + 1,)``: sample i is
    ``frames[o[i]:o[i+1]]``) and ``meta.json`` (what the entry is, and the sizes and
    checksums of both files: see :func:`verify_entry`). It is written with
    :func:`atomic_folder`, so a folder that exists was complete when it was renamed
    into place; whether it is still intact is what :meth:`verify` checks.
    """

    def __init__(self, root: str | Path | None = None) -> None:
        self.root = Path(root) if root is not None else cache_dir("encodings")
        self.root.mkdir(parents=True, exist_ok=True)

    @staticmethod
    def identity(dataset_hash: str, imaging: dict[str, Any], encoder: str, version: str,
                 precision: str = "float32") -> dict[str, Any]:
        """What decides an entry's content; its digest is the entry's key, and
        ``meta.json`` records it so that a reader can check the key against it."""
        return {"dataset": dataset_hash, "imaging": imaging, "encoder": encoder,
                "version": version, **storage_identity(precision)}

    def key(self, dataset_hash: str, imaging: dict[str, Any], encoder: str,
            version: str, precision: str = "float32") -> str:
        return digest(EncodingCache.identity(dataset_hash, imaging, encoder, version,
                                             precision), KEY_DIGITS)

    def path(self, key: str) -> Path:
        return self.root / key

    def has(self, key: str) -> bool:
        """Whether an entry folder of ``key`` is there (cheap; :meth:`verify` says
        whether it is intact)."""
        return (self.path(key) / "meta.json").is_file()

    def verify(self, key: str, *, full: bool = True) -> dict[str, Any]:
        """The entry's ``meta.json`` after :func:`verify_entry`; raises
        :class:`CorruptArtefactError` naming the entry and what is wrong."""
        return verify_entry(self.path(key), full=full)

    def discard(self, key: str) -> None:
        """Remove the entry ``key`` (a damaged one, so it can be written again)."""
        _forget(self.path(key))
        discard(self.path(key))

    def clean(self) -> list[Temporary]:
        """Remove the temporary folders whose writing process is gone; returns them."""
        return remove_orphans(self.root)

    @contextlib.contextmanager
    def entry(self, key: str, lengths: Sequence[int], frame_shape: Sequence[int],
              storage: Storage) -> Iterator[EntryWriter]:
        """Write the entry ``key`` sequence by sequence: the block gets an
        :class:`EntryWriter`; the entry appears, complete, when the block ends without
        an error (and not at all otherwise).

        When another process wrote the same key first, its entry is kept (ours is
        dropped) and verified here: a damaged winner raises
        :class:`CorruptArtefactError` (the next run rebuilds it).
        """
        with atomic_folder(self.path(key)) as tmp:
            writer = EntryWriter(tmp, lengths, frame_shape, storage, key=key)
            try:
                yield writer
            except BaseException:
                writer.discard()
                raise
            writer.close()
            ours = json.loads((tmp / "meta.json").read_text())["meta_checksum"]
        _forget(self.path(key))
        meta = json.loads((self.path(key) / "meta.json").read_text()) \
            if (self.path(key) / "meta.json").is_file() else {}
        if meta.get("meta_checksum") != ours:  # another process's entry: verify it
            self.verify(key)
        else:  # ours: its checksum was taken of the very bytes written, no need to reread
            _VERIFIED.add((str(self.path(key)), _signature(self.path(key))))

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
        """Every entry folder: its ``meta.json`` (as far as it is readable), ``key``,
        size in ``bytes``, ``precision`` and ``state``: ``"ok"``, or ``"damaged"`` with
        the ``problem`` (sizes, identity and offsets are checked; checksums are not,
        to keep listing cheap)."""
        out = []
        for folder in sorted(p for p in self.root.iterdir()
                             if p.is_dir() and not p.name.startswith(".")):
            size = sum(f.stat().st_size for f in folder.iterdir() if f.is_file())
            entry: dict[str, Any] = {"key": folder.name, "bytes": size,
                                     "precision": "float32"}
            try:
                entry.update(verify_entry(folder, full=False))
                entry["state"] = "ok"
            except CorruptArtefactError as exc:
                entry.update(_readable_meta(folder))
                entry.update({"state": "damaged", "problem": exc.problem})
            entry["key"], entry["bytes"] = folder.name, size
            out.append(entry)
        return out

    def temporaries(self) -> list[dict[str, Any]]:
        """Temporary folders beside the entries: ``name``, ``key`` (the entry it was
        going to be), ``pid``, ``state`` (``"orphaned"``: its process is gone, removed
        at the next run; ``"in progress"``; ``"other host"``) and ``bytes``."""
        out = []
        for t in temporaries(self.root):
            try:
                size = sum(f.stat().st_size for f in t.path.rglob("*") if f.is_file()) \
                    if t.path.is_dir() else t.path.stat().st_size
            except OSError:
                size = 0
            out.append({"name": t.path.name, "key": t.target, "pid": t.pid,
                        "state": t.state, "bytes": size})
        return out

    def clear(self) -> int:
        """Delete every entry and every orphaned temporary folder; returns how many.
        Temporaries of running writers (``"in progress"``) are left to them."""
        n = 0
        for child in self.root.iterdir():
            temp = parse_temporary(child)
            if temp is not None and temp.state != "orphaned":
                continue
            if child.is_dir() or temp is not None:
                _forget(child)
                remove_path(child)
                n += 1
        return n


# ------------------------------------------------------------------- verification

#: Hex digits of an entry's key.
KEY_DIGITS = 24
#: A ``.npy`` header longer than this is not one tactbench wrote (they are 128 bytes).
NPY_HEADER_MAX = 4096
#: ``meta.json`` larger than this is not one tactbench wrote.
META_MAX_BYTES = 1 << 20
#: ``(folder, signature of its files)`` whose checksums this process verified.
_VERIFIED: set[tuple[str, tuple]] = set()


def _signature(folder: Path) -> tuple:
    """What changes when an entry's files are written, replaced or touched."""
    sig = []
    for name in ("meta.json", "offsets.npy", "frames.npy"):
        try:
            st = os.stat(folder / name)
        except OSError:
            sig.append(None)
            continue
        sig.append((st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns))
    return tuple(sig)


def _forget(folder: Path) -> None:
    folder = Path(folder)
    for item in [v for v in _VERIFIED if v[0] == str(folder)]:
        _VERIFIED.discard(item)
    for item in [k for k in _LOADED if k[0] == str(folder)]:
        del _LOADED[item]


def _readable_meta(folder: Path) -> dict[str, Any]:
    """Whatever of ``meta.json`` can be read, for listing a damaged entry."""
    try:
        if (folder / "meta.json").stat().st_size <= META_MAX_BYTES:
            meta = json.loads((folder / "meta.json").read_text())
            return meta if isinstance(meta, dict) else {}
    except (OSError, ValueError, RecursionError):
        pass
    return {}


def _read_meta(folder: Path) -> dict[str, Any]:
    path = folder / "meta.json"
    try:
        size = path.stat().st_size
        if size > META_MAX_BYTES:
            raise CorruptArtefactError(folder, f"meta.json is {size} bytes, not an entry's")
        meta = json.loads(path.read_bytes())
    except FileNotFoundError:
        raise CorruptArtefactError(folder, "meta.json is missing") from None
    except (ValueError, RecursionError) as exc:
        raise CorruptArtefactError(folder, f"meta.json is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise CorruptArtefactError(folder, "meta.json is not a JSON object")
    fmt = meta.get("format", 1)
    if fmt != FORMAT:
        raise CorruptArtefactError(folder, f"entry format {fmt!r}, this tactbench writes and "
                                           f"reads format {FORMAT}")
    if seal(meta)["meta_checksum"] != meta.get("meta_checksum"):
        raise CorruptArtefactError(folder, "meta.json does not match its checksum (edited "
                                           "or damaged)")
    return meta


def _expect(folder: Path, ok: bool, problem: str) -> None:
    if not ok:
        raise CorruptArtefactError(folder, problem)


def verify_entry(folder: str | Path, *, full: bool = True) -> dict[str, Any]:
    """The entry's ``meta.json``, after :func:`check_entry`."""
    return check_entry(folder, full=full)[0]


def check_entry(folder: str | Path, *, full: bool = True,
                ) -> tuple[dict[str, Any], "np.ndarray"]:
    """Check a cache entry before use and return its ``meta.json``.

    Always (cheap: a few ``stat`` calls and small reads): ``meta.json`` is a JSON object
    of this format whose ``meta_checksum`` matches; its ``key`` is the folder's name
    and its ``identity`` digests to that key (another entry copied under this name is
    refused); both files have the recorded sizes; the ``.npy`` header of
    ``frames.npy`` states ``(n_frames, *frame_shape)`` of the recorded dtype;
    ``offsets.npy`` has the recorded checksum and runs from 0 up to ``n_frames``
    without going down. With ``full``, once per process for each version of the files:
    the SHA-256 of ``frames.npy`` (streamed in 1 MiB reads; see ``docs/runner.md``
    for its cost). Returns ``(meta, offsets)``; raises :class:`CorruptArtefactError`
    (the entry and the problem, in one line).
    """
    import numpy as np

    from tactbench.integrity import hash_bytes, hash_file

    folder = Path(folder)
    signature = _signature(folder)
    if not folder.is_dir():
        raise CorruptArtefactError(folder, "the entry folder is missing")
    meta = _read_meta(folder)
    _expect(folder, meta.get("key") == folder.name,
            f"meta.json belongs to entry {str(meta.get('key'))!r}, not to this one")
    identity = meta.get("identity")
    if identity is not None:
        _expect(folder, digest(identity, len(folder.name)) == folder.name,
                "its recorded identity does not hash to its key")
    files = meta.get("files")
    _expect(folder, isinstance(files, dict) and all(
        isinstance(files.get(n), dict) and isinstance(files[n].get("bytes"), int)
        and isinstance(files[n].get("checksum"), str) for n in ("frames.npy", "offsets.npy")),
        "meta.json lacks the sizes and checksums of its files")
    for name in ("frames.npy", "offsets.npy"):
        try:
            size = (folder / name).stat().st_size
        except FileNotFoundError:
            raise CorruptArtefactError(folder, f"{name} is missing") from None
        _expect(folder, size == files[name]["bytes"],
                f"{name} is {size} bytes, meta.json records {files[name]['bytes']} "
                f"({'truncated' if size < files[name]['bytes'] else 'grown'})")
    frame_shape, n_frames = meta.get("frame_shape"), meta.get("n_frames")
    n_sequences = meta.get("n_sequences")
    _expect(folder, isinstance(frame_shape, list) and 1 <= len(frame_shape) <= 3
            and all(isinstance(n, int) and n > 0 for n in frame_shape)
            and isinstance(n_frames, int) and n_frames >= 0
            and isinstance(n_sequences, int) and n_sequences >= 0,
            "meta.json's frame_shape, n_frames or n_sequences are not counts")
    channels = frame_shape[0] if len(frame_shape) == 3 else 1
    try:
        storage = Storage.from_meta(meta, channels)
        _expect(folder, meta.get("dtype") == storage.dtype.name,
                f"meta.json's dtype {str(meta.get('dtype'))[:20]!r} is not its precision's")
        _expect(folder, bool(np.isfinite(storage.scale).all() and np.isfinite(storage.offset)
                             .all() and (storage.scale != 0).all()),
                "meta.json's scale and offset are not finite numbers")
        _expect(folder, storage.scale.shape == storage.offset.shape == (channels,),
                f"meta.json's scale and offset are not one number per channel ({channels})")
        header = _npy_header(folder / "frames.npy")
    except (InputError, TypeError, ValueError) as exc:
        raise CorruptArtefactError(folder, f"frames.npy or its meta.json: {exc}") from None
    shape, fortran, dtype, data_offset = header
    _expect(folder, not fortran and dtype == storage.dtype
            and shape == (n_frames, *frame_shape),
            f"frames.npy holds {dtype} {shape}, meta.json says {storage.dtype} "
            f"{(n_frames, *frame_shape)}")
    _expect(folder, data_offset + n_frames * int(np.prod(frame_shape)) * dtype.itemsize
            == files["frames.npy"]["bytes"], "frames.npy's size does not fit its header")
    data = (folder / "offsets.npy").read_bytes()  # its size was checked: (n + 1) × 8 + header
    _expect(folder, hash_bytes(data) == files["offsets.npy"]["checksum"],
            "offsets.npy does not match its checksum")
    offsets = _offsets(folder, data, n_sequences, n_frames)
    key = (str(folder), signature)
    if full and key not in _VERIFIED:
        got = hash_file(folder / "frames.npy")
        _expect(folder, got == files["frames.npy"]["checksum"],
                f"frames.npy does not match its checksum ({got[:12]}…, recorded "
                f"{files['frames.npy']['checksum'][:12]}…)")
        if _signature(folder) == signature:  # unchanged while it was read
            _VERIFIED.add(key)
    return meta, offsets


def _npy_header(path: Path, data: bytes | None = None,
                ) -> tuple[tuple[int, ...], bool, Any, int]:
    """``(shape, fortran_order, dtype, data offset)`` of a ``.npy`` file (or of its bytes,
    ``data``), from its header alone; a header numpy cannot parse, or longer than
    :data:`NPY_HEADER_MAX`, raises :class:`CorruptArtefactError`."""
    import io

    from tactbench.integrity import read_npy_header

    with (open(path, "rb") if data is None else io.BytesIO(data)) as fh:
        try:
            shape, fortran, dtype = read_npy_header(fh, max_header=NPY_HEADER_MAX)
        except ValueError as exc:
            raise CorruptArtefactError(path, f"not a valid .npy header ({exc})") from None
        return tuple(shape), bool(fortran), dtype, fh.tell()


def _offsets(folder: Path, data: bytes, n_sequences: int, n_frames: int) -> "np.ndarray":
    """The offsets in ``data`` (the bytes of ``offsets.npy``), checked against the entry:
    int64 ``(n_sequences + 1,)`` from 0 up to ``n_frames``, never going down. The header
    is checked before anything of the stated shape is made."""
    import numpy as np

    shape, fortran, dtype, start = _npy_header(folder / "offsets.npy", data)
    _expect(folder, dtype == np.dtype("<i8") and shape == (n_sequences + 1,) and not fortran
            and len(data) - start == 8 * (n_sequences + 1),
            f"offsets.npy holds {dtype} {shape}, expected int64 ({n_sequences + 1},)")
    offsets = np.frombuffer(data, dtype="<i8", offset=start).astype(np.int64)
    _expect(folder, offsets[0] == 0 and offsets[-1] == n_frames
            and bool(np.all(np.diff(offsets) >= 0)),
            f"offsets.npy does not run from 0 up to its {n_frames} frames")
    return offsets


# ------------------------------------------------------------------------ reading


class EntryFile:
    """An entry's ``frames.npy``, read by frame range; safe to share between threads
    and to pickle (the file is opened again, lazily, where it is unpickled)."""

    def __init__(self, path: str | Path, storage: Storage) -> None:
        import numpy as np

        self.path = str(path)
        self.storage = storage
        shape, fortran, dtype, self.data_offset = _npy_header(Path(self.path))
        if fortran or dtype != storage.dtype:
            raise CorruptArtefactError(self.path, f"stored as {dtype}"
                                       f"{' (Fortran order)' * fortran}, but its meta.json "
                                       f"says {storage.dtype}")
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
                raise CorruptArtefactError(self.path, "shorter than its header says "
                                           "(truncated); the next run rebuilds the entry")
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


_LOADED: dict[tuple[str, tuple], tuple[list[StoredSequence], dict[str, Any]]] = {}


def load_encoding(folder: str | Path) -> tuple[list[StoredSequence], dict[str, Any]]:
    """The cached sequences (read from disk on demand, float32) and metadata of an entry.

    The entry is verified first (:func:`check_entry`: sizes, identity and offsets each
    time, the checksum of ``frames.npy`` once per process); a damaged one raises
    :class:`CorruptArtefactError`. Memoised per process and version of the entry's
    files: the cells of one process that read the same entry share its open file.
    Reading costs a ``preadv`` per slice plus, for float16 and uint8, one pass to
    float32; nothing stays resident after a read but the array it returns.
    """
    path = Path(folder)
    memo = (str(path), _signature(path))
    if memo not in _LOADED:
        meta, offsets = check_entry(path)
        frame_shape = meta["frame_shape"]
        channels = frame_shape[0] if len(frame_shape) == 3 else 1
        file = EntryFile(path / "frames.npy", Storage.from_meta(meta, channels))
        seqs = [StoredSequence(file, a, b) for a, b in zip(offsets[:-1], offsets[1:])]
        verified = (str(path), memo[1]) in _VERIFIED
        _forget(path)  # an older version of this entry
        if verified:
            _VERIFIED.add((str(path), memo[1]))
        _LOADED[memo] = (seqs, meta)
    return _LOADED[memo]


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
    identities: dict[str, dict[str, Any]] = {}
    for orphan in cache.clean():
        log.info("removed the temporary folder %s left by process %s", orphan.path,
                 orphan.pid)
    for enc, kind in sorted(needed):
        imaging = imaging_identity(scene, kind)
        key = cache.key(plan_.dataset_hash, imaging, enc, plan_.encoder_versions[enc],
                        precision)
        identities[key] = cache.identity(plan_.dataset_hash, imaging, enc,
                                         plan_.encoder_versions[enc], precision)
        folders[(enc, kind)] = str(cache.path(key))
        if (enc, kind) not in pending_pairs:
            continue
        if cache.path(key).exists() or cache.path(key).is_symlink():
            if _usable(cache, key, enc, kind):
                continue
        missing[kind][enc] = key
    if missing["vectors"]:
        _store_vectors(plan_, cache, missing["vectors"], precision, chunk_bytes, identities)
    if missing["images"]:
        _encode_images(plan_, cache, missing["images"], precision, progress, chunk_bytes,
                       identities)
    return folders


def _usable(cache: EncodingCache, key: str, enc: str, kind: str) -> bool:
    """Whether the entry ``key`` is sound; a damaged one is reported and removed. When
    its files change while they are checked (another run replacing a damaged entry with
    a new one), they are checked again rather than removed."""
    for _ in range(3):
        found = _signature(cache.path(key))
        try:
            cache.verify(key)
            return True
        except CorruptArtefactError as exc:
            if _signature(cache.path(key)) != found:
                continue  # replaced meanwhile: look at the new files
            log.warning("tactbench: warning: cached encoding %s (%s, %s) is damaged: %s; "
                        "encoding it again", key, enc, kind, exc.problem)
            cache.discard(key)
            return False
    return False


def _common_meta(plan_: Plan, enc: str, kind: str) -> dict[str, Any]:
    from tactbench.contracts import ENCODER

    return {"encoder": enc, "encoder_version": plan_.encoder_versions[enc],
            "channels": list(ENCODER.get(plan_.encoders[enc], "channels")),
            "imaging": imaging_identity(plan_.scene, kind),
            "dataset": plan_.dataset.name, "dataset_hash": plan_.dataset_hash}


def _store_vectors(plan_: Plan, cache: EncodingCache, keys: dict[str, str],
                   precision: str, chunk_bytes: int,
                   identities: dict[str, dict[str, Any]]) -> None:
    """The taxel-vector entries: no imaging; raw passes the vectors through, an encoder
    with ``encode_vectors`` (frame-diff) gives ``(T, C·N)`` frames, its channels side by
    side (planning refuses any other encoder on vectors). Stored as one channel whose
    range spans every channel's."""
    from tactbench.contracts import ENCODER
    from tactbench.specs import parse_spec

    dataset = plan_.dataset
    lengths = dataset.lengths()
    for enc, key in keys.items():
        encoder = plan_.encoders[enc]
        ranges = tuple(ENCODER.get(encoder, "ranges"))
        n_channels = max(1, len(ENCODER.get(encoder, "channels")))
        if ranges:
            ranges = ((min(lo for lo, _ in ranges), max(hi for _, hi in ranges)),)
        encode = None if parse_spec(enc)[0] == "raw" else ENCODER.get(encoder, "encode_vectors")
        width = dataset.n_taxels * (1 if encode is None else n_channels)
        storage = Storage.for_channels(precision, 1, ranges)
        t0 = time.perf_counter()
        encode_s = 0.0
        with cache.entry(key, lengths, (width,), storage) as writer:
            for a, b in chunk_bounds(lengths, 4 * width, chunk_bytes):
                for vec in dataset.vectors(range(a, b)):
                    if encode is not None:
                        t1 = time.perf_counter()
                        vec = encode(vec)
                        encode_s += time.perf_counter() - t1
                        if vec.shape != (len(vec), width):
                            raise ValueError(f"encoder {enc!r}: encode_vectors gave frames of "
                                             f"{vec.shape[1:]}, not ({width},)")  # a bug
                    writer.append(vec)
            writer.meta.update({**_common_meta(plan_, enc, "vectors"),
                                "identity": identities[key],
                                "encode_seconds": encode_s, "encode_cpu_seconds": encode_s,
                                "imaging_seconds": 0.0, "workers": 1,
                                "wall_seconds": time.perf_counter() - t0,
                                "peak_rss_mb": peak_rss_mb()})


def _encode_images(plan_: Plan, cache: EncodingCache, keys: dict[str, str], precision: str,
                   progress: "Progress | None", chunk_bytes: int,
                   identities: dict[str, dict[str, Any]]) -> None:
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
                "identity": identities[keys[enc]],
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
