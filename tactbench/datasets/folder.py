"""Your own sensor's data: a folder of arrays or CSV files, one file per recording.

The layout most grid and taxel sensors' data already has::

    ROOT/<class>/<recording>.npy | .npz | .csv
    ROOT/<class>/<user>/<recording>.*          (with ``users=folder``)
    ROOT/users.csv                             (optional: recording → user)

What a file may hold (every recording of a dataset alike):

``(T, H, W)`` arrays — a grid
    ``T`` frames of an ``H`` × ``W`` grid (pressure mat, glove, skin patch). The layout
    is the grid itself (:meth:`TaxelLayout.grid`), ``pitch_mm`` apart (default
    :data:`DEFAULT_PITCH_MM`); taxel ``r · W + c`` is row ``r``, column ``c``. Image
    encoders run on it with no layout file.
``(T, N)`` arrays — taxel vectors
    ``T`` frames of ``N`` taxels with no layout (layout-free classifiers such as
    ``taxel-lstm``), or with ``layout=FILE`` (column ``k`` is the file's ``k``-th taxel),
    or ``grid=HxW`` when the columns are a row-major grid.
``.npy``
    one array; ``.npz``: member ``values`` (or its only member) and optionally
    ``timestamps`` ``(T,)`` seconds; no other member is read.
``.csv``
    one frame per row (comma, semicolon or tab separated; an optional header row). With
    ``timestamp_column=NAME`` (a header name, or a 0-based column number) that column
    holds seconds and the others are the taxels; ``nan`` marks a missing reading.

Timestamps come from the file when it has them; otherwise frame ``k`` is at ``k / rate``
(``rate`` in Hz, default :data:`DEFAULT_RATE_HZ`, an assumption shown in the dataset's
description). Users (for ``--split users``): ``users=prefix`` (the file name before the
first ``users_sep``, default ``_``), ``users=folder`` (``ROOT/<class>/<user>/``),
``users=FILE.csv`` (columns ``recording,user``, and optionally ``class``, checked against
the folder), or ``ROOT/users.csv`` when present; otherwise no users. Classes are the
folder names (natural order) or ``classes=a;b;c`` (that order; every name must be a
folder and every folder a name). Normalisation: ``vmin``/``vmax`` (the sensor's range),
``normalisation=SPEC`` (e.g. ``baseline``), or by default 0 to the data's maximum, stored
in the manifest so it is reproducible. Negative readings (baseline-subtracted, shear,
signed sensors) are clipped at 0 by default, since every later stage reads an image
value of 0 as no contact, and one line says so and how to keep the sign (``vmin=`` the
data's minimum).

Every mistake is one :class:`~tactbench.errors.InputError` naming the file (and line).
See ``docs/own-data.md``.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tactbench.budget import check_budget
from tactbench.data.dataset import Dataset
from tactbench.data.layout import TaxelLayout
from tactbench.data.layout_io import load_layout
from tactbench.data.recording import Recording, Sample
from tactbench.datasets.array_files import SUFFIXES, read_array_file
from tactbench.errors import InputError, MissingFileError, check_number, check_positive_float
from tactbench.integrity import check_regular_file, read_npy_header, special_file_problem
#: Grid pitch assumed when none is given: the quick profile's pixel, so one pixel per cell.
DEFAULT_PITCH_MM = 5.0
#: Frame rate assumed for files without timestamps (the study's 10 Hz).
DEFAULT_RATE_HZ = 10.0
#: A mapping recording → user picked up from the dataset's root when present.
USERS_FILE = "users.csv"
#: A taxel pitch is a physical length: between a micrometre and ten metres (1e-300 mm
#: would reach the imaging as a degenerate triangulation).
MIN_PITCH_MM, MAX_PITCH_MM = 1e-3, 1e4
USER_RULES = ("prefix", "folder")


@dataclass
class _Read:
    """One file's frames before they become a Recording."""

    path: Path
    values: np.ndarray      # (T, H, W) or (T, N)
    timestamps: np.ndarray | None


def natural_key(text: str) -> list[Any]:
    """Sort key that puts ``"2"`` before ``"10"`` (and ``"tap2"`` before ``"tap10"``)."""
    return [(0, int(t), "") if t.isdigit() else (1, 0, t.lower())
            for t in re.split(r"(\d+)", text) if t]


