"""Checksums and file formats: what every stored artefact goes through when read back.

Everything tactbench stores records a checksum of its payload, and its reader verifies
it before use (see ``docs/reliability.md``). The digest is SHA-256 (``hashlib``): on
this project's machines it hashes about 1.8 GB/s (BLAKE2b 0.9 GB/s; CPUs with SHA
instructions), far cheaper than recomputing any cached encoding.

The file formats tactbench reads arrays from are checked here too: :func:`read_npy_header`
is the one reader of ``.npy`` headers (with the one limit :data:`NPY_HEADER_MAX`), and
:func:`zip_read_errors` is what a damaged ``.npz`` can raise. (The memory budget of large
steps is :mod:`tactbench.budget`.)
"""

from __future__ import annotations

import hashlib
import io
import struct
import zipfile
import zlib
from pathlib import Path
from typing import Any, Iterable


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
