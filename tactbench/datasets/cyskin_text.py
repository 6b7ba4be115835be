"""The CySkin acquisition text format (``cyskin_acquisition --buffer file``).

::

    56560 56561 ... 56435            ← line 1: taxel ids (module_id * 16 + slot)
    0 0.000000 38 135 0 ...          ← frame_index timestamp_s v_1 ... v_N
    1 0.100177 35 75 0 ...

A folder of such files with one sub-folder per class (``0_finger/``,
``1_finger/``, …) is a dataset: the class is the folder name, sorted; a single
file is a one-sample dataset whose class is its folder's name.

Reading is strict: an empty file, a bad header, ragged or truncated rows,
non-numeric values, infinite values, duplicate taxel ids and timestamps that go
backwards each raise :class:`~tactbench.errors.InputError` naming the file, the line
and the problem.
``nan`` in a reading marks a missing taxel: kept as NaN (counted by
``tactbench data info``), not an error. Writing and reading back is exact.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample
from tactbench.errors import InputError, MissingFileError

SUFFIX = ".txt"
#: CySkin text values are baseline-removed raw counts, non-negative; the scale
#: is estimated from the data (a high percentile), as no fixed range is known.
NORMALISATION = "baseline:low=5,high=99.9"


def read_cyskin_text(path: str | Path) -> Recording:
    """Read one recording (see the module docstring for the format and errors)."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="ascii")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a CySkin text file (non-ASCII byte at offset "
                         f"{exc.start})") from None
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise InputError(f"{path}: empty file (expected a line of taxel ids, then frames)")
    header = lines[0].split()
    if not header:
        raise InputError(f"{path}, line 1: empty header (expected the taxel ids)")
    try:
        ids = np.array([int(tok) for tok in header], dtype=np.int64)
    except ValueError:
        bad = next(tok for tok in header if not _is_int(tok))
        raise InputError(f"{path}, line 1: the header must list integer taxel ids, found "
                         f"{bad!r}") from None
    uniq, counts = np.unique(ids, return_counts=True)
    if uniq.size != ids.size:
        dup = uniq[counts > 1]
        raise InputError(f"{path}, line 1: duplicate taxel id(s) "
                         f"{', '.join(map(str, dup[:8]))}")
    n = ids.size
    if len(lines) < 2:
        raise InputError(f"{path}: no frames after the header")
    rows = np.empty((len(lines) - 1, n + 2), dtype=np.float64)
    for k, line in enumerate(lines[1:]):
        lineno = k + 2
        toks = line.split()
        if len(toks) != n + 2:
            what = "truncated or ragged row" if len(toks) < n + 2 else "too many values"
            raise InputError(f"{path}, line {lineno}: {what}: expected {n + 2} fields "
                             f"(frame index, timestamp, {n} values), got {len(toks)}")
        try:
            rows[k] = np.array(toks, dtype=np.float64)
        except ValueError:
            col = next(i for i, tok in enumerate(toks) if not _is_float(tok))
            raise InputError(f"{path}, line {lineno}, field {col + 1}: {toks[col]!r} is not "
                             f"a number") from None
    index, ts, values = rows[:, 0], rows[:, 1], rows[:, 2:]
    if not np.all(np.isfinite(index)) or not np.all(index == np.round(index)):
        k = int(np.nonzero(~np.isfinite(index) | (index != np.round(index)))[0][0])
        raise InputError(f"{path}, line {k + 2}: frame index {lines[k + 1].split()[0]!r} is "
                         f"not an integer")
    if not np.all(np.isfinite(ts)):
        k = int(np.nonzero(~np.isfinite(ts))[0][0])
        raise InputError(f"{path}, line {k + 2}: timestamp is not finite")
    back = np.nonzero(np.diff(ts) < 0)[0]
    if back.size:
        k = int(back[0]) + 1
        raise InputError(f"{path}, line {k + 2}: timestamp {ts[k]:.6f} s goes backwards "
                         f"(previous {ts[k - 1]:.6f} s)")
    inf = np.argwhere(np.isinf(values))
    if inf.size:
        k, col = inf[0]
        raise InputError(f"{path}, line {k + 2}: taxel {ids[col]} reads "
                         f"{lines[k + 1].split()[col + 2]!r}; infinite values are not "
                         f"allowed (write nan for a missing reading)")
    return Recording(values.astype(np.float32), ts, ids)


def write_cyskin_text(recording: Recording, path: str | Path, *,
                      frame_indices: np.ndarray | None = None) -> None:
    """Write ``recording`` in the CySkin text format, exactly.

    Whole-number values are written as integers; others, and timestamps,
    with the shortest text that reads back to the same float. Frame indices
    default to 0, 1, 2, … The file is replaced atomically.
    """
    from tactbench.paths import atomic_write_text

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


def _is_int(tok: str) -> bool:
    try:
        int(tok)
        return True
    except ValueError:
        return False


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
        files = sorted(p for p in path.rglob(f"*{SUFFIX}") if p.is_file())
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
    for k, (f, cls) in enumerate(zip(files, class_of)):
        rec = read_cyskin_text(f)
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
