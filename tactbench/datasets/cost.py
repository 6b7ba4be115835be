"""The Corpus of Social Touch (CoST): its CSV file, read as distributed.

CoST (Jung et al., 2014; 2017) holds 31 subjects × 14 gestures × 3 variants (gentle,
normal, rough) × 6 repetitions, performed on an 8 × 8 pressure grid wrapped around a
mannequin arm, sampled at 135 Hz with 10-bit readings (0–1023); 7 805 of the 7 812
planned captures were kept, already segmented. One row per frame:
``subject, variant, gesture, frame, ch1, …, ch64`` (header optional; names compared
without case or stray spaces).

What the reader makes of it:

- a *capture* (one sample) is a run of rows of one subject, variant and gesture whose
  ``frame`` values follow one another (``frame`` = previous + 1); a new capture starts
  wherever ``frame`` does not follow the previous row or a label changes;
- ``user`` = subject (``--split users`` leaves people out), the attribute ``variant`` =
  the variant as written (``--split group:variant``), ``repetition`` counts the captures
  of one subject, variant and gesture in file order;
- ``class`` = the gesture: one of the corpus's 14 names (any case), or a number 1–14 read
  as those names in alphabetical order (:data:`GESTURES`: an assumption, as the corpus
  lists them; check it against your copy's key);
- taxel ``ch{k}`` has id ``k - 1`` at row ``(k-1) // 8``, column ``(k-1) % 8`` of a grid
  ``pitch_mm`` apart (10 mm by default: the reader's assumption, set it for the physical
  grid); timestamps are ``(frame - first frame) / 135`` s; normalised with
  ``fixed:scale=1023``.

Refused, one line naming the line or capture: a missing column, a channel count other
than 64, a row with another field count, a reading that is not a finite number, an empty
label, an unknown gesture, a capture of one frame, and a duplicated capture (the same
subject, variant and gesture with the same readings twice). The file is read with
pyarrow (:mod:`tactbench.datasets.touch_csv`), converted once into the store and read
from there after (keyed by the file's SHA-256). The real corpus is not shipped here; the
tests write files in this format.
"""

from __future__ import annotations

import csv
import hashlib
import io
import re
from pathlib import Path

import numpy as np

from tactbench.data.dataset import Dataset
from tactbench.data.layout import TaxelLayout
from tactbench.data.recording import Recording, Sample
from tactbench.datasets.touch_csv import (
    Table,
    cached_dataset,
    captures_at,
    first_repeat,
    inferred,
    read_table,
)
from tactbench.errors import InputError, check_positive_float
from tactbench.paths import atomic_write_text

RATE_HZ = 135.0
GRID = 8
LABELS = ("subject", "variant", "gesture")
COLUMNS = [*LABELS, "frame"] + [f"ch{k}" for k in range(1, 65)]
NORMALISATION = "fixed:scale=1023"
#: The corpus's 14 gestures, in the alphabetical order its description lists them; a
#: gesture written as a number ``k`` is ``GESTURES[k - 1]``.
GESTURES = ("grab", "hit", "massage", "pat", "pinch", "poke", "press", "rub", "scratch",
            "slap", "squeeze", "stroke", "tap", "tickle")
#: Captures per subject, variant and gesture in the corpus's design.
REPETITIONS = 6


def cost_layout(pitch_mm: float = 10.0) -> TaxelLayout:
    """The 8 × 8 grid: id ``k - 1`` for ``ch{k}``, row-major, ``pitch_mm`` apart."""
    return TaxelLayout.grid(GRID, GRID, check_positive_float(pitch_mm, "pitch_mm"),
                            name="cost-8x8")


def gesture_name(text: str) -> str | None:
    """The corpus's name of a gesture written as a name (any case) or a number 1–14;
    None when it is neither."""
    name = text.strip().lower()
    if name in GESTURES:
        return name
    if re.fullmatch(r"\d+(\.0+)?", name) and 1 <= int(float(name)) <= len(GESTURES):
        return GESTURES[int(float(name)) - 1]
    return None


def _classes(table: Table) -> tuple[np.ndarray, tuple[str, ...]]:
    """Each row's class index and the classes (the gestures present, in the corpus's
    order); an unknown gesture is refused at its first line."""
    codes, names = table.labels["gesture"]
    canon = [gesture_name(n) for n in names]
    for k, c in enumerate(canon):
        if c is None:
            row = int(np.argmax(codes == k))
            raise InputError(f"{table.where(row)}: gesture {names[k]!r} is not one of "
                             f"CoST's 14 ({', '.join(GESTURES)}, or 1–14 in that order)")
    classes = tuple(g for g in GESTURES if g in canon)
    lookup = np.array([classes.index(c) for c in canon], dtype=np.int64)  # type: ignore
    return lookup[codes], classes


