"""Cache entries: the on-disk format of one encoded dataset, its verification, reading.

An entry is a folder holding ``frames.npy`` (all frames stacked, ``(ΣT, C, H, W)`` or
``(ΣT, N)`` in the entry's storage dtype, see :class:`~tactbench.encoders.encoding.Storage`),
``offsets.npy`` (int64 ``(n + 1,)``: sample i is ``frames[o[i]:o[i+1]]``) and
``meta.json``.

Writing (:class:`EntryWriter`): ``frames.npy`` is written front to back with plain writes
after a ``.npy`` header for the known total shape, never through a writable memory map
(its dirty pages would count as the process's resident memory). ``meta.json`` records
``precision``, ``dtype`` and per-channel ``scale`` and ``offset`` (value = stored · scale
+ offset).

Verification (:func:`verify_entry`, the one check): ``meta.json`` also records what the
entry is (its key and the identity the key is the digest of, encoder, versions, shapes)
and the sizes and SHA-256 of ``frames.npy`` and ``offsets.npy`` (hashed while they are
written), and seals itself with ``meta_checksum``. Every open checks the cheap part
(identity, sizes, headers, offsets); the checksum of ``frames.npy`` is read once per
process for each version of the file.

Reading (:func:`load_encoding`) gives :class:`StoredSequence` objects: a sample's frames
read from the file on demand (``os.preadv`` into a fresh array) and turned back into
float32; nothing is memory-mapped, so reading an entry sequence by sequence keeps the
process's resident memory at one sequence.
"""

from __future__ import annotations

import io
import json
import math
import os
import stat
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from tactbench import __version__
from tactbench.encoders.encoding import Storage
from tactbench.errors import CorruptArtefactError, InputError
from tactbench.integrity import (ALGORITHM, hash_bytes, hash_file, new_hasher, read_npy_header,
                                 read_regular_bytes, special_file_problem)
from tactbench.runner.execution.planning import digest
from tactbench.runner.execution.system import now

if TYPE_CHECKING:
    import numpy as np

#: Version of the entry format: 2 added precision, scale and offset; 3 added the entry's
#: key and identity, the sizes and checksums of its files and of ``meta.json`` itself.
#: Entries of another format are rebuilt.
FORMAT = 3


# ------------------------------------------------------------------------ writing


def _canonical(obj: Any) -> bytes:
    """The bytes a JSON document's checksum is taken of: sorted keys, no spaces."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()


def seal(meta: dict[str, Any]) -> dict[str, Any]:
    """``meta`` with ``meta_checksum``: the checksum of everything else in it."""
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
        import numpy as np

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
        import numpy as np

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


# ------------------------------------------------------------------- verification

#: Hex digits of an entry's key.
KEY_DIGITS = 24
#: ``meta.json`` larger than this is not one tactbench wrote.
META_MAX_BYTES = 1 << 20
#: ``(folder, signature of its files)`` whose checksums this process verified.
_VERIFIED: set[tuple[str, tuple]] = set()


def signature(folder: Path) -> tuple:
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


#: The file whose modification time is an entry's last use: touched when a run checks or
#: loads the entry; ``tactbench cache prune`` removes the least recently used first.
USED_MARKER = "used"


def mark_used(folder: str | Path) -> None:
    """Record that the entry at ``folder`` is used now (:data:`USED_MARKER`'s time). Only
    a regular file is touched (never through a link, never a FIFO); a cache that cannot
    be written (a read-only disk) keeps no record, and that is not an error."""
    try:
        fd = os.open(Path(folder) / USED_MARKER,
                     os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError:
        return
    try:
        if stat.S_ISREG(os.fstat(fd).st_mode):
            os.utime(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def last_used(folder: str | Path) -> float:
    """When the entry at ``folder`` was last used (seconds since the epoch): its
    :data:`USED_MARKER`'s time, else when its ``meta.json`` was written (entries from
    before the marker), else the folder's time; 0 when none can be read."""
    folder = Path(folder)
    for path in (folder / USED_MARKER, folder / "meta.json", folder):
        try:
            return path.stat().st_mtime
        except OSError:
            continue
    return 0.0


def mark_verified(folder: str | Path) -> None:
    """Record that the entry at ``folder``, as its files are now, is verified (its
    writer took the checksums of the very bytes it wrote: no need to read them again)."""
    _VERIFIED.add((str(folder), signature(Path(folder))))


def forget(folder: str | Path) -> None:
    """Drop what this process knows of the entry at ``folder`` (verified checksums, open
    files): it is about to be removed or replaced."""
    folder = Path(folder)
    for item in [v for v in _VERIFIED if v[0] == str(folder)]:
        _VERIFIED.discard(item)
    for item in [k for k in _LOADED if k[0] == str(folder)]:
        del _LOADED[item]


