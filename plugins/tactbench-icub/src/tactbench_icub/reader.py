"""The iCub grasp dataset's text format, read into a tactbench Dataset of taxel vectors.

One file per grasp, ``<object>_<trial>.txt`` (e.g. ``blue_bear_8.txt``)::

    -10000                                   ← a separator line (the first line)
    20.86 80.62 13.45 0.54 39.61 67.40 35.90 55.54 4.05     ← 9 hand-joint encoders (7-15)
    14.0 15.0 12.0 13.0 11.0                 ← per finger max(255 − reading): not used
    242.0 242.0 241.0 … (12 values)          ← thumb taxels, 8-bit, lower = more pressure
    243.0 … (12)                             ← index
    244.0 … (12)                             ← middle
    242.0 … (12)                             ← ring
    244.0 … (12)                             ← little
    …                                        ← the next time slice: 7 more lines

What a file becomes (a :class:`tactbench.data.recording.Recording`):

- one frame per time slice; values are **pressure = 255 − reading** (so, as everywhere in
  tactbench, more pressure is a larger value; the rest value is about 5–15);
- taxel ids ``12 × finger + k`` (``finger`` 0–4: thumb, index, middle, ring, little;
  ``k`` 0–11), 60 taxels; with ``joints=True`` the 9 joint encoder values follow, in
  degrees as recorded, with ids 107–115 (100 + the iCub joint number);
- timestamps are the slice numbers 0, 1, 2, … (the data give no times and no rate).

A folder of files is a dataset (:func:`read_icub_folder`): the class is the object name
from the file name (classes sorted), ``repetition`` the trial number, ``source`` the file
name; ``user`` and ``position`` are empty (one robot, no user ids: split by class, e.g.
``--split paper``, not by users); there is no taxel layout (a fingertip's 12 taxels sit on
a curved pad; none is published). ``full_coke`` is left out unless ``full_coke=True``: its
author flags it as unreliable. The normalisation is :data:`NORMALISATION` (each taxel's
rest value removed, one scale for all), applied to the joints too when they are included.

Reading is strict: a file that is empty, has no time slice, ends inside a slice, has a
``-10000`` inside a slice, a line with the wrong number of values, a value that is not a
finite number, a reading outside 0–255, or text that is not ASCII raises
:class:`tactbench.errors.InputError` naming the file and the line. A file (or folder)
larger than the memory budget allows (:func:`tactbench.budget.check_budget`) is
refused before it is read, with a :class:`~tactbench.errors.BudgetError`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample
from tactbench.errors import InputError, MissingFileError
from tactbench.budget import check_budget

FINGERS = ("thumb", "index", "middle", "ring", "little")
TAXELS_PER_FINGER = 12
JOINTS = 9
#: iCub hand joints 7-15, stored with ids 100 + joint.
JOINT_IDS = tuple(100 + j for j in range(7, 16))
SEPARATOR = "-10000"
SLICE_LINES = 2 + len(FINGERS)
#: Objects left out unless asked for: the dataset's author calls full_coke unreliable.
UNRELIABLE = ("full_coke",)
READING_MAX = 255.0
NORMALISATION = "baseline:high=99.9,low=5"
FOLDER = "iCubGraspDataset"
_NAME = re.compile(r"^(?P<object>.+)_(?P<trial>\d+)\.txt$")

#: Memory while a file is parsed, per byte of text (the bytes, its lines, float64 values).
PARSE_BYTES_PER_BYTE = 4
#: What each line of a time slice holds, and how many values.
_LINES = (("9 joint encoder values", JOINTS), ("5 per-finger maxima", len(FINGERS))) + tuple(
    (f"12 taxel readings of the {f}", TAXELS_PER_FINGER) for f in FINGERS)


def taxel_ids(joints: bool = False) -> np.ndarray:
    """The ids of a recording's columns (module docstring)."""
    ids = list(range(len(FINGERS) * TAXELS_PER_FINGER))
    return np.array(ids + (list(JOINT_IDS) if joints else []), dtype=np.int64)


