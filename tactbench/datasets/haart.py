"""HAART, the Human-Animal Affective Robot Touch set: its two challenge files, read as
distributed.

HAART (Cang et al., 2015; the 2015 Social Touch Gesture Challenge's second corpus): 10
participants performed 7 gestures (constant contact without movement, no touch, pat,
rub, scratch, stroke, tickle) on a 10 × 10 pressure sensor (Flagg & MacLean, 2013)
mounted on 3 substrates (firm and flat, foam and flat, foam and curved) under 4 covers
(none, short minkee, long minkee, synthetic fur): 840 captures of 10 s at 54 Hz, trimmed
to the middle 8 s (432 frames) and to the centre 8 × 8 of the grid (for consistency with
CoST), readings 0–1023. The challenge split them by participant into ``training.csv``
(7 participants, 578 captures) and ``testWITHLABELS.csv`` (3 participants, 251). One row
per frame: ``ParticipantID, Substrate, Cover, Gesture, ch1, …, ch64`` (header optional;
names compared without case or stray spaces; a copy whose header adds a ``Frame`` column
is read as CoST's is: a capture also ends where ``frame`` does not follow).

What the reader makes of ``haart:path=FOLDER`` (the folder holding both files):

- a *capture* (one sample) is a run of rows of one participant, substrate, cover and
  gesture; it must have ``frames`` rows (432, the challenge's 8 s; ``frames=0`` takes any
  length of ≥ 2);
- ``user`` = participant (``--split users`` leaves people out); attributes
  ``substrate`` and ``cover`` as written, and ``set``: ``training`` or ``test``, the file
  it came from, so ``--split group:set:test=test`` is the challenge's own division, a
  fixed split (the same every run), beside ``--split users``;
- ``class`` = the gesture, one of :data:`GESTURES` (any case; ``press``, ``contact`` and
  ``constant`` are one, as are ``notouch``, ``no touch`` and ``no-touch``);
- the 64 channels are an 8 × 8 grid ``pitch_mm`` apart (10 mm by default: the reader's
  assumption), row-major as CoST's; timestamps are ``frame / 54`` s; normalised with
  ``fixed:scale=1023``.

Refused, one line naming the file and line or capture: what the CoST reader refuses
(:mod:`tactbench.datasets.cost`), a capture of another length than ``frames``, and the
same participant, substrate, cover and gesture captured twice (in one file or across
both: a duplicated capture). Converted once into the store, keyed by both files' SHA-256.
"""

from __future__ import annotations

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
from tactbench.errors import InputError, MissingFileError, check_positive_float, \
    check_positive_int

RATE_HZ = 54.0
FRAMES = 432
LABELS = ("participantid", "substrate", "cover", "gesture")
#: The challenge's files and the ``set`` each gives its captures.
FILES = (("training.csv", "training"), ("testWITHLABELS.csv", "test"))
GESTURES = ("constant", "no-touch", "pat", "rub", "scratch", "stroke", "tickle")
_ALIASES = {"press": "constant", "contact": "constant",
            "contactwithoutmovement": "constant", "notouch": "no-touch", "none": "no-touch"}
_HEADER_ALIASES = {"participant": "participantid", "participant id": "participantid",
                   "participant_id": "participantid", "subject": "participantid"}
NORMALISATION = "fixed:scale=1023"


def gesture_name(text: str) -> str | None:
    """HAART's name of a gesture as written (any case, spaces or dashes), or None."""
    word = re.sub(r"[^a-z]", "", text.lower())
    for name in GESTURES:
        if word == name.replace("-", ""):
            return name
    return _ALIASES.get(word)


