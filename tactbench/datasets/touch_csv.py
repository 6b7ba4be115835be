"""The public touch-gesture corpora's CSV files (CoST, HAART): read fast, checked, cached.

Both corpora are one row per frame: a few label columns (subject, gesture, ...), then 64
pressure channels of an 8 × 8 grid. :func:`read_table` reads such a file with pyarrow's
CSV engine (column by column, on every core; the extra ``tactbench[export]``), never a
Python list per row: the 206 MB of the real CoST file in seconds, not minutes. It gives
each label column as integer codes and the names they stand for, the numeric columns as
arrays and the channels as one float32 ``(F, 64)`` array, and refuses, one line naming
the file and line, a file that is not what it claims: a missing column, a channel count
other than 64, a row with another number of fields, a reading that is not a number
(empty, ``nan``, text, infinite), an empty label.

:func:`cached_dataset` converts a file once into tactbench's store
(:mod:`tactbench.data.store`) under ``cache_dir("datasets")``, keyed by the SHA-256 of
the files' bytes and the reader's options, so a second load reads the store (verified
against its content hash) instead of the CSV. A file's SHA-256 is computed once per
version of it (:func:`file_digest`: path, size, modification time).

Column names are compared without case and stray spaces (``" ch1"`` is ``ch1``); the
header row is optional (without one the columns are in the documented order).
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
import mmap
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from tactbench.data.dataset import Dataset
from tactbench.datasets.array_files import is_number
from tactbench.budget import check_budget, human_bytes
from tactbench.errors import BudgetError, InputError, require
from tactbench.integrity import check_regular_file
from tactbench.paths import atomic_folder, atomic_write_text, cache_dir

#: Pressure channels of both corpora: the 8 × 8 grid.
CHANNELS = 64
#: Peak memory of reading a file, as a multiple of its size (with room above the 4.4×
#: measured at the real CoST file's size).
READ_FACTOR = 5
#: Bumped when what a reader makes of the same file changes: it keys the store's cache.
READER_VERSION = 1
_CHANNEL_NAME = re.compile(r"ch(\d+)")
_CONVERSION = re.compile(r"In CSV column #(\d+): CSV conversion error to \w+: invalid "
                         r"value '(.*)'", re.S)


def clean_name(name: str) -> str:
    """A header name as compared: no surrounding spaces or quotes, lower case."""
    return name.strip().strip('"').strip().lower()


@dataclass
class Table:
    """A corpus file read into columns.

    ``labels[name]`` is ``(codes, names)``: int32 codes ``(F,)`` into the list of the
    distinct texts (stripped of spaces), in order of first appearance; ``numbers[name]``
    int64 ``(F,)``; ``values`` float32 ``(F, 64)``, the channels in the file's order.
    """

    path: Path
    header_lines: int
    labels: dict[str, tuple[np.ndarray, list[str]]]
    numbers: dict[str, np.ndarray]
    values: np.ndarray

    @property
    def n_rows(self) -> int:
        return int(self.values.shape[0])

    def where(self, row: int) -> str:
        """``"FILE, line L"`` of data row ``row`` (0-based, as in the arrays)."""
        return f"{self.path}, line {line_of(self.path, self.header_lines, row)}"


def line_of(path: Path, header_lines: int, row: int) -> int:
    """The 1-based line of data row ``row`` (0-based; blank lines hold no row, as the CSV
    engine skips them): counted in the file's bytes, only when an error names a row."""
    with path.open("rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        data = np.frombuffer(mm, dtype=np.uint8)
        ends = np.flatnonzero(data == 10)
        starts = np.concatenate([[0], ends + 1])
        stops = np.concatenate([ends, [data.size]])
        lengths = stops - starts
        has_cr = np.zeros(lengths.size, dtype=bool)
        nonempty = lengths > 0
        has_cr[nonempty] = data[stops[nonempty] - 1] == 13
        blank = (lengths - has_cr) == 0
        del data
    blank[:header_lines] = True  # the header holds no data row
    filled = np.flatnonzero(~blank)
    return int(filled[row]) + 1 if row < filled.size else int(lengths.size)


def _first_line(path: Path) -> list[str]:
    """The first line's fields (a UTF-8 byte-order mark dropped); [] for an empty file."""
    with path.open("rb") as fh:
        first = fh.readline(1 << 20)
    text = first.decode("utf-8-sig", errors="replace").rstrip("\r\n")
    return next(csv.reader([text]), []) if text.strip() else []


def _columns(path: Path, first: list[str], labels: Sequence[str], numbers: Sequence[str],
             aliases: dict[str, str], corpus: str, optional: Sequence[str] = ()
             ) -> tuple[list[str], int]:
    """Each column's role (a label's or number's name, or ``chK``) and the header's line
    count (0 or 1), from the first line; refused, naming what is wrong, unless it holds
    every named column and 64 channels (a header may add the ``optional`` numbers)."""
    named = [*labels, *numbers]
    expected = len(named) + CHANNELS
    want = ", ".join(named) + ", ch1, …, ch64"
    if not first:
        raise InputError(f"{path}: empty file (a {corpus} file has the columns {want})")
    probe = first[len(named)] if len(first) > len(named) else ""
    if is_number(probe):  # no header: the documented order
        if len(first) != expected:
            raise InputError(f"{path}, line 1: {len(first)} columns; a {corpus} file without "
                             f"a header has {expected} ({want})")
        return [*named, *(f"ch{k}" for k in range(1, CHANNELS + 1))], 0
    names = [aliases.get(clean_name(c), clean_name(c)) for c in first]
    named += [n for n in optional if n in names]
    seen: set[str] = set()
    for n in names:
        if n in seen:
            raise InputError(f"{path}, line 1: column {n!r} appears twice")
        seen.add(n)
    missing = [n for n in named if n not in seen]
    if missing:
        raise InputError(f"{path}, line 1: no column {', '.join(map(repr, missing))} (a "
                         f"{corpus} file has {want}; this header has "
                         f"{', '.join(names[:6])}{', …' if len(names) > 6 else ''})")
    channels = [n for n in names if n not in named]
    if len(channels) != CHANNELS:
        raise InputError(f"{path}, line 1: {len(channels)} channel columns; {corpus} has "
                         f"{CHANNELS} (an 8 × 8 grid: ch1, …, ch64)")
    numbered = [_CHANNEL_NAME.fullmatch(c) for c in channels]
    if all(numbered):
        for k, m in enumerate(numbered, start=1):
            if int(m.group(1)) != k:  # type: ignore[union-attr]
                raise InputError(f"{path}, line 1: channel column {k} is named "
                                 f"{channels[k - 1]!r}; expected ch1, …, ch64 in order")
    roles = iter(f"ch{k}" for k in range(1, CHANNELS + 1))
    return [n if n in named else next(roles) for n in names], 1


def read_table(path: str | Path, *, labels: Sequence[str], numbers: Sequence[str] = (),
               optional: Sequence[str] = (), aliases: dict[str, str] | None = None,
               corpus: str = "corpus") -> Table:
    """Read a corpus CSV (module docstring): ``labels`` are text columns, ``numbers``
    whole-number columns (CoST's ``frame``), ``optional`` whole-number columns a header
    may name (they are then in :attr:`Table.numbers`), then the 64 channels; ``aliases``
    maps other spellings of a header name (cleaned) to its name. Refused, one line naming
    the line, when the file is not what it claims."""
    pa = require("pyarrow", "export")
    pacsv = require("pyarrow.csv", "export")
    pc = require("pyarrow.compute", "export")
    path = Path(path)
    size = check_regular_file(path)  # a FIFO or a device: one line, never opened
    # the engine's columns, the float32 readings and their copy: measured 4.4× the file
    # (benchmarks/corpora.py: 936 MiB for 213 MB); refused before reading when over budget
    check_budget(READ_FACTOR * size, f"reading {path} ({human_bytes(size)} of CSV)")
    roles, header = _columns(path, _first_line(path), labels, numbers, aliases or {}, corpus,
                             optional)
    numbers = [*numbers, *(n for n in optional if n in roles)]
    internal = [f"c{i}" for i in range(len(roles))]  # the file's own names may repeat
    # whole numbers are read as float64 so that a copy writing 12.0 (MATLAB's export) reads
    types = {c: (pa.string() if r in labels else pa.float64() if r in numbers
                 else pa.float32()) for c, r in zip(internal, roles)}
    convert = pacsv.ConvertOptions(column_types=types, strings_can_be_null=False,
                                   quoted_strings_can_be_null=False)

    def read(threads: bool, handler: Callable | None = None,
             include: list[str] | None = None, as_text: bool = False):
        opts = convert if not as_text else pacsv.ConvertOptions(
            column_types={c: pa.string() for c in internal}, include_columns=include)
        return pacsv.read_csv(path, read_options=pacsv.ReadOptions(
            column_names=internal, skip_rows=header, use_threads=threads,
            block_size=1 << 24),
            parse_options=pacsv.ParseOptions(invalid_row_handler=handler),
            convert_options=opts)

    bad_rows: list = []

    def first_bad(row) -> str:
        bad_rows.append(row)
        return "error"

    try:
        table = read(True, first_bad)
    except pa.ArrowInvalid as exc:
        if bad_rows:
            raise _ragged(path, header, read, len(roles), corpus) from None
        m = _CONVERSION.search(str(exc))
        if m is None:
            raise InputError(f"{path}: not a {corpus} CSV file: {str(exc)[:160]}") from None
        column, value = int(m.group(1)), m.group(2)
        text = read(True, include=[internal[column]], as_text=True).column(0)
        row = pc.index(pc.utf8_trim_whitespace(text), value.strip()).as_py()
        what = roles[column]
        line = f"{path}, line {line_of(path, header, row)}" if row >= 0 else str(path)
        raise InputError(f"{line}: {what} value {value.strip()!r} is not "
                         f"{'a whole number' if what in numbers else 'a number'}") from None
    except (UnicodeDecodeError, OSError) as exc:
        raise InputError(f"{path}: cannot read it as CSV text: {exc}") from None
    if table.num_rows == 0:
        raise InputError(f"{path}: no rows of data")
    return _gather(Table(path, header, {}, {}, np.empty((0, CHANNELS), np.float32)),
                   table, internal, roles, labels, numbers)


def _ragged(path: Path, header: int, read: Callable, width: int, corpus: str) -> InputError:
    """The line whose field count is not the file's (read again on one thread, where the
    engine numbers the rows)."""
    found: list = []

    def note(row) -> str:
        found.append(row)
        return "error"

    try:
        read(False, note)
    except Exception:  # noqa: BLE001 - the row was noted; the engine's own error is not needed
        pass
    row = found[0] if found else None
    # the engine numbers the file's non-blank lines, the header among them
    line = "" if row is None or row.number is None else \
        f", line {line_of(path, 0, row.number - 1)}"
    got = "?" if row is None else row.actual_columns
    return InputError(f"{path}{line}: {got} fields; every {corpus} row has {width} "
                      f"({'truncated?' if row is not None and got < width else 'a stray comma?'})")


def _gather(out: Table, table, internal: list[str], roles: list[str],
            labels: Sequence[str], numbers: Sequence[str]) -> Table:
    """The table's columns as arrays, checked: no empty label, no missing reading."""
    pc = require("pyarrow.compute", "export")
    n = table.num_rows
    for c, r in zip(internal, roles):
        if r in labels:
            text = pc.utf8_trim_whitespace(table.column(c).combine_chunks())
            empty = pc.index(text, "").as_py()
            if empty >= 0:
                raise InputError(f"{out.where(empty)}: empty {r}")
            enc = text.dictionary_encode()
            out.labels[r] = (enc.indices.to_numpy(zero_copy_only=False).astype(np.int32),
                             [str(v) for v in enc.dictionary.to_pylist()])
        elif r in numbers:
            col = table.column(c)
            if col.null_count:
                row = int(np.flatnonzero(pc.is_null(col).to_numpy(zero_copy_only=False))[0])
                raise InputError(f"{out.where(row)}: empty {r}")
            number = col.to_numpy()
            whole = np.isfinite(number) & (number == np.round(number))
            if not whole.all():
                row = int(np.flatnonzero(~whole)[0])
                raise InputError(f"{out.where(row)}: {r} value {number[row]:g} is not a whole "
                                 f"number")
            out.numbers[r] = number.astype(np.int64)
    channels = [c for c, r in zip(internal, roles) if r not in labels and r not in numbers]
    by_channel = np.empty((CHANNELS, n), dtype=np.float32)  # filled a column at a time
    for k, c in enumerate(channels):
        col = table.column(c)
        if col.null_count:
            row = int(np.flatnonzero(pc.is_null(col).to_numpy(zero_copy_only=False))[0])
            raise InputError(f"{out.where(row)}: ch{k + 1} is empty or NaN (every reading "
                             f"is a number)")
        by_channel[k] = col.to_numpy()
    del table
    values = np.ascontiguousarray(by_channel.T)  # (F, 64): one blocked copy
    del by_channel
    if not np.isfinite(values).all():
        row, k = (int(i) for i in np.argwhere(~np.isfinite(values))[0])
        raise InputError(f"{out.where(row)}: ch{k + 1} is {values[row, k]} (readings must be "
                         f"finite)")
    out.values = values
    return out


def captures_at(starts: np.ndarray, n_rows: int) -> np.ndarray:
    """``(C + 1,)`` row offsets of captures beginning at ``starts`` (sorted, from 0)."""
    return np.concatenate([starts, [n_rows]]).astype(np.int64)


def first_repeat(keys: np.ndarray) -> tuple[int, int] | None:
    """The first pair ``(earlier, later)`` of equal rows of ``keys`` ``(C, k)``, or None."""
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    repeated = np.flatnonzero(first[inverse] != np.arange(len(keys)))
    if repeated.size == 0:
        return None
    later = int(repeated[0])
    return int(first[inverse[later]]), later


def content_key(paths: Sequence[Path], options: dict) -> str:
    """SHA-256 of the files' bytes (:func:`file_digest`), the reader's version and its
    options (hex)."""
    h = hashlib.sha256(json.dumps({"reader": READER_VERSION, **options},
                                  sort_keys=True).encode())
    for p in paths:
        h.update(bytes.fromhex(file_digest(Path(p))))
    return h.hexdigest()


def file_digest(path: Path) -> str:
    """The SHA-256 of ``path``'s bytes (hex), computed once per version of the file: it
    is kept under ``cache_dir("datasets")/digests``, named by the file's absolute path,
    size, modification time (ns), inode, device and its first and last MiB, so a file
    changed in any of them is hashed again; an unreadable or damaged record is computed
    anew."""
    st = path.stat()
    with path.open("rb") as fh:
        ends = hashlib.sha256(fh.read(1 << 20))
        if st.st_size > 1 << 20:
            fh.seek(max(1 << 20, st.st_size - (1 << 20)))
            ends.update(fh.read(1 << 20))
    stamp = (f"{path.resolve()}\0{st.st_size}\0{st.st_mtime_ns}\0{st.st_ino}\0{st.st_dev}"
             f"\0{ends.hexdigest()}")
    record = cache_dir("datasets") / "digests" / hashlib.sha256(stamp.encode()).hexdigest()[:32]
    try:
        known = record.read_text(encoding="ascii").strip()
        if re.fullmatch(r"[0-9a-f]{64}", known):
            return known
    except (OSError, UnicodeDecodeError):
        pass
    one = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 22), b""):
            one.update(block)
    digest = one.hexdigest()
    try:
        record.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(record, digest + "\n")
    except OSError:  # a read-only cache: hashed again next time, nothing lost
        pass
    return digest


