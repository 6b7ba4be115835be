"""Checksums and file formats: what every stored artefact goes through when read back.

Everything tactbench stores records a checksum of its payload, and its reader verifies
it before use (see ``docs/reliability.md``). The digest is SHA-256 (``hashlib``): on
this project's machines it hashes about 1.8 GB/s (BLAKE2b 0.9 GB/s; CPUs with SHA
instructions), far cheaper than recomputing any cached encoding.

The file formats tactbench reads arrays from are checked here too: :func:`read_npy_header`
is the one reader of ``.npy`` headers (with the one limit :data:`NPY_HEADER_MAX`), and
:func:`zip_read_errors` is what a damaged ``.npz`` can raise. (The memory budget of large
steps is :mod:`tactbench.budget`.)

Every reader of a file a user or a disk may have put there opens it through
:func:`check_regular_file` (or :func:`read_regular_bytes`): only regular files are read,
with their size checked against a limit before a byte is read. A FIFO (opening one
blocks until a writer comes), a device (``/dev/zero`` reads forever), a socket or a
dangling link is one line naming the path, decided by ``os.stat`` before any ``open``.
"""

from __future__ import annotations

import hashlib
import io
import os
import stat
import struct
import zipfile
import zlib
from pathlib import Path
from typing import Any, Iterable

from tactbench.budget import human_bytes
from tactbench.errors import InputError, MissingFileError


#: Digest algorithm recorded beside every checksum (so it can change later).
ALGORITHM = "sha256"
_CHUNK = 1 << 20


def new_hasher() -> "hashlib._Hash":
    return hashlib.sha256()


def hash_bytes(data: bytes | memoryview) -> str:
    """Hex digest of ``data``."""
    h = new_hasher()
    h.update(data)
    return h.hexdigest()


def hash_chunks(chunks: Iterable[bytes | memoryview]) -> str:
    """Hex digest of the concatenation of ``chunks`` (streamed; nothing is joined)."""
    h = new_hasher()
    for chunk in chunks:
        h.update(chunk)
    return h.hexdigest()


def hash_file(path: str | Path, *, length: int | None = None) -> str:
    """Hex digest of a file's bytes (its first ``length`` bytes), read in 1 MiB chunks."""
    h = new_hasher()
    left = length
    with open(path, "rb") as f:
        while left is None or left > 0:
            block = f.read(_CHUNK if left is None else min(_CHUNK, left))
            if not block:
                break
            h.update(block)
            if left is not None:
                left -= len(block)
    return h.hexdigest()


# ------------------------------------------------------------------------ npy headers

#: The longest ``.npy`` header read. numpy writes a few hundred bytes; a larger length
#: field is damage (a flipped version byte once claimed a 630 MB header), refused before
#: that many bytes are read.
NPY_HEADER_MAX = 1 << 16


def read_npy_header(fh: Any, *, max_header: int = NPY_HEADER_MAX
                    ) -> tuple[tuple[int, ...], bool, Any]:
    """``(shape, fortran_order, dtype)`` of the ``.npy`` array starting at ``fh``'s position,
    leaving ``fh`` at the first byte of its data; ``fh`` may be a stream (a zip member).

    Raises ``ValueError`` with a short reason for anything but a sound header: wrong magic
    or version (1.0, 2.0 and 3.0 are read), a length field beyond ``max_header`` bytes, a
    header cut short, anything numpy's own parser raises on it (``ValueError``,
    ``SyntaxError``, ``tokenize.TokenError``, ...), or a shape that is not whole numbers
    ≥ 0. Callers turn it into their own error naming the file. Object dtypes are returned
    as they are: whether they are refused is the caller's to say.
    """
    from numpy.lib import format as npy  # numpy stays out of import time

    start = fh.read(8)
    if len(start) < 8 or start[:6] != b"\x93NUMPY":
        raise ValueError("no .npy magic string")
    major = start[6]
    if major not in (1, 2, 3) or start[7] != 0:
        raise ValueError(f"npy format version {major}.{start[7]} is not read")
    length_field = fh.read(2 if major == 1 else 4)
    if len(length_field) < (2 if major == 1 else 4):
        raise ValueError("cut short in its header")
    length = int.from_bytes(length_field, "little")
    if length > max_header:
        raise ValueError(f"a header of {length} bytes (at most {max_header})")
    header = fh.read(length)
    if len(header) < length:
        raise ValueError("cut short in its header")
    copy = io.BytesIO(start + length_field + header)
    try:
        npy.read_magic(copy)
        reader = npy.read_array_header_1_0 if major == 1 else npy.read_array_header_2_0
        shape, fortran, dtype = reader(copy, max_header_size=max(max_header, 10_000))
    except Exception as exc:  # noqa: BLE001 - see the docstring: all mean a bad header
        first = str(exc).splitlines()[0][:120] if str(exc) else ""
        raise ValueError(f"{type(exc).__name__}: {first}") from None
    if not isinstance(shape, tuple) or any(
            not isinstance(n, int) or isinstance(n, bool) or n < 0 for n in shape):
        raise ValueError(f"shape {shape!r}")
    return shape, bool(fortran), dtype