def readable_meta(folder: Path) -> dict[str, Any]:
    """Whatever of ``meta.json`` can be read, for listing a damaged entry."""
    try:
        meta = json.loads(read_regular_bytes(folder / "meta.json", limit=META_MAX_BYTES))
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
        meta = json.loads(read_regular_bytes(path, limit=META_MAX_BYTES))
    except FileNotFoundError:
        raise CorruptArtefactError(folder, "meta.json is missing") from None
    except InputError as exc:  # a FIFO or a device: refused before it is opened
        raise CorruptArtefactError(folder, str(exc)) from None
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


def verify_entry(folder: str | Path, *, full: bool = True,
                 ) -> tuple[dict[str, Any], "np.ndarray"]:
    """Check a cache entry before use; its ``meta.json`` and offsets.

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
    folder = Path(folder)
    before = signature(folder)
    if not folder.is_dir():
        raise CorruptArtefactError(folder, "the entry folder is missing")
    meta = _read_meta(folder)
    _expect(folder, meta.get("key") == folder.name,
            f"meta.json belongs to entry {str(meta.get('key'))!r}, not to this one")
    identity = meta.get("identity")
    if identity is not None:
        _expect(folder, digest(identity, len(folder.name)) == folder.name,
                "its recorded identity does not hash to its key")
    files = _check_sizes(folder, meta)
    _check_frames_header(folder, meta, files["frames.npy"]["bytes"])
    data = (folder / "offsets.npy").read_bytes()  # its size was checked: (n + 1) × 8 + header
    _expect(folder, hash_bytes(data) == files["offsets.npy"]["checksum"],
            "offsets.npy does not match its checksum")
    offsets = _offsets(folder, data, meta["n_sequences"], meta["n_frames"])
    key = (str(folder), before)
    if full and key not in _VERIFIED:
        got = hash_file(folder / "frames.npy")
        _expect(folder, got == files["frames.npy"]["checksum"],
                f"frames.npy does not match its checksum ({got[:12]}…, recorded "
                f"{files['frames.npy']['checksum'][:12]}…)")
        if signature(folder) == before:  # unchanged while it was read
            _VERIFIED.add(key)
    return meta, offsets


def _check_sizes(folder: Path, meta: dict[str, Any]) -> dict[str, Any]:
    """``meta.json``'s ``files`` (the size and checksum of each), after checking that both
    files are there with the recorded sizes."""
    files = meta.get("files")
    _expect(folder, isinstance(files, dict) and all(
        isinstance(files.get(n), dict) and isinstance(files[n].get("bytes"), int)
        and isinstance(files[n].get("checksum"), str) for n in ("frames.npy", "offsets.npy")),
        "meta.json lacks the sizes and checksums of its files")
    for name in ("frames.npy", "offsets.npy"):
        special = special_file_problem(folder / name)
        if special is not None:  # a FIFO or a device is never opened
            raise CorruptArtefactError(folder, special)
        try:
            size = (folder / name).stat().st_size
        except FileNotFoundError:
            raise CorruptArtefactError(folder, f"{name} is missing") from None
        _expect(folder, size == files[name]["bytes"],
                f"{name} is {size} bytes, meta.json records {files[name]['bytes']} "
                f"({'truncated' if size < files[name]['bytes'] else 'grown'})")
    return files


def _check_frames_header(folder: Path, meta: dict[str, Any], size: int) -> None:
    """``meta.json``'s counts and storage are sound, and the header of ``frames.npy``
    (``size`` bytes) states ``(n_frames, *frame_shape)`` of the storage's dtype."""
    import numpy as np

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
            == size, "frames.npy's size does not fit its header")


def _npy_header(path: Path, data: bytes | None = None,
                ) -> tuple[tuple[int, ...], bool, Any, int]:
    """``(shape, fortran_order, dtype, data offset)`` of a ``.npy`` file (or of its bytes,
    ``data``), from its header alone; a header numpy cannot parse, or longer than
    :data:`tactbench.integrity.NPY_HEADER_MAX`, raises :class:`CorruptArtefactError`."""
    with (open(path, "rb") if data is None else io.BytesIO(data)) as fh:
        try:
            shape, fortran, dtype = read_npy_header(fh)
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

    The entry is verified first (:func:`verify_entry`: sizes, identity and offsets each
    time, the checksum of ``frames.npy`` once per process); a damaged one raises
    :class:`CorruptArtefactError`. Memoised per process and version of the entry's
    files: the cells of one process that read the same entry share its open file.
    Reading costs a ``preadv`` per slice plus, for float16 and uint8, one pass to
    float32; nothing stays resident after a read but the array it returns.
    """
    path = Path(folder)
    memo = (str(path), signature(path))
    if memo not in _LOADED:
        meta, offsets = verify_entry(path)
        mark_used(path)
        frame_shape = meta["frame_shape"]
        channels = frame_shape[0] if len(frame_shape) == 3 else 1
        file = EntryFile(path / "frames.npy", Storage.from_meta(meta, channels))
        seqs = [StoredSequence(file, a, b) for a, b in zip(offsets[:-1], offsets[1:])]
        verified = (str(path), memo[1]) in _VERIFIED
        forget(path)  # an older version of this entry
        if verified:
            _VERIFIED.add((str(path), memo[1]))
        _LOADED[memo] = (seqs, meta)
    return _LOADED[memo]


