"""The CySkin acquisition text format (``cyskin_acquisition --buffer file``).

::

    56560 56561 ... 56435            ← line 1: taxel ids (module_id * 16 + slot)
    0 0.000000 38 135 0 ...          ← frame_index timestamp_s v_1 ... v_N
    1 0.100177 35 75 0 ...

A folder of such files with one sub-folder per class (``0_finger/``,
``1_finger/``, …) is a dataset: the class is the folder name, sorted; a single
file is a one-sample dataset whose class is its folder's name.

Reading is strict: an empty file, a bad header, taxel ids outside 0..2**63-1,
ragged or truncated rows, non-numeric values, infinite values or values beyond
float32's range, duplicate taxel ids and timestamps that go backwards each raise
:class:`~tactbench.errors.InputError` naming the file, the line, the field and the
problem. Row lengths are checked against the header before anything is allocated,
and the values' memory (frames × taxels, and for a folder every file's) is checked
against :func:`tactbench.budget.check_budget` first (a
:class:`~tactbench.errors.BudgetError` beyond it).
``nan`` in a reading marks a missing taxel: kept as NaN (counted by
``tactbench data info``), not an error. Writing and reading back is exact.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from tactbench.budget import check_budget, memory_budget_bytes
from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample
from tactbench.errors import InputError, MissingFileError
from tactbench.integrity import check_regular_file, special_file_problem
from tactbench.paths import atomic_write_text

SUFFIX = ".txt"
#: CySkin text values are baseline-removed raw counts, non-negative; the scale
#: is estimated from the data (a high percentile), as no fixed range is known.
NORMALISATION = "baseline:low=5,high=99.9"


def read_cyskin_text(path: str | Path) -> Recording:
    """Read one recording (see the module docstring for the format and errors)."""
    return _read(Path(path), held=0)


#: Largest magnitude a reading may have: values are stored as float32.
VALUE_MAX = float(np.finfo(np.float32).max)
#: Taxel ids are stored as int64 and are never negative (``module * 16 + slot``).
ID_MAX = int(np.iinfo(np.int64).max)
#: Bytes one token of a split line costs while it is held (a short str and its pointer).
_TOKEN_BYTES = 64


def _read(path: Path, held: int) -> Recording:
    """Read ``path`` in two streamed passes: the first checks the header and every row's
    field count and sizes the arrays (nothing is allocated for a malformed file, and the
    memory budget is asked first); the second parses the numbers into them. ``held``
    bytes of earlier files of the same dataset count against the budget too."""
    check_regular_file(path)  # a FIFO or a device: one line, never opened
    ids: np.ndarray | None = None
    n_rows = 0
    blank: int | None = None  # first blank line after the last non-blank one
    # A small file's rows are kept from the first pass (at most _CHUNK_TOKENS tokens)
    kept: list[tuple[int, list[str]]] | None = []
    kept_tokens = 0
    for lineno, line in _lines(path):
        if ids is not None and kept is None:  # a large file: count, keep nothing
            n_fields = _count_fields(line)
            toks = None
        else:
            toks = line.split()
            n_fields = len(toks)
        if not n_fields:
            blank = blank or lineno
            continue
        if ids is None:
            if blank is not None:
                raise InputError(f"{path}, line 1: empty header (expected the taxel ids)")
            ids = _header(path, toks)
        else:
            if blank is not None:
                _ragged(path, blank, 0, ids.size)
            if n_fields != ids.size + 2:
                _ragged(path, lineno, n_fields, ids.size)
            n_rows += 1
            if kept is not None:
                kept_tokens += n_fields
                kept = kept if kept_tokens <= _CHUNK_TOKENS else None
                if kept is not None:
                    kept.append((lineno, toks))
        blank = None
    if ids is None:
        raise InputError(f"{path}: empty file (expected a line of taxel ids, then frames)")
    if n_rows == 0:
        raise InputError(f"{path}: no frames after the header")
    n = int(ids.size)
    # values (float32), the reader's checks on them (bool) and the timestamps
    check_budget(held + n_rows * n * 5 + n_rows * 16,
                 f"{path}: {n_rows} frames × {n} taxels")
    values = np.empty((n_rows, n), dtype=np.float32)
    ts = np.empty(n_rows, dtype=np.float64)
    chunk_rows = max(1, _CHUNK_TOKENS // (n + 2))
    k = 0
    linenos: list[int] = []
    chunk: list[list[str]] = []
    rows = kept if kept is not None else ((lineno, line.split()) for lineno, line in
                                          _lines(path))
    for lineno, toks in rows:
        if lineno == 1 or not toks:
            continue
        if len(toks) != n + 2 or k + len(chunk) == n_rows:
            raise InputError(f"{path}, line {lineno}: the file changed while it was read")
        linenos.append(lineno)
        chunk.append(toks)
        if len(chunk) == chunk_rows:
            _parse_rows(path, linenos, chunk, ids, values, ts, k)
            k += len(chunk)
            linenos, chunk = [], []
    _parse_rows(path, linenos, chunk, ids, values, ts, k)
    if k + len(chunk) != n_rows:
        raise InputError(f"{path}: the file changed while it was read")
    return Recording(values, ts, ids)


#: Tokens parsed at once (rows are parsed in chunks of about this many numbers).
_CHUNK_TOKENS = 1 << 18


def _parse_rows(path: Path, linenos: list[int], rows: list[list[str]], ids: np.ndarray,
                values: np.ndarray, ts: np.ndarray, k: int) -> None:
    """Parse consecutive frame lines into ``values[k:]`` and ``ts[k:]``, all at once;
    the first bad row is parsed alone by :func:`_parse_row` for its message."""
    if not rows:
        return
    m, width = len(rows), len(rows[0])
    try:
        block = np.fromiter(map(float, itertools.chain.from_iterable(rows)),
                            dtype=np.float64, count=m * width).reshape(m, width)
        bad = np.zeros(m, dtype=bool)
    except ValueError:
        block, bad = None, None
    if block is not None:
        index, t, vals = block[:, 0], block[:, 1], block[:, 2:]
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(index) | (index != np.round(index)) | ~np.isfinite(t)
            bad |= (np.abs(vals) > VALUE_MAX).any(axis=1)
            prev = np.concatenate([[ts[k - 1] if k else -np.inf], t[:-1]])
            bad |= t < prev
    if block is None or bad.any():
        for i in range(m):  # the first bad row raises
            _parse_row(path, linenos[i], rows[i], ids, values[k + i], ts, k + i)
        raise AssertionError("a chunk failed but none of its rows did")  # a bug, not input
    values[k:k + m] = vals
    ts[k:k + m] = t


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` for each line, streamed; a non-ASCII byte is an InputError."""
    # One line's tokens are held at a time: refuse a line they would not fit.
    longest = 2 * (memory_budget_bytes() // _TOKEN_BYTES)
    try:
        with open(path, encoding="ascii", errors="strict") as f:
            for lineno, line in enumerate(f, start=1):
                if len(line) > longest:
                    check_budget(_TOKEN_BYTES * (len(line) // 2 + 1),
                                 f"{path}, line {lineno}: a line of {len(line)} characters")
                yield lineno, line
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a CySkin text file (non-ASCII byte at offset "
                         f"{_first_non_ascii(path)})") from None


def _count_fields(line: str) -> int:
    """``len(line.split())`` without making the tokens (one field per single space when
    the line has no other whitespace, else split)."""
    text = line.strip()
    if text.isprintable() and "  " not in text:
        return text.count(" ") + 1 if text else 0
    return len(text.split())


def _first_non_ascii(path: Path) -> int:
    offset = 0
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            bad = next((k for k, byte in enumerate(block) if byte > 127), None)
            if bad is not None:
                return offset + bad
            offset += len(block)
    return -1  # not reached: only called after a decode error


def _header(path: Path, toks: list[str]) -> np.ndarray:
    """The taxel ids of line 1: integers in 0..2**63-1, unique."""
    try:
        ids = [int(tok) for tok in toks]
        if min(ids) < 0 or max(ids) > ID_MAX:
            raise ValueError
    except ValueError:
        for col, tok in enumerate(toks):  # the first bad field, for the message
            where = f"{path}, line 1, field {col + 1}"
            try:
                value = int(tok)
            except ValueError:
                if not tok.lstrip("+-").isdigit():  # else: too many digits for int()
                    raise InputError(f"{where}: the header must list integer taxel ids, "
                                     f"found {_show(tok)}") from None
                value = -1 if tok.startswith("-") else ID_MAX + 1
            if not 0 <= value <= ID_MAX:
                raise InputError(f"{where}: taxel id {_show(tok)} is out of range "
                                 f"(0 to 2**63-1)") from None
        raise  # not reached: some field failed above
    arr = np.array(ids, dtype=np.int64)
    uniq, counts = np.unique(arr, return_counts=True)
    if uniq.size != arr.size:
        dup = uniq[counts > 1]
        first: dict[int, int] = {}
        col, again = next((first[v], k) for k, v in enumerate(ids)
                          if first.setdefault(v, k) != k)
        raise InputError(f"{path}, line 1, field {again + 1}: duplicate taxel id "
                         f"{ids[again]} (also field {col + 1}); duplicate id(s): "
                         f"{', '.join(map(str, dup[:8]))}")
    return arr


def _ragged(path: Path, lineno: int, got: int, n: int) -> None:
    what = "truncated or ragged row" if got < n + 2 else "too many values"
    raise InputError(f"{path}, line {lineno}: {what}: expected {n + 2} fields "
                     f"(frame index, timestamp, {n} values), got {got}")


def _parse_row(path: Path, lineno: int, toks: list[str], ids: np.ndarray,
               out: np.ndarray, ts: np.ndarray, k: int) -> None:
    """Parse one frame line into ``out`` (its values) and ``ts[k]``, checking each field."""
    where = f"{path}, line {lineno}"
    try:
        row = np.fromiter(map(float, toks), dtype=np.float64, count=len(toks))
    except ValueError:
        col = next(i for i, tok in enumerate(toks) if not _is_float(tok))
        raise InputError(f"{where}, field {col + 1}: {_show(toks[col])} is not "
                         f"a number") from None
    index, t = row[0], row[1]
    if not np.isfinite(index) or index != np.round(index):
        raise InputError(f"{where}, field 1: frame index {_show(toks[0])} is not an integer")
    if not np.isfinite(t):
        raise InputError(f"{where}, field 2: timestamp {_show(toks[1])} is not finite")
    if k and t < ts[k - 1]:
        raise InputError(f"{where}, field 2: timestamp {t:.6f} s goes backwards "
                         f"(previous {ts[k - 1]:.6f} s)")
    values = row[2:]
    big = np.flatnonzero(np.abs(values) > VALUE_MAX)  # NaN (a missing reading) passes
    if big.size:
        col = int(big[0])
        why = ("infinite values are not allowed (write nan for a missing reading)"
               if np.isinf(values[col]) else
               f"out of range (a reading is stored as float32, at most {VALUE_MAX:.3g})")
        raise InputError(f"{where}, field {col + 3}: taxel {ids[col]} reads "
                         f"{_show(toks[col + 2])}; {why}")
    ts[k] = t
    out[:] = values


def _show(tok: str, limit: int = 40) -> str:
    """A token for an error line, quoted, cut to ``limit`` characters."""
    return repr(tok if len(tok) <= limit else tok[:limit] + "…")


def write_cyskin_text(recording: Recording, path: str | Path, *,
                      frame_indices: np.ndarray | None = None) -> None:
    """Write ``recording`` in the CySkin text format, exactly.

    Whole-number values are written as integers; others, and timestamps,
    with the shortest text that reads back to the same float. Frame indices
    default to 0, 1, 2, … The file is replaced atomically.
    """
    idx = np.arange(recording.n_frames) if frame_indices is None else frame_indices
    lines = [" ".join(str(int(t)) for t in recording.taxel_ids)]
    for k in range(recording.n_frames):
        vals = recording.values[k]
        parts = [str(int(idx[k])), _fmt(float(recording.timestamps[k]))]
        parts.extend(_fmt32(v) for v in vals.tolist())
        lines.append(" ".join(parts))
    atomic_write_text(path, "\n".join(lines) + "\n")  # ASCII: ids and numbers only


def _fmt(x: float) -> str:
    return repr(x)


def _fmt32(x: float) -> str:
    if x != x:
        return "nan"
    if float(x).is_integer():
        return str(int(x))
    return repr(float(np.float32(x)))


def _is_float(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def read_cyskin_folder(path: str | Path, *, name: str | None = None,
                       progress: Callable[[int, int], None] | None = None) -> Dataset:
    """A dataset from a CySkin text file, or a folder of class folders of them.

    The class of a file is the name of the folder it is in (classes sorted
    by name); ``repetition`` numbers the files of a class in name order;
    ``user`` and ``position`` are unknown (empty); ``source`` is the file's
    path relative to ``path``. All files must have the same taxel ids. The
    dataset has no layout (none was published for these modules).
    """
    path = Path(path)
    if path.is_file():
        files = [path]
        root = path.parent
    elif path.is_dir():
        found = sorted(path.rglob(f"*{SUFFIX}"))
        for p in found:  # a FIFO, a device or a dangling link: named, never left out
            if (problem := special_file_problem(p)) and "is a folder" not in problem:
                raise InputError(f"{problem} (inside the dataset folder {path})")
        files = [p for p in found if p.is_file()]
        root = path
        if not files:
            raise InputError(f"{path}: no CySkin text files (*{SUFFIX}) in this folder")
    else:
        raise MissingFileError(f"{path}: no such file or folder")
    class_of = [f.parent.name if f.parent != root or path.is_file() else root.name
                for f in files]
    classes = sorted(set(class_of))
    samples = []
    counter: dict[str, int] = {}
    held = 0  # bytes of values already read: the budget covers the whole dataset
    for k, (f, cls) in enumerate(zip(files, class_of)):
        rec = _read(f, held)
        held += rec.values.nbytes
        if samples and not np.array_equal(rec.taxel_ids, samples[0].recording.taxel_ids):
            raise InputError(f"{f}: its taxel ids differ from those of {files[0]} "
                             f"({rec.n_taxels} vs {samples[0].recording.n_taxels} taxels); "
                             f"all files of a dataset must list the same taxels")
        counter[cls] = counter.get(cls, 0) + 1
        rel = f.relative_to(root).as_posix() if path.is_dir() else f.name
        samples.append(Sample(rec, classes.index(cls), user="", position="",
                              repetition=counter[cls], source=rel))
        if progress is not None:
            progress(k + 1, len(files))
    return Dataset(name or (path.stem if path.is_file() else path.name), samples, classes,
                   layout=None, normalisation=NORMALISATION,
                   description=f"CySkin text recordings from {path}")


class CySkinText:
    """Registered dataset ``cyskin-text``: ``cyskin-text:path=FOLDER_OR_FILE``."""

    def __init__(self, path: str, name: str | None = None) -> None:
        self.path = path
        self.name = name

    def load(self, progress: Callable[[int, int], None] | None = None) -> Dataset:
        """The dataset; ``progress(done, total)`` after each file read."""
        return read_cyskin_folder(self.path, name=self.name, progress=progress)