def read_icub_file(path: str | Path, *, joints: bool = False) -> Recording:
    """One grasp file → a :class:`Recording` of pressure (and joints); see the module
    docstring for the format and the errors."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such file")
    check_budget(path.stat().st_size * PARSE_BYTES_PER_BYTE, f"reading {path}")
    raw = path.read_bytes()
    if not raw.strip():
        raise InputError(f"{path}: empty file (expected '{SEPARATOR}' and time slices of "
                         f"{SLICE_LINES} lines)")
    frames: list[np.ndarray] = []
    joint_rows: list[np.ndarray] = []
    current: list[np.ndarray] = []
    start = 0  # line number where the current slice began
    lineno = 0
    for lineno, line_bytes in enumerate(raw.splitlines(), start=1):
        try:
            line = line_bytes.decode("ascii")
        except UnicodeDecodeError:
            raise InputError(f"{path}, line {lineno}: not ASCII text; is this an iCub grasp "
                             f"file?") from None
        toks = line.split()
        if not toks:
            continue  # blank lines carry nothing
        if toks == [SEPARATOR]:
            if current:
                raise InputError(f"{path}, line {lineno}: '{SEPARATOR}' inside a time slice "
                                 f"(at its line {len(current) + 1} of {SLICE_LINES}, started "
                                 f"at line {start})")
            continue
        what, count = _LINES[len(current)]
        if len(toks) != count:
            raise InputError(f"{path}, line {lineno}: expected {what} (line "
                             f"{len(current) + 1} of a {SLICE_LINES}-line time slice), "
                             f"found {len(toks)} value(s)")
        values = np.empty(count, dtype=np.float64)
        for i, tok in enumerate(toks):
            try:
                values[i] = float(tok)
            except ValueError:
                raise InputError(f"{path}, line {lineno}: value {i + 1} {tok[:40]!r} is not "
                                 f"a number") from None
            if not np.isfinite(values[i]):
                raise InputError(f"{path}, line {lineno}: value {i + 1} is {tok[:40]!r}, "
                                 f"not a finite number")
        if len(current) >= 2:
            bad = np.flatnonzero((values < 0) | (values > READING_MAX))
            if bad.size:
                raise InputError(f"{path}, line {lineno}: reading {toks[bad[0]]} (value "
                                 f"{bad[0] + 1}) is outside 0–255 (8-bit taxel readings)")
        if not current:
            start = lineno
        current.append(values)
        if len(current) == SLICE_LINES:
            joint_rows.append(current[0])
            frames.append(READING_MAX - np.concatenate(current[2:]))
            current = []
    if current:
        raise InputError(f"{path}, line {lineno}: the file ends inside a time slice (it has "
                         f"{len(current)} of its {SLICE_LINES} lines, from line {start})")
    if not frames:
        raise InputError(f"{path}: no time slice (only '{SEPARATOR}' or blank lines)")
    values = np.stack(frames)
    if joints:
        values = np.concatenate([values, np.stack(joint_rows)], axis=1)
    return Recording(values.astype(np.float32), np.arange(len(frames), dtype=np.float64),
                     taxel_ids(joints))


def _flag(value: Any, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be true or false, got {value!r}")
    return bool(value)


def _files(path: Path) -> tuple[Path, list[tuple[str, int, Path]]]:
    """The folder holding the grasp files and ``(object, trial, file)`` for each."""
    if not path.exists():
        raise MissingFileError(f"{path}: no such folder")
    if not path.is_dir():
        raise InputError(f"{path}: not a folder (give the folder of <object>_<trial>.txt "
                         f"files, or the one holding {FOLDER}/)")
    folder = path / FOLDER if (path / FOLDER).is_dir() else path
    found = []
    seen: dict[tuple[str, int], Path] = {}
    for f in sorted(folder.glob("*.txt")):
        m = _NAME.match(f.name)
        if m is None:
            raise InputError(f"{f}: not named <object>_<trial>.txt (e.g. blue_bear_8.txt); "
                             f"only grasp files belong in {folder}")
        key = (m["object"], int(m["trial"]))
        if key in seen:
            raise InputError(f"{f}: trial {key[1]} of '{key[0]}' is also {seen[key].name}")
        seen[key] = f
        found.append((key[0], key[1], f))
    if not found:
        raise InputError(f"{folder}: no <object>_<trial>.txt grasp files here")
    return folder, sorted(found)


def read_icub_folder(path: str | Path, *, joints: bool = False, full_coke: bool = False,
                     name: str | None = None,
                     progress: Callable[[int, int], None] | None = None) -> Dataset:
    """The dataset in ``path`` (the folder of grasp files, or the one holding
    ``iCubGraspDataset/``); see the module docstring. ``progress(done, total)`` after
    each file."""
    joints = _flag(joints, "joints")
    full_coke = _flag(full_coke, "full_coke")
    folder, found = _files(Path(path))
    left_out = sorted({o for o, _, _ in found if o in UNRELIABLE and not full_coke})
    found = [t for t in found if t[0] not in left_out]
    if not found:
        raise InputError(f"{folder}: only {', '.join(left_out)} files, which are left out "
                         f"unless full_coke=true")
    # The values held (float32) take less than the text; the text's size bounds them.
    check_budget(sum(f.stat().st_size for _, _, f in found),
                 f"reading {len(found)} grasp files in {folder}")
    classes = sorted({o for o, _, _ in found})
    samples = []
    for k, (obj, trial, f) in enumerate(found):
        rec = read_icub_file(f, joints=joints)
        samples.append(Sample(rec, classes.index(obj), user="", position="",
                              repetition=trial, source=f.name))
        if progress is not None:
            progress(k + 1, len(found))
    note = f"; left out: {', '.join(left_out)} (unreliable)" if left_out else ""
    return Dataset(name or "icub-grasp", samples, classes, layout=None,
                   normalisation=NORMALISATION,
                   description=(f"iCub fingertip grasps from {folder}: pressure = 255 − "
                                f"reading, 60 taxels{' + 9 joints' if joints else ''}, "
                                f"no layout, no users{note}"))


class ICubGrasp:
    """Registered dataset ``icub-grasp``:
    ``icub-grasp:path=FOLDER[,joints=true][,full_coke=true]``."""

    def __init__(self, path: str | None = None, joints: bool = False, full_coke: bool = False,
                 name: str | None = None) -> None:
        if path is None:
            raise InputError("icub-grasp needs path=FOLDER (the folder of the iCub grasp "
                             "dataset, e.g. icub-grasp:path=data/icub-grasp)")
        self.path = str(path)
        self.joints = _flag(joints, "joints")
        self.full_coke = _flag(full_coke, "full_coke")
        self.name = name

    def load(self, progress: Callable[[int, int], None] | None = None) -> Dataset:
        """The dataset; ``progress(done, total)`` after each file read."""
        return read_icub_folder(self.path, joints=self.joints, full_coke=self.full_coke,
                                name=self.name, progress=progress)
