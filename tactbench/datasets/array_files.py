"""One recording file of a folder dataset: ``.npy``, ``.npz`` or ``.csv`` into an array.

The readers :mod:`tactbench.datasets.folder` uses for each file of
``ROOT/<class>/<recording>.*`` (the formats are described there and in
``docs/own-data.md``). Every file is checked to be a regular file before it is opened
(:func:`tactbench.integrity.check_regular_file`), each array's header before its data is
read (and its size against the memory budget), and every mistake is one
:class:`~tactbench.errors.InputError` naming the file (and line).
"""

from __future__ import annotations

import csv
import math
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from tactbench.budget import check_budget
from tactbench.errors import InputError, TactbenchError
from tactbench.integrity import check_regular_file, read_npy_header, zip_read_errors

SUFFIXES = (".npy", ".npz", ".csv")


def read_array_file(path: Path, *, timestamp_column: str | int | None = None
                    ) -> tuple[np.ndarray, np.ndarray | None]:
    """``(values, timestamps or None)`` of one ``.npy``, ``.npz`` or ``.csv`` file."""
    suffix = path.suffix.lower()
    try:
        check_regular_file(path, what="recording")  # a FIFO or a device: never opened
        if suffix == ".npy":
            with path.open("rb") as fh:
                return _read_npy(fh, path, path.stat().st_size, "the file"), None
        if suffix == ".npz":
            return _read_npz(path)
        if suffix == ".csv":
            return _read_csv(path, timestamp_column)
    except OSError as exc:  # no permission, a FIFO, an I/O error: the file, one line
        if isinstance(exc, TactbenchError):
            raise
        raise InputError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    raise InputError(f"{path}: unknown suffix {suffix!r}; expected one of {', '.join(SUFFIXES)}")


def _read_npy(fh: Any, path: Path, size: int, what: str) -> np.ndarray:
    """An npy array from ``fh``, its header checked (and its size budgeted) before reading."""
    try:
        shape, fortran, dtype = read_npy_header(fh)
    except ValueError as exc:
        raise InputError(f"{path}: {what} is not a valid .npy array ({exc})") from None
    if dtype.hasobject:
        raise InputError(f"{path}: {what} holds Python objects (a ragged array of "
                         f"recordings or frames of different sizes?), not numbers")
    if dtype.kind not in "biuf":
        raise InputError(f"{path}: {what} holds {dtype} values; expected numbers")
    count = math.prod(shape)
    nbytes = count * dtype.itemsize
    check_budget(nbytes, f"reading {path} ({'×'.join(map(str, shape))} {dtype})")
    header_end = fh.tell()
    truncated = InputError(f"{path}: {what} is truncated: its header says "
                           f"{'×'.join(map(str, shape))} {dtype} ({nbytes} bytes), "
                           f"{max(size - header_end, 0)} bytes follow")
    if size - header_end < nbytes:
        raise truncated
    arr = np.empty(count, dtype=dtype)
    view, got = memoryview(arr).cast("B"), 0
    while got < nbytes:
        n = fh.readinto(view[got:])
        if not n:
            raise truncated
        got += n
    return arr.reshape(shape, order="F" if fortran else "C")


def _read_npz(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    try:
        zf = zipfile.ZipFile(path)
    except (*zip_read_errors(), ValueError) as exc:
        raise InputError(f"{path}: not a valid .npz file (not a zip archive: {exc})") from None
    with zf:
        members: dict[str, zipfile.ZipInfo] = {}
        for info in zf.infolist():
            if not info.filename.endswith(".npy") or info.is_dir():
                continue
            stem = Path(info.filename).stem
            if stem in members:  # a/values.npy and b/values.npy: which is meant?
                raise InputError(f"{path}: members {members[stem].filename!r} and "
                                 f"{info.filename!r} have one name ({stem!r}) in different "
                                 f"folders; keep one")
            members[stem] = info
        if "values" in members:
            values_info = members["values"]
        elif len(members) == 1:
            values_info = next(iter(members.values()))
        else:
            raise InputError(f"{path}: .npz needs a member 'values' (or exactly one array); "
                             f"found {', '.join(sorted(members)) or 'none'}")
        values = _read_member(zf, values_info, path)
        ts = None
        if "timestamps" in members and members["timestamps"] is not values_info:
            ts = _read_member(zf, members["timestamps"], path).astype(np.float64)
            if ts.shape != values.shape[:1]:
                raise InputError(f"{path}: 'timestamps' has shape {ts.shape}; expected "
                                 f"({values.shape[0] if values.ndim else '?'},), one per frame")
    return values, ts


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path) -> np.ndarray:
    try:
        with zf.open(info) as fh:
            return _read_npy(fh, path, info.file_size, f"member {info.filename!r}")
    except zip_read_errors() as exc:
        raise InputError(f"{path}: member {info.filename!r} cannot be read "
                         f"(damaged .npz: {exc})") from None