def files_in(folder: Path) -> list[Path]:
    """The two challenge files of ``folder`` (names matched without case)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingFileError(f"{folder}: no such folder (haart:path= names the folder "
                               f"holding {FILES[0][0]} and {FILES[1][0]})")
    present = {p.name.lower(): p for p in folder.iterdir()}
    out = []
    for name, _ in FILES:
        if name.lower() not in present:
            raise MissingFileError(f"{folder}: no {name} (HAART's challenge files are "
                                   f"{FILES[0][0]} and {FILES[1][0]})")
        out.append(present[name.lower()])
    return out


def is_haart_folder(folder: Path) -> bool:
    """Whether ``folder`` holds both challenge files (names matched without case)."""
    names = {p.name.lower() for p in Path(folder).iterdir()}
    return all(name.lower() in names for name, _ in FILES)


def _captures(table: Table, frames: int) -> np.ndarray:
    """``(C + 1,)`` row offsets: a new capture wherever a label changes (or, in a file
    with a ``frame`` column, where it does not follow the previous row's); each of
    ``frames`` rows (any ≥ 2 when 0), else refused naming the capture."""
    new = np.zeros(max(table.n_rows - 1, 0), dtype=bool)
    if "frame" in table.numbers:
        new |= np.diff(table.numbers["frame"]) != 1
    for name in LABELS:
        new |= np.diff(table.labels[name][0]) != 0
    offsets = captures_at(np.concatenate([[0], np.flatnonzero(new) + 1]), table.n_rows)
    lengths = np.diff(offsets)
    wrong = np.flatnonzero(lengths != frames) if frames else np.flatnonzero(lengths < 2)
    if wrong.size:
        c = int(wrong[0])
        want = f"{frames} (8 s at 54 Hz; frames=0 takes any)" if frames else "≥ 2"
        extra = (f": {lengths[c] // frames} captures of the same participant, substrate, "
                 f"cover and gesture one after the other (duplicated?)"
                 if frames and lengths[c] % frames == 0 else "")
        raise InputError(f"{table.where(int(offsets[c]))}: capture {c + 1} has "
                         f"{int(lengths[c])} frames; HAART's have {want}{extra}")
    return offsets


def read_haart(folder: str | Path, *, frames: int = FRAMES, pitch_mm: float = 10.0,
               name: str | None = None) -> Dataset:
    """Read HAART's ``training.csv`` and ``testWITHLABELS.csv`` from ``folder`` (see the
    module docstring), without the store's cache; errors name the file and line or
    capture."""
    frames = check_positive_int(frames, "haart option frames", minimum=0)
    layout = TaxelLayout.grid(8, 8, check_positive_float(pitch_mm, "pitch_mm"),
                              name="haart-8x8")
    found: list[tuple[tuple[str, ...], str, Path, int, Recording]] = []
    for path, (_, set_name) in zip(files_in(Path(folder)), FILES):
        table = read_table(path, labels=LABELS, optional=("frame",), aliases=_HEADER_ALIASES,
                           corpus="HAART")
        codes, names = table.labels["gesture"]
        for k, text in enumerate(names):
            if gesture_name(text) is None:
                raise InputError(f"{table.where(int(np.argmax(codes == k)))}: gesture "
                                 f"{text!r} is not one of HAART's 7 ({', '.join(GESTURES)})")
        offsets = _captures(table, frames)
        for c, (a, b) in enumerate(zip(offsets[:-1].tolist(), offsets[1:].tolist())):
            key = tuple(table.labels[n][1][table.labels[n][0][a]] for n in LABELS)
            frame = table.numbers.get("frame")
            ticks = np.arange(b - a) if frame is None else frame[a:b] - frame[a]
            rec = Recording(table.values[a:b], ticks / RATE_HZ, layout.ids)
            found.append((key, set_name, path, c + 1, rec))
    _refuse_repeats(found)
    present = {gesture_name(k[3]) for k, *_ in found}
    classes = tuple(g for g in GESTURES if g in present)
    samples = [Sample(rec, classes.index(gesture_name(key[3])), user=key[0],
                      source=f"{path.name}#capture{c}",
                      attributes={"substrate": key[1], "cover": key[2], "set": set_name})
               for key, set_name, path, c, rec in found]
    return Dataset(name or "haart", samples, classes, layout, NORMALISATION,
                   description=f"HAART captures from {folder}")


def _refuse_repeats(found: list) -> None:
    """The same participant, substrate, cover and gesture twice is a duplicated capture."""
    keys = [(k[0], k[1], k[2], gesture_name(k[3])) for k, *_ in found]
    index = {key: i for i, key in enumerate(dict.fromkeys(keys))}
    pair = first_repeat(np.array([[index[k]] for k in keys], dtype=np.int64))
    if pair is None:
        return
    (key, _, path_a, ca, _), (_, _, path_b, cb, _) = found[pair[0]], found[pair[1]]
    raise InputError(f"{path_b.name}, capture {cb}: participant {key[0]}, substrate "
                     f"{key[1]}, cover {key[2]}, gesture {key[3]} again (first as "
                     f"{path_a.name} capture {ca}): a duplicated capture"
                     + (" (if the test file numbers its participants anew, they are not "
                        "the training file's people: give them other IDs)"
                        if path_a != path_b else ""))


class HAART:
    """Registered dataset ``haart``: ``haart:path=FOLDER[,frames=432,pitch_mm=10]``: both
    challenge files read once, then from the store (module docstring)."""

    def __init__(self, path: str, frames: int = FRAMES, pitch_mm: float = 10.0,
                 name: str | None = None, cache: bool = True) -> None:
        self.path, self.name, self.cache = Path(path), name, bool(cache)
        self.frames = check_positive_int(frames, "haart option frames", minimum=0)
        self.pitch_mm = check_positive_float(pitch_mm, "haart option pitch_mm")

    def load(self) -> Dataset:
        def build() -> Dataset:
            return read_haart(self.path, frames=self.frames, pitch_mm=self.pitch_mm,
                              name=self.name)

        if not self.cache:
            return build()
        return cached_dataset("haart", files_in(self.path),
                              {"frames": self.frames, "pitch_mm": self.pitch_mm,
                               "name": self.name or "haart"}, build, inferred)