# -------------------------------------------------------------------------- the tree


def find_recordings(root: Path, *, users: str | None = None
                    ) -> dict[str, list[Path]]:
    """Class folder name → its recording files (sorted naturally); checks the tree."""
    if not root.exists():
        raise MissingFileError(f"{root}: no such folder")
    if not root.is_dir():
        raise InputError(f"{root}: not a folder (expected ROOT/<class>/<recording>.npy|.npz|.csv)")
    _refuse_special_entries(root)
    stray = sorted(p.name for p in root.iterdir()
                   if p.is_file() and p.suffix.lower() in SUFFIXES and p.name != USERS_FILE)
    if stray:
        raise InputError(f"{root / stray[0]}: a recording outside any class folder; put each "
                         f"recording in ROOT/<class>/ (the folder name is its label)")
    folders = sorted((p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")),
                     key=lambda p: natural_key(p.name))
    if not folders:
        raise InputError(f"{root}: no class folders (expected ROOT/<class>/<recording>"
                         f".npy|.npz|.csv)")
    found: dict[str, list[Path]] = {}
    for folder in folders:
        _check_name(folder, "a class folder's name is its class name")
        if not os.access(folder, os.R_OK | os.X_OK):
            raise InputError(f"{folder}: cannot read this class folder (permission "
                             f"denied)")
        files = []
        for p in folder.rglob("*"):
            if not p.is_file() or p.suffix.lower() not in SUFFIXES \
                    or any(part.startswith(".") for part in p.relative_to(root).parts):
                continue
            depth = len(p.relative_to(folder).parts)
            if users == "folder" and depth != 2:
                raise InputError(f"{p}: with users=folder every recording sits in "
                                 f"ROOT/<class>/<user>/")
            if users != "folder" and depth != 1:
                raise InputError(f"{p}: recordings sit directly in their class folder "
                                 f"(use users=folder for ROOT/<class>/<user>/<recording>)")
            _check_name(p, "recordings are named in results")
            files.append(p)
        if not files:
            raise InputError(f"{folder}: empty class folder (no .npy, .npz or .csv "
                             f"recordings); remove it or add its recordings")
        found[folder.name] = sorted(files, key=lambda p: natural_key(p.relative_to(root)
                                                                      .as_posix()))
    return found


def _refuse_special_entries(root: Path) -> None:
    """A FIFO, a device, a socket or a dangling link anywhere in the tree (hidden names
    aside) is one line naming it: left out, the dataset would silently lose a recording
    (12 of 13, no word); opened, a FIFO blocks and ``/dev/zero`` never ends."""
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [d for d in dirnames if not d.startswith(".")]
        for name in [*dirnames, *filenames]:
            problem = None if name.startswith(".") else \
                special_file_problem(Path(dirpath) / name)
            if problem is not None and "is a folder" not in problem:
                raise InputError(f"{problem} (inside the dataset folder {root}: a "
                                 f"recording must be a regular file; remove it or put the "
                                 f"file there)")


def _check_name(path: Path, why: str) -> None:
    """Refuse a name that is not valid UTF-8 (Python keeps its bytes as surrogates):
    results, reports and CSV files could not be written with it, after the work."""
    try:
        path.name.encode("utf-8")
    except UnicodeEncodeError:
        shown = os.fsencode(path.name).decode("utf-8", "backslashreplace")
        raise InputError(f"{path.parent / shown}: the name is not valid UTF-8 text "
                         f"({why}); rename it") from None
    if any(ord(c) < 32 or ord(c) == 127 for c in path.name):  # a newline breaks reports
        raise InputError(f"{path.parent / ascii(path.name)[1:-1]}: the name holds a "
                         f"control character (a newline, a tab; {why}); rename it")


def _order_classes(found: dict[str, list[Path]], classes: str | None, root: Path) -> list[str]:
    if classes is None:
        return list(found)
    names = [c.strip() for c in str(classes).split(";") if c.strip()]
    if len(set(names)) != len(names):
        raise InputError(f"classes={classes!r} names a class twice")
    missing = [c for c in names if c not in found]
    if missing:
        raise InputError(f"{root / missing[0]}: class {missing[0]!r} (from classes=) has no "
                         f"folder; folders: {', '.join(found)}")
    extra = [c for c in found if c not in names]
    if extra:
        raise InputError(f"{root / extra[0]}: folder {extra[0]!r} is not among classes="
                         f"{';'.join(names)}")
    return names


def _users_of(files: dict[str, list[Path]], root: Path, rule: str | None,
              sep: str) -> dict[Path, str]:
    """Recording file → user name, by the ``users`` rule (see the module docstring)."""
    all_files = [p for ps in files.values() for p in ps]
    if rule is None:
        if not (root / USERS_FILE).is_file():
            return {p: "" for p in all_files}
        rule = str(root / USERS_FILE)
    if rule == "prefix":
        out = {}
        for p in all_files:
            user, found, _ = p.stem.partition(sep)
            if not found or not user:
                raise InputError(f"{p}: users=prefix needs file names like "
                                 f"USER{sep}REST{p.suffix}; this one has no {sep!r}")
            out[p] = user
        return out
    if rule == "folder":
        return {p: p.parent.name for p in all_files}
    return _users_from_csv(Path(rule), files, root)


def _users_from_csv(path: Path, files: dict[str, list[Path]], root: Path) -> dict[Path, str]:
    if not path.is_file():
        if not (root / path).is_file():
            raise MissingFileError(f"{path}: users file not found (users= takes 'prefix', "
                                   f"'folder' or a CSV file recording,user)")
        path = root / path
    try:
        check_regular_file(path, what="users file")  # a FIFO would block
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text CSV file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the users file ({exc.strerror or exc})"
                         ) from None
    rows = [r for r in csv.reader(io.StringIO(text)) if any(c.strip() for c in r)]
    if not rows:
        raise InputError(f"{path}: empty users file (expected a header recording,user)")
    head = [c.strip().lower() for c in rows[0]]
    if "recording" not in head or "user" not in head:
        raise InputError(f"{path}, line 1: header must name columns 'recording' and 'user' "
                         f"(and optionally 'class'), got {','.join(rows[0])!r}")
    i_rec, i_user = head.index("recording"), head.index("user")
    i_cls = head.index("class") if "class" in head else None
    by_key: dict[str, tuple[str, str | None, int]] = {}
    for lineno, row in enumerate(rows[1:], 2):
        if len(row) != len(head):
            raise InputError(f"{path}, line {lineno}: {len(row)} fields, expected {len(head)}")
        rec = row[i_rec].strip().replace("\\", "/")
        entry = (row[i_user].strip(), None if i_cls is None else row[i_cls].strip(), lineno)
        if rec in by_key and by_key[rec][:2] != entry[:2]:
            raise InputError(f"{path}, line {lineno}: recording {rec!r} is listed again "
                             f"(first on line {by_key[rec][2]}) with another "
                             f"{'user' if by_key[rec][0] != entry[0] else 'class'}; "
                             f"list each recording once")
        by_key.setdefault(rec, entry)
    out: dict[Path, str] = {}
    for cls, paths in files.items():
        for p in paths:
            rel = p.relative_to(root).as_posix()
            keys = (rel, rel[: -len(p.suffix)], p.name, p.stem)
            hits = [by_key[k] for k in dict.fromkeys(keys) if k in by_key]
            if len({h[:2] for h in hits}) > 1:
                raise InputError(f"{path}, lines {hits[0][2]} and {hits[1][2]}: {rel} is "
                                 f"listed twice with different users or classes; list "
                                 f"each recording once")
            hit = hits[0] if hits else None
            if hit is None:
                raise InputError(f"{p}: not listed in {path} (a row recording,user with "
                                 f"{rel!r} or {p.stem!r})")
            user, label, lineno = hit
            if label is not None and label != cls:
                raise InputError(f"{path}, line {lineno}: class {label!r} does not match the "
                                 f"folder of {rel} ({cls!r})")
            if not user:
                raise InputError(f"{path}, line {lineno}: empty user for {rel}")
            out[p] = user
    return out