def cached_dataset(kind: str, paths: Sequence[Path], options: dict,
                   build: Callable[[], Dataset], say: Callable[[Dataset], str]) -> Dataset:
    """The dataset ``build()`` makes of ``paths``, converted once into the store under
    ``cache_dir("datasets")/KIND-<content key>`` and read from there after; ``say(dataset)``
    is the one line printed when it is converted (what the reader inferred). A damaged
    entry is made again."""
    for p in paths:
        check_regular_file(Path(p))
    folder = cache_dir("datasets") / f"{kind}-{content_key(paths, options)[:20]}"
    if (folder / "manifest.json").is_file():
        try:
            return Dataset.load(folder)
        except BudgetError:  # too large for this budget: not a damaged entry
            raise
        except (InputError, OSError):  # damaged: made again below
            shutil.rmtree(folder, ignore_errors=True)
    elif folder.exists():  # a leftover without a manifest
        shutil.rmtree(folder, ignore_errors=True)
    dataset = build()
    with atomic_folder(folder) as tmp:  # another process may win the race: fine
        dataset.save(tmp)
    logging.getLogger("tactbench.datasets").warning("tactbench: note: %s", say(dataset))
    return dataset


def inferred(dataset: Dataset) -> str:
    """The one line saying what a reader made of a corpus (a
    :class:`~tactbench.data.dataset.Dataset`): captures, people, gestures, frames per
    capture, rate and the attributes' values."""
    lengths = dataset.lengths()
    counts = np.bincount(dataset.labels, minlength=len(dataset.classes))
    attrs = "; ".join(f"{k}: {', '.join(sorted(set(v)))}"
                      for k, v in dataset.attributes.items())
    periods = np.diff(dataset.samples[0].recording.timestamps)
    return (f"{dataset.name}: {len(dataset)} captures of {len(set(dataset.users))} "
            f"people, {len(dataset.classes)} gestures ({counts.min()}–{counts.max()} "
            f"captures each), {lengths.min()}–{lengths.max()} frames a capture (median "
            f"{float(np.median(lengths)):g}) at {1 / float(np.median(periods)):g} Hz"
            + (f"; {attrs}" if attrs else "") + " (converted once into the store; "
            "tactbench data info shows it again)")