def segment(table: Table) -> np.ndarray:
    """``(C + 1,)`` row offsets of the captures: a new one wherever a label changes or
    ``frame`` does not follow the previous row's (vectorised over the rows)."""
    frame = table.numbers["frame"]
    new = np.diff(frame) != 1
    for name in LABELS:
        new |= np.diff(table.labels[name][0]) != 0
    return captures_at(np.concatenate([[0], np.flatnonzero(new) + 1]), table.n_rows)


def _check_captures(table: Table, offsets: np.ndarray) -> None:
    """One-frame captures and duplicated captures are refused, naming the capture."""
    lengths = np.diff(offsets)
    if (lengths < 2).any():
        c = int(np.flatnonzero(lengths < 2)[0])
        raise InputError(f"{table.where(int(offsets[c]))}: capture {c + 1} has one frame "
                         f"(frame {int(table.numbers['frame'][offsets[c]])}); a capture is a "
                         f"run of consecutive frame numbers of ≥ 2 frames")
    keys = np.stack([table.labels[n][0][offsets[:-1]] for n in LABELS], axis=1)
    digests = np.array([np.frombuffer(hashlib.blake2b(
        table.values[a:b].tobytes(), digest_size=8).digest(), dtype=np.int64)[0]
        for a, b in zip(offsets[:-1], offsets[1:])], dtype=np.int64)
    pair = first_repeat(np.concatenate([keys.astype(np.int64), lengths[:, None],
                                        digests[:, None]], axis=1))
    if pair is not None:
        a, b = pair
        if np.array_equal(table.values[offsets[a]:offsets[a + 1]],
                          table.values[offsets[b]:offsets[b + 1]]):
            subject, variant, gesture = (table.labels[n][1][keys[b, i]]
                                         for i, n in enumerate(LABELS))
            raise InputError(f"{table.where(int(offsets[b]))}: capture {b + 1} repeats "
                             f"capture {a + 1} (subject {subject}, {variant}, {gesture}: the "
                             f"same {int(lengths[b])} frames of readings); a duplicated "
                             f"capture")


def read_cost_csv(path: str | Path, *, pitch_mm: float = 10.0, name: str | None = None
                  ) -> Dataset:
    """Read a CoST CSV file (see the module docstring), without the store's cache;
    errors name the line or capture."""
    path = Path(path)
    table = read_table(path, labels=LABELS, numbers=("frame",), corpus="CoST")
    offsets = segment(table)
    _check_captures(table, offsets)
    labels, classes = _classes(table)
    layout = cost_layout(pitch_mm)
    (subj, subjects), (var, variants) = table.labels["subject"], table.labels["variant"]
    frame = table.numbers["frame"]
    samples, counter = [], {}
    for c, (a, b) in enumerate(zip(offsets[:-1].tolist(), offsets[1:].tolist())):
        key = (int(subj[a]), int(var[a]), int(labels[a]))
        counter[key] = counter.get(key, 0) + 1
        rec = Recording(table.values[a:b], (frame[a:b] - frame[a]) / RATE_HZ, layout.ids)
        samples.append(Sample(rec, key[2], user=subjects[key[0]], repetition=counter[key],
                              source=f"{path.name}#capture{c + 1}",
                              attributes={"variant": variants[key[1]]}))
    return Dataset(name or path.stem, samples, classes, layout, NORMALISATION,
                   description=f"CoST captures from {path}")


def write_cost_csv(dataset: Dataset, path: str | Path) -> None:
    """Write a 64-taxel dataset in the CoST CSV format (with a header; frames numbered
    from 1 in each capture; the variant is the sample's ``variant`` attribute, else its
    position); the file is replaced atomically."""
    if dataset.n_taxels != GRID * GRID:
        raise InputError(f"CoST files hold 64 channels; dataset {dataset.name!r} has "
                         f"{dataset.n_taxels} taxels")
    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow(COLUMNS)
    for s in dataset:
        rec = s.recording
        variant = s.attributes.get("variant", s.position)
        for k in range(rec.n_frames):
            w.writerow([s.user, variant, dataset.classes[s.label], k + 1]
                       + [_fmt(v) for v in rec.values[k].tolist()])
    atomic_write_text(path, buf.getvalue())


def _fmt(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else repr(v)


class CoST:
    """Registered dataset ``cost``: ``cost:path=CoST.csv[,pitch_mm=10]``: the file read
    once, then from the store (module docstring)."""

    def __init__(self, path: str, pitch_mm: float = 10.0, name: str | None = None,
                 cache: bool = True) -> None:
        self.path, self.name, self.cache = Path(path), name, bool(cache)
        self.pitch_mm = check_positive_float(pitch_mm, "cost option pitch_mm")

    def load(self) -> Dataset:
        def build() -> Dataset:
            return read_cost_csv(self.path, pitch_mm=self.pitch_mm, name=self.name)

        if not self.cache:
            return build()
        return cached_dataset("cost", [self.path],
                              {"pitch_mm": self.pitch_mm, "name": self.name or
                               self.path.stem}, build, inferred)