def _parse_grid(text: Any) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", str(text))
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise InputError(f"grid must be ROWSxCOLS such as 8x8, got {text!r}")
    return int(m.group(1)), int(m.group(2))


# -------------------------------------------------------------------------- the reader


def read_folder(root: str | Path, *, pitch_mm: float = DEFAULT_PITCH_MM,
                layout: str | Path | None = None, rate: float | None = None,
                timestamp_column: str | int | None = None, users: str | None = None,
                users_sep: str = "_", grid: str | None = None, vmin: float | None = None,
                vmax: float | None = None, normalisation: str | None = None,
                classes: str | None = None, name: str | None = None,
                progress: Callable[..., None] | None = None) -> Dataset:
    """Read ``ROOT/<class>/<recording>.{npy,npz,csv}`` into a :class:`Dataset`.

    Options are those of the module docstring; ``progress(done, total)`` is called
    after each file.
    """
    root = Path(root)
    pitch = check_number(pitch_mm, "pitch_mm (mm)", minimum=MIN_PITCH_MM, maximum=MAX_PITCH_MM)
    rate_hz = DEFAULT_RATE_HZ if rate is None else check_positive_float(rate, "rate")
    if not users_sep:
        raise InputError("users_sep must not be empty")
    found = find_recordings(root, users=users)
    class_names = _order_classes(found, classes, root)
    user_of = _users_of(found, root, users, str(users_sep))
    grid_shape = None if grid is None else _parse_grid(grid)
    if grid_shape is not None and layout is not None:
        raise InputError("give grid= or layout=, not both")

    total = sum(len(v) for v in found.values())
    _check_total_budget(root, [p for cls in class_names for p in found[cls]])
    reads: list[tuple[int, _Read]] = []
    first: _Read | None = None
    done = 0
    for label, cls in enumerate(class_names):
        for path in found[cls]:
            values, ts = read_array_file(path, timestamp_column=timestamp_column)
            item = _Read(path, values, ts)
            _check_frames(item, first, grid_shape)
            if first is None:
                first = item
            reads.append((label, item))
            done += 1
            if progress is not None:
                progress(done, total)
    assert first is not None  # find_recordings refuses an empty tree

    if grid_shape is not None and len(first.values.shape) == 3:
        raise InputError(f"{first.path}: grid= is for (T, N) taxel vectors; these "
                         f"recordings are (T, H, W) grids already")
    if timestamp_column is not None and not any(
            p.suffix.lower() == ".csv" for ps in found.values() for p in ps):
        raise InputError(f"timestamp_column= names a CSV column, and {root} holds no CSV "
                         f"recordings (an .npz carries its timestamps as a member)")
    frame_shape = first.values.shape[1:]
    if len(frame_shape) == 1 and grid_shape is not None:
        frame_shape = grid_shape
    lay, ids = _layout_of(first, frame_shape, layout, pitch)

    samples: list[Sample] = []
    repetition: dict[tuple[int, str], int] = {}
    for label, item in reads:
        t = item.values.shape[0]
        flat = item.values.reshape(t, -1)
        if item.timestamps is not None:
            ts = item.timestamps - item.timestamps[0] if t else item.timestamps
        else:
            ts = np.arange(t, dtype=np.float64) / rate_hz
        try:
            rec = Recording(flat.astype(np.float32, copy=False), ts, ids)
        except InputError as exc:
            raise InputError(f"{item.path}: {exc}") from None
        user = user_of[item.path]
        repetition[(label, user)] = repetition.get((label, user), 0) + 1
        samples.append(Sample(rec, label, user=user, repetition=repetition[(label, user)],
                              source=item.path.relative_to(root).as_posix()))

    norm = _normalisation(samples, vmin, vmax, normalisation)
    kind = (f"{frame_shape[0]}×{frame_shape[1]} grid, pitch {pitch:g} mm"
            if len(frame_shape) == 2 else
            f"{frame_shape[0]} taxels{' with layout ' + str(layout) if layout else ''}")
    timing = ("timestamps from the files" if all(r.timestamps is not None for _, r in reads)
              else f"{rate_hz:g} Hz{' (assumed)' if rate is None else ''}")
    return Dataset(name or root.resolve().name, samples, class_names, lay, norm,
                   description=f"{len(samples)} recordings ({kind}; {timing}) from {root}")