def zip_read_errors() -> tuple[type[BaseException], ...]:
    """What reading a damaged zip archive (an ``.npz``) can raise, from the standard
    library: a bad archive or member, inflating damaged data (``zlib.error``), a header
    cut short (``struct.error``, ``EOFError``), an unknown compression or version
    (``NotImplementedError``), an "encrypted" flag (``RuntimeError``), the file itself."""
    return (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, struct.error, EOFError,
            NotImplementedError, RuntimeError, OSError)


# ------------------------------------------------------------------ only regular files

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def path_kind(path: str | Path) -> str | None:
    """What ``path`` is, as a message says it: ``"a regular file"``, ``"a folder"``,
    ``"a FIFO (named pipe)"``, ... or ``"a dangling link (to X)"``; None when nothing is
    there. Links are followed; only ``os.stat``: nothing is opened."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return f"a dangling link (to {os.readlink(path)})" if os.path.islink(path) else None
    except OSError as exc:
        return f"unreadable ({exc.strerror or exc})"
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((text for test, text in _KINDS if test(mode)), "not a regular file")


def special_file_problem(path: str | Path) -> str | None:
    """Why ``path`` is not a regular file tactbench may read, or None when it is one (or
    does not exist at all: the caller says "no such file" in its own words). Links are
    followed; a link to nothing is a problem. Only ``os.stat``: nothing is opened."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        if os.path.islink(path):
            return f"{path} is a dangling link (to {os.readlink(path)}), not a file"
        return None
    except OSError as exc:  # a loop of links, a name too long, no permission
        return f"{path} cannot be read: {exc.strerror or exc}"
    if stat.S_ISREG(mode):
        return None
    kind = next((text for test, text in _KINDS if test(mode)), "not a regular file")
    via = " (through a link)" if os.path.islink(path) else ""
    return f"{path} is {kind}{via}, not a regular file; tactbench reads only regular files"


def check_regular_file(path: str | Path, *, limit: int | None = None,
                       what: str = "file") -> int:
    """The size of ``path``, refused in one line (:class:`InputError`) unless it is a
    regular file (:func:`special_file_problem`) of at most ``limit`` bytes. Call it before
    opening: a missing file raises :class:`MissingFileError` (a ``FileNotFoundError``,
    as ``open`` would) saying "no such ``what``"."""
    problem = special_file_problem(path)
    if problem is not None:
        raise InputError(problem)
    try:
        size = os.stat(path).st_size
    except FileNotFoundError:
        raise MissingFileError(f"{path}: no such {what}") from None
    if limit is not None and size > limit:
        raise InputError(f"{path} is {human_bytes(size)}, more than the "
                         f"{human_bytes(limit)} a {what} may be; it was not read")
    return size


def read_regular_bytes(path: str | Path, *, limit: int, what: str = "file") -> bytes:
    """The bytes of the regular file ``path`` of at most ``limit`` bytes
    (:func:`check_regular_file`). Opened without blocking and checked again on the open
    descriptor (a FIFO swapped in meanwhile is refused, not waited on); at most
    ``limit`` bytes are read whatever the file grows to."""
    check_regular_file(path, limit=limit, what=what)
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{path} changed into a special file while it was opened; "
                             f"tactbench reads only regular files")
        # its size, not the limit: read(n) allocates n bytes before reading
        data = fh.read(min(st.st_size, limit) + 1)
        if len(data) > st.st_size:  # it grew meanwhile: the rest, up to the limit
            data += fh.read(limit + 1 - len(data))
    if len(data) > limit:
        raise InputError(f"{path} grew beyond the {human_bytes(limit)} a {what} may be "
                         f"while it was read")
    return data
