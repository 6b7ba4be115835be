"""The Corpus of Social Touch (CoST) CSV format.

One row per frame: ``subject, variant, gesture, frame, ch1, …, ch64`` — an
8 × 8 pressure grid sampled at 135 Hz. A capture (one sample) starts wherever
the frame counter restarts (does not increase) or subject, variant or gesture
change. The header row is optional; when present it must name those columns.

Mapping to tactbench: ``user`` = subject, ``position`` = variant (gentle,
normal, rough in CoST), ``class`` = gesture as written in the file (names or
numbers, sorted naturally), ``repetition`` counts the captures of the same
(subject, variant, gesture). Taxel ``ch{k}`` has id ``k - 1`` and sits at row
``(k-1) // 8``, column ``(k-1) % 8`` of a grid with ``pitch_mm`` spacing
(10 mm by default — an assumption, set it for your sensor). Values are 10-bit
(0–1023), normalised with ``fixed:scale=1023``.

The real corpus is not shipped here; the tests write files in this format.
"""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path

import numpy as np

from tactbench.data.dataset import Dataset
from tactbench.data.layout import TaxelLayout
from tactbench.data.recording import Recording, Sample
from tactbench.datasets.array_files import is_number
from tactbench.errors import InputError, check_positive_float
from tactbench.integrity import check_regular_file
from tactbench.paths import atomic_write_text

RATE_HZ = 135.0
GRID = 8
COLUMNS = ["subject", "variant", "gesture", "frame"] + [f"ch{k}" for k in range(1, 65)]
NORMALISATION = "fixed:scale=1023"


def cost_layout(pitch_mm: float = 10.0) -> TaxelLayout:
    """The 8 × 8 grid: id ``k - 1`` for ``ch{k}``, row-major, ``pitch_mm`` apart."""
    return TaxelLayout.grid(GRID, GRID, check_positive_float(pitch_mm, "pitch_mm"),
                            name="cost-8x8")


def _natural(text: str):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]


def read_cost_csv(path: str | Path, *, pitch_mm: float = 10.0, name: str | None = None
                  ) -> Dataset:
    """Read a CoST CSV file (see the module docstring); errors name the line."""
    path = Path(path)
    check_regular_file(path)  # a FIFO or a device: one line, never opened
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    lineno0 = 1
    if not rows or not any(c.strip() for c in rows[0]):
        raise InputError(f"{path}: empty file (expected CoST rows: {', '.join(COLUMNS[:5])}, "
                         f"…, ch64)")
    first = [c.strip().lower() for c in rows[0]]
    if first and not is_number(first[3] if len(first) > 3 else ""):
        if first != COLUMNS:
            raise InputError(f"{path}, line 1: header must be {','.join(COLUMNS[:5])},…,ch64 "
                             f"({len(COLUMNS)} columns); got {len(first)} columns starting "
                             f"{','.join(first[:5])!r}")
        rows = rows[1:]
        lineno0 = 2
    captures: list[tuple[tuple[str, str, str], list[int], list[np.ndarray]]] = []
    prev_key, prev_frame = None, None
    for offset, row in enumerate(rows):
        lineno = lineno0 + offset
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(COLUMNS):
            raise InputError(f"{path}, line {lineno}: expected {len(COLUMNS)} columns "
                             f"(subject, variant, gesture, frame, ch1..ch64), got {len(row)}"
                             f"{' (truncated?)' if len(row) < len(COLUMNS) else ''}")
        subject, variant, gesture = (c.strip() for c in row[:3])
        if not subject or not gesture:
            raise InputError(f"{path}, line {lineno}: empty subject or gesture")
        try:
            frame = int(float(row[3]))
        except ValueError:
            raise InputError(f"{path}, line {lineno}: frame {row[3]!r} is not a number") from None
        try:
            vals = np.array([float(c) for c in row[4:]], dtype=np.float64)
        except ValueError:
            bad = next(i for i, c in enumerate(row[4:]) if not is_number(c))
            raise InputError(f"{path}, line {lineno}: ch{bad + 1} value {row[4 + bad]!r} is "
                             f"not a number") from None
        if not np.all(np.isfinite(vals)):
            bad = int(np.nonzero(~np.isfinite(vals))[0][0])
            raise InputError(f"{path}, line {lineno}: ch{bad + 1} is {row[4 + bad].strip()} "
                             f"(readings must be finite)")
        key = (subject, variant, gesture)
        if key != prev_key or prev_frame is None or frame <= prev_frame:
            captures.append((key, [], []))
        captures[-1][1].append(frame)
        captures[-1][2].append(vals)
        prev_key, prev_frame = key, frame
    if not captures:
        raise InputError(f"{path}: no frames")
    classes = sorted({key[2] for key, _, _ in captures}, key=_natural)
    layout = cost_layout(pitch_mm)
    samples, counter = [], {}
    for key, frames, values in captures:
        counter[key] = counter.get(key, 0) + 1
        f = np.asarray(frames, dtype=np.float64)
        rec = Recording(np.asarray(values, dtype=np.float32), (f - f[0]) / RATE_HZ, layout.ids)
        samples.append(Sample(rec, classes.index(key[2]), user=key[0], position=key[1],
                              repetition=counter[key],
                              source=f"{path.name}#capture{len(samples) + 1}"))
    return Dataset(name or path.stem, samples, classes, layout, NORMALISATION,
                   description=f"CoST captures from {path}")


def write_cost_csv(dataset: Dataset, path: str | Path) -> None:
    """Write a 64-taxel dataset in the CoST CSV format (with a header); the file is
    replaced atomically."""
    if dataset.n_taxels != GRID * GRID:
        raise InputError(f"CoST files hold 64 channels; dataset {dataset.name!r} has "
                         f"{dataset.n_taxels} taxels")
    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow(COLUMNS)
    for s in dataset:
        rec = s.recording
        for k in range(rec.n_frames):
            w.writerow([s.user, s.position, dataset.classes[s.label], k]
                       + [_fmt(v) for v in rec.values[k].tolist()])
    atomic_write_text(path, buf.getvalue())


def _fmt(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else repr(v)


class CoST:
    """Registered dataset ``cost``: ``cost:path=FILE.csv[,pitch_mm=10]``."""

    def __init__(self, path: str, pitch_mm: float = 10.0, name: str | None = None) -> None:
        self.path, self.name = path, name
        self.pitch_mm = check_positive_float(pitch_mm, "cost option pitch_mm")

    def load(self) -> Dataset:
        return read_cost_csv(self.path, pitch_mm=self.pitch_mm, name=self.name)