def _layout_of(first: _Read, frame_shape: tuple[int, ...], layout: str | Path | None,
               pitch: float) -> tuple[TaxelLayout | None, np.ndarray]:
    """``(layout or None, taxel ids)``: a grid is its own layout; ``(T, N)`` vectors take
    ``layout=`` (its ``N`` taxels) or none."""
    if len(frame_shape) == 2:
        if layout is not None:
            raise InputError(f"{first.path}: layout= is for (T, N) taxel vectors; a "
                             f"(T, H, W) grid is its own layout (set pitch_mm)")
        lay = TaxelLayout.grid(*frame_shape, pitch)
        return lay, lay.ids
    if layout is not None:
        lay = load_layout(layout)
        if lay.n_taxels != frame_shape[0]:
            raise InputError(f"{first.path}: {frame_shape[0]} taxels per frame, but layout "
                             f"{layout} has {lay.n_taxels}")
        return lay, lay.ids
    return None, np.arange(frame_shape[0], dtype=np.int64)


def _check_total_budget(root: Path, paths: list[Path]) -> None:
    """The memory budget counts the whole folder, not a file at a time: every recording
    is held while the dataset is built (its values and their float32 copy)."""
    need = sum(_estimated_bytes(p) for p in paths)
    check_budget(need, f"reading the {len(paths)} recordings under {root}")