def _read_csv(path: Path, timestamp_column: str | int | None
              ) -> tuple[np.ndarray, np.ndarray | None]:
    """One frame per line; parsed a line at a time into one array (never a list of
    every field as text, which costs ~50 bytes a field)."""
    size = path.stat().st_size
    check_budget(2 * size, f"reading {path}")  # its bytes and their text
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text CSV file (not UTF-8; binary data?)") from None
    if "\x00" in text:
        raise InputError(f"{path}: not a text CSV file (it holds NUL bytes; binary data?)")
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1) if line.strip()]
    del text
    if not lines:
        raise InputError(f"{path}: empty CSV file (expected one frame per row)")
    first = lines[0][1]
    delimiter = next((d for d in (",", ";", "\t") if d in first), ",")

    line_of = {id(line): n for n, line in lines}

    def fields(line: str) -> list[str]:
        try:
            return [c.strip() for c in next(csv.reader([line], delimiter=delimiter), [])]
        except csv.Error as exc:  # a field beyond the csv module's limit, a stray quote
            raise InputError(f"{path}, line {line_of.get(id(line), '?')}: not a CSV row "
                             f"({exc})") from None

    # a delimiter ending every line is no column; on a file of one line it could as well
    # be a missing last reading, so it is refused rather than guessed
    trailing = all(line.rstrip().endswith(delimiter) for _, line in lines)
    if trailing and len(lines) == 1:
        raise InputError(f"{path}, line {lines[0][0]}: its one row ends in {delimiter!r}: a "
                         f"missing last reading or a trailing delimiter? Give the reading, "
                         f"or remove the {delimiter!r}")

    def row_of(line: str) -> list[str]:
        row = fields(line)
        return row[:-1] if trailing and row and row[-1] == "" else row

    header = None
    start = 0
    if is_header(row_of(first)):
        header = row_of(first)
        start = 1
        if len(lines) == 1:
            raise InputError(f"{path}: only a header row, no frames")
    width = len(header) if header is not None else len(row_of(first))
    ts_col = _timestamp_index(timestamp_column, header, width, path)
    check_budget(8 * width * (len(lines) - start) + 2 * size,
                 f"reading {path} ({len(lines) - start} rows × {width} fields)")
    out = np.empty((len(lines) - start, width), dtype=np.float64)
    for k, (lineno, line) in enumerate(lines[start:]):
        row = row_of(line)
        if len(row) != width:
            raise InputError(f"{path}, line {lineno}: {len(row)} fields, expected {width} "
                             f"({'as the header' if header is not None else 'as the first row'};"
                             f" rows of different lengths)")
        try:
            out[k] = [float(c) for c in row]
        except ValueError:
            col = next(i for i, c in enumerate(row) if not is_number(c))
            name = header[col] if header is not None else f"column {col}"
            raise InputError(f"{path}, line {lineno}: {name} is {row[col]!r}, not a number"
                             ) from None
    if ts_col is None:
        return out, None
    ts = out[:, ts_col].copy()
    return np.delete(out, ts_col, axis=1), ts


def _timestamp_index(column: str | int | None, header: list[str] | None, width: int,
                     path: Path) -> int | None:
    if column is None:
        return None
    if header is not None and str(column) in header:
        return header.index(str(column))
    if isinstance(column, int) and not isinstance(column, bool):
        if 0 <= column < width:
            return column
        raise InputError(f"{path}: timestamp_column {column} is out of range "
                         f"(the file has {width} columns)")
    where = f"header ({', '.join(header[:6])}{', …' if len(header) > 6 else ''})" \
        if header is not None else "file (it has no header row)"
    raise InputError(f"{path}: no column {column!r} in the {where} for timestamp_column")


#: Fields that mean "no reading" in a data row, never a column name.
MISSING_MARKERS = frozenset({"", "-", "--", "?", "na", "n/a", "nan", "null", "none"})


def is_header(fields: list[str]) -> bool:
    """Whether a CSV's first row is a header: every field a name (not blank, not a
    missing-reading marker such as ``-`` or ``NA``) and at least one not a number.
    A first row with a blank or ``-`` field is a data row, and is refused like the same
    field on any other line; it is never dropped as a header."""
    return (all(f.strip().lower() not in MISSING_MARKERS for f in fields)
            and any(not is_number(f) for f in fields))


def is_number(text: str) -> bool:
    """Whether ``text`` reads as a float (``nan`` and ``inf`` do)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


__all__ = ["read_array_file", "is_header", "is_number", "MISSING_MARKERS", "SUFFIXES"]