def _estimated_bytes(path: Path) -> int:
    """Memory a recording takes once read: its numbers (from the npy headers; ~4 bytes a
    CSV field) and their float32 copy. 0 where the file cannot tell (its reader then
    reports the problem)."""
    suffix = path.suffix.lower()
    try:
        if suffix == ".csv":
            return int(path.stat().st_size) * 6  # ≥ 2 bytes a field → 8 + 4 bytes
        if suffix == ".npy":
            with path.open("rb") as fh:
                return _held(read_npy_header(fh), path.stat().st_size)
        if suffix == ".npz":
            total = 0
            with zipfile.ZipFile(path) as zf:
                for info in zf.infolist():
                    if info.filename.endswith(".npy"):
                        with zf.open(info) as fh:
                            total += _held(read_npy_header(fh), info.file_size)
            return total
    except Exception:  # noqa: BLE001 — an estimate only; the reader names the problem
        return 0
    return 0


def _held(header: tuple[Any, ...], available: int) -> int:
    """Bytes an npy array and its float32 copy take, when its file can hold it (a header
    claiming more is the reader's to refuse, naming the file)."""
    shape, _, dtype = header
    count = math.prod(shape)
    if count * dtype.itemsize > available:
        return 0
    return count * (dtype.itemsize + 4)


def _check_frames(item: _Read, first: _Read | None, grid_shape: tuple[int, int] | None) -> None:
    shape = item.values.shape
    if item.values.ndim not in (2, 3):
        raise InputError(f"{item.path}: array of shape {shape}; expected (T, H, W) grid "
                         f"frames or (T, N) taxel vectors")
    if shape[0] == 0 or 0 in shape[1:]:
        raise InputError(f"{item.path}: no frames (shape {shape})")
    if item.values.ndim == 2 and grid_shape is not None \
            and shape[1] != grid_shape[0] * grid_shape[1]:
        raise InputError(f"{item.path}: {shape[1]} values per frame, but grid="
                         f"{grid_shape[0]}x{grid_shape[1]} needs {grid_shape[0] * grid_shape[1]}")
    if first is not None and shape[1:] != first.values.shape[1:]:
        def what(s: tuple[int, ...]) -> str:
            return f"{s[1]}×{s[2]} grid" if len(s) == 3 else f"{s[1]} taxels"

        raise InputError(f"{item.path}: frames of a {what(shape)}, but {first.path} (the "
                         f"first recording) has frames of a {what(first.values.shape)}; "
                         f"every recording must have the same frame shape")


def _normalisation(samples: list[Sample], vmin: float | None, vmax: float | None,
                   spec: str | None) -> str:
    if spec is not None:
        if vmin is not None or vmax is not None:
            raise InputError("give vmin/vmax or normalisation=, not both")
        return str(spec)
    lo = vmin
    hi = vmax
    if lo is None or hi is None:
        finite = [s.recording.values[np.isfinite(s.recording.values)] for s in samples]
        values = np.concatenate([f for f in finite if f.size] or [np.zeros(1, np.float32)])
        if hi is None:
            hi = float(values.max())
        if lo is None:  # a reading of 0 is no contact, the images' 0 (see _say_clipped);
            lo = min(0.0, float(values.min())) if hi <= 0 else 0.0  # unless none is above
            if float(values.min()) < 0 < hi:
                _say_clipped(float(np.mean(values < 0)), float(values.min()), hi)
    for v, what in ((lo, "vmin"), (hi, "vmax")):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{what} must be a finite number, got {v!r}")
    if hi <= lo:
        if vmin is not None or vmax is not None:  # a bound the user gave is never replaced
            given = (f"vmax ({vmax}) must be greater than vmin ({vmin})"
                     if vmin is not None and vmax is not None else
                     f"vmax ({vmax}) must be greater than the smallest reading ({lo:g})"
                     if vmax is not None else
                     f"vmin ({vmin}) must be less than the largest reading ({hi:g})")
            raise InputError(given)
        hi = lo + 1.0  # constant data: any scale maps it to one value
    return f"fixed:offset={float(lo)!r},scale={float(hi - lo)!r}"


def _say_clipped(share: float, lo: float, hi: float) -> None:
    """One line on what was done to negative readings and how to choose otherwise.

    Every stage after the reader takes an image value of 0 as no contact: pixels off the
    skin are 0, a pixel on the skin's edge is dimmed towards 0 by the skin it covers, the
    frame before a recording's first is all 0 for the flow and difference encoders. So a
    reading of 0 (rest, for readings minus a baseline) must image as 0, and a negative
    reading (noise or drift below the baseline, or a baseline taken under contact) is
    clipped there, as pressure above a baseline (what CySkin's own acquisition writes).
    Mapped as signed instead, rest sits above 0 and every dip below the baseline is
    structure the flow follows (``benchmarks/signed.py``); ``vmin=LO`` keeps the sign
    (shear, a signed sensor).
    """
    rest = -lo / (hi - lo)
    logging.getLogger("tactbench.datasets").warning(
        "tactbench: note: %.0f %% of the readings are negative (down to %.4g): clipped at "
        "0, so that rest (a reading of 0) images as no contact; give vmin=%.6g to keep "
        "the sign ([%.4g, %.4g] mapped onto [0, 1], rest at %.2f), or vmin=/vmax= for the "
        "sensor's range (docs/own-data.md)", 100 * share, lo, lo, lo, hi, rest)


class FolderDataset:
    """Registered dataset ``folder``: ``folder:path=ROOT[,pitch_mm=5,users=prefix,...]``.

    See :mod:`tactbench.datasets.folder` for every option.
    """

    def __init__(self, path: str, pitch_mm: float = DEFAULT_PITCH_MM, layout: str | None = None,
                 rate: float | None = None, timestamp_column: str | int | None = None,
                 users: str | None = None, users_sep: str = "_", grid: str | None = None,
                 vmin: float | None = None, vmax: float | None = None,
                 normalisation: str | None = None, classes: str | None = None,
                 name: str | None = None) -> None:
        self.path = str(path)
        self.options = dict(pitch_mm=check_number(pitch_mm, "folder option pitch_mm (mm)",
                                                  minimum=MIN_PITCH_MM, maximum=MAX_PITCH_MM),
                            layout=layout, timestamp_column=timestamp_column, users=users,
                            users_sep=str(users_sep), grid=grid, vmin=vmin, vmax=vmax,
                            normalisation=normalisation, classes=classes, name=name,
                            rate=None if rate is None
                            else check_positive_float(rate, "folder option rate"))
        if grid is not None:
            _parse_grid(grid)

    def load(self, progress: Callable[..., None] | None = None) -> Dataset:
        return read_folder(self.path, progress=progress, **self.options)


def looks_like_folder(path: Path) -> bool:
    """Whether ``path`` is a folder of class folders holding .npy/.npz/.csv recordings."""
    return path.is_dir() and any(
        p.is_file() and p.suffix.lower() in SUFFIXES
        for sub in path.iterdir() if sub.is_dir() for p in sub.rglob("*"))


__all__ = ["read_folder", "FolderDataset", "find_recordings", "read_array_file",
           "looks_like_folder", "natural_key", "DEFAULT_PITCH_MM", "DEFAULT_RATE_HZ",
           "USERS_FILE"]
