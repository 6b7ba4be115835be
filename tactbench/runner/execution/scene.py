"""The run configuration (a *scene*): what to compare, on what, and how to run it.

A scene file (:mod:`~tactbench.runner.execution.scene_files`) holds the same fields as
:class:`Scene`. The window length is ``L`` everywhere (the ``-L`` option, this field,
cell identities, model metadata); a name that changed (``lengths``) is refused with a
line naming the new one.

A :class:`Scene` is frozen and checks itself when it is made, once: every field's type
and range (:func:`check_fields`: ``seeds = [1.5]``, ``encoders = [1]``, ``threads = 0``,
``L = 0``), and what the fields need together without a dataset or the plugins (a
profile, precision, executor and input that exist, a grid of at most
:data:`MAX_CELLS`, a split and test window written in their grammar). What needs the
plugins or the disk (the split's and test window's names, the out folder, the dataset)
is checked once by :func:`tactbench.runner.execution.planning.plan`; neither checks the other's
part again. :meth:`Scene.of` names a refused field as its source does (``--threads``).
A field that only means something with ``until`` (:data:`UNTIL_ONLY`) is refused at
another value than its default without it: the scene's rule, whoever makes the scene.

(The runner's scene is the run configuration; the synthetic flow scenes of
:mod:`tactbench.encoders.evaluation.flowbench` are a different thing with their own name.)
"""

from __future__ import annotations

import itertools
import math
import numbers
import re
from dataclasses import MISSING, dataclass, field, fields
from functools import cached_property
from typing import Any, Iterable, Mapping, Sequence

from tactbench.budget import parse_bytes
from tactbench.data.splits import parse_split
from tactbench.errors import InputError, check_choice
from tactbench.profiles import PRECISIONS, get_profile
from tactbench.runner.execution.system import check_scheduler
from tactbench.specs import parse_spec

#: Where cells run: this machine (serially or in ``workers`` processes) or a dask cluster.
EXECUTORS = ("local", "dask")
#: What ``--input`` may ask a classifier that takes either input for.
INPUT_KINDS = ("images", "vectors")
#: At most this many cells in one run (encoders × classifiers × L × seeds): each trains a
#: model, and a larger grid is a typo (its plan alone would grow without bound).
MAX_CELLS = 10_000
#: The primary comparison of a grid with both encoders when none is named: the study's
#: question, Farnebäck flow against pressure images.
DEFAULT_PRIMARY = "encoder=raw..encoder=farneback"
#: What ``--until`` takes, and the runs before the first look (docs/statistics.md).
UNTIL = ("answered",)
FIRST_LOOK = 5


@dataclass(frozen=True)
class Scene:
    """Everything a run needs to know; a scene file holds the same fields (TOML).

    Frozen, and checked when made (see the module docstring): a ``Scene`` that exists is
    a valid one, and the runner trusts it. The defaults here are the run's, the one place
    they are written: the split ``paper`` and the test window ``vote``.
    """

    dataset: str = "synthetic-forearm"
    encoders: list[str] = field(default_factory=lambda: ["raw", "farneback"])
    classifiers: list[str] = field(default_factory=lambda: ["small-cnn-lstm"])
    L: list[int] = field(default_factory=lambda: [5])  # window lengths, frames
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    split: str = "paper"  # a registered split: paper, users[:folds=K], group:KEY[...], kfold
    test_window: str = "vote"  # a registered test window: vote, onset or first (the study's)
    test_per_class: int = 30
    profile: str = "quick"
    pixel_mm: float | None = None  # None: the profile's
    imaging: str = "linear"
    precision: str | None = None  # storage of cached encodings (PRECISIONS); None: the profile's
    device: str = "cpu"
    # torch threads per cell: fixed, since the thread count changes a cell's numbers (it is
    # in the cell's identity when not 1); a machine's cores are used by cells side by side
    threads: int = 1
    executor: str = "local"
    workers: int | None = None  # cells at once; None: cores, GPUs, memory (workers.py)
    # the run's memory in all, its process and its workers ("4GiB"); None: this machine's
    memory: str | None = None
    scheduler: str | None = None
    out: str = "tactbench-out"
    rerun: bool = False
    save_models: bool = False  # OUT/models/<cell key>.safetensors, usable by `tactbench live`
    # statistics and inputs (docs/statistics.md): an equivalence margin in points; contrasts
    # "A..B"; what a classifier taking either input is fed; init seeds apart from split seeds
    margin: float | None = None
    contrasts: list[str] | None = None
    input: str | None = None  # images or vectors; None: images where there is a layout
    init_seeds: list[int] | None = None
    # the confirmatory comparisons (contrasts "A..B"); None: raw..farneback where the grid
    # has both (Scene.design); and runs added until they are answered (docs/runner.md)
    primary: list[str] | None = None
    until: str | None = None  # "answered": seeds in batches until the primaries are decided
    max_runs: int = 20  # with until: the most runs (seeds) planned
    look_every: int = 5  # with until: the runs added between two looks (the first at 5)
    budget: str | None = None  # with until: no batch begun past this time ("90m", "2h")
    paired_test: str | None = None  # the test of every comparison; None: corrected-t

    def __post_init__(self) -> None:
        checked = check_fields({f.name: getattr(self, f.name) for f in fields(self)})
        for name, value in checked.items():
            object.__setattr__(self, name, value)  # lists copied, lengths parsed
        _check_together(self)

    @classmethod
    def of(cls, values: Mapping[str, Any], *,
           labels: Mapping[str, str] | None = None) -> "Scene":
        """The scene of ``values`` (field → value), a refused field named as ``labels``
        says (``{"threads": "--threads"}``; default ``scene field 'threads'``)."""
        try:
            return cls(**values)
        except FieldError as exc:
            if labels and exc.field in labels:
                raise InputError(f"{labels[exc.field]}{exc.detail}") from None
            raise

    def resolved_pixel_mm(self) -> float:
        """The tactile-image pixel size in mm: the scene's, else its profile's."""
        if self.pixel_mm is not None:
            return float(self.pixel_mm)

        return get_profile(self.profile).pixel_mm

    def memory_mb(self) -> float | None:
        """The run's memory in all (``memory``) in MiB; None: not capped (this machine's).
        A size that is not one, or below 64 MiB, is one line naming the field."""
        if self.memory is None:
            return None
        try:
            nbytes = parse_bytes(self.memory, "memory")
        except InputError:
            raise FieldError("memory", f" must be a size such as 4GiB or 500MiB, got "
                                       f"{_show(self.memory)}") from None
        if nbytes < 64 << 20:
            raise FieldError("memory", f" must be at least 64MiB (a worker's imports "
                                       f"alone take more), got {self.memory!r}")
        return nbytes / (1 << 20)

    def resolved_precision(self) -> str:
        """How cached encodings are stored: the scene's precision, else its profile's."""
        if self.precision is not None:
            return str(self.precision)

        return get_profile(self.profile).precision

    @cached_property
    def design(self) -> "Design":
        """What this scene decides once, before any work (:class:`Design`): computed on
        first use and kept; every look and report reads it."""
        return design_of(self)


#: At most this many window lengths, or seeds, in one run: a range of more
#: (``-L 1-3000000``) is refused before it is expanded.
MAX_LENGTHS = 1000
#: At most this many workers or torch threads (more is a typo, and would start that many).
MAX_WORKERS = 1024
#: The longest text field (a dataset path, a component spec): about a path's limit.
MAX_TEXT = 4096

#: "N" or "A-B" (both ends included), spaces allowed around the numbers; at most 20
#: digits each, so that a number of thousands of digits is refused before ``int()``.
_NUMBER_OR_RANGE = re.compile(r"\s*(-?\d{1,20})\s*(?:-\s*(-?\d{1,20})\s*)?")


def parse_numbers(values: Iterable[str | int], what: str, example: str) -> list[int]:
    """The one reader of the "N or A-B" syntax of ``-L`` and ``--seed`` (and of the scene
    file's ``L`` and ``seeds``): ``[5]``, ``["5"]``, ``["1-6"]``, ``["3", "5-6"]`` → the
    numbers in the order given, each once.

    A value is a whole number (an ``int``, not a ``bool``, or its text) or a range
    ``"A-B"`` with ``A ≤ B``, both ends included; every number fits in 64 bits; all of
    them together are at most :data:`MAX_LENGTHS`, a range's size checked before it is
    expanded. ``what`` names a value in the messages (``"seed"``), ``example`` is a range
    to show (``"0-9"``). Raises :class:`InputError` in one line naming the value.
    """
    out: dict[int, None] = {}
    for value in values:
        m = _NUMBER_OR_RANGE.fullmatch(value) if isinstance(value, str) else None
        if _is_int(value):
            start = stop = int(value)
        elif m is not None:
            start = int(m.group(1))
            stop = int(m.group(2)) if m.group(2) is not None else start
        else:
            raise InputError(f"bad {what} {_show(value)}: use a whole number or a range "
                             f"such as {example}")
        if stop < start:
            raise InputError(f"bad {what} range {_show(value)}: the end is below the start")
        if abs(start) >= 2 ** 63 or abs(stop) >= 2 ** 63:
            raise InputError(f"{what} {_show(value)} is not a 64-bit integer")
        if stop - start + 1 + len(out) > MAX_LENGTHS:
            raise InputError(f"too many {what}s: {_show(value)} is {stop - start + 1} of "
                             f"them; a run takes at most {MAX_LENGTHS}")
        out.update(dict.fromkeys(range(start, stop + 1)))
    return list(out)


def parse_lengths(values: Iterable[str | int]) -> list[int]:
    """Window lengths (:func:`parse_numbers`), sorted: a grid's L are a set, shown in order.

    ``["1-3", "6", "2"]`` → ``[1, 2, 3, 6]``.
    """
    return sorted(parse_numbers(values, "window length", "1-6"))


def parse_seeds(values: Iterable[str | int]) -> list[int]:
    """Seeds (:func:`parse_numbers`) in the order given: ``[5, "0-2", 1]`` → ``[5, 0, 1, 2]``."""
    return parse_numbers(values, "seed", "0-9")


_ALIASES = {"encoder": "encoders", "classifier": "classifiers", "seed": "seeds",
            "contrast": "contrasts", "init_seed": "init_seeds"}
#: Field names that changed: refused with a line naming the new one (no silent aliases).
RENAMED = {"lengths": "L"}

#: What each field holds: text, optional text, list of text, window lengths or seeds
#: ("N or A-B", :func:`parse_numbers`), integer ≥ 1 (optional), number > 0 (optional),
#: or a boolean.
_KINDS: dict[str, str] = {
    "dataset": "text", "encoders": "texts", "classifiers": "texts", "L": "lengths",
    "seeds": "seeds", "split": "text", "test_window": "text", "test_per_class": "count", "profile": "text",
    "pixel_mm": "number?", "imaging": "text", "precision": "text?", "device": "text",
    "threads": "workers", "executor": "text", "workers": "workers?", "memory": "text?",
    "scheduler": "text?",
    "out": "text", "rerun": "bool", "save_models": "bool",
    "margin": "number?", "contrasts": "texts?", "input": "text?", "init_seeds": "seeds?",
    "primary": "texts?", "until": "text?", "max_runs": "count", "look_every": "count",
    "budget": "text?", "paired_test": "text?",
}


def _show(value: Any, limit: int = 60) -> str:
    try:
        text = repr(value)
    except ValueError:  # an int too long to print
        return f"an integer of {value.bit_length()} bits"
    return text if len(text) <= limit else text[:limit - 5] + "…" + text[-4:]


def _is_int(value: Any) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _check_text(value: Any, name: str) -> str:
    if not isinstance(value, str):
        raise InputError(f"{name} must be text, got {type(value).__name__} {_show(value)}")
    if not value.strip():
        raise InputError(f"{name} is empty")
    if "\x00" in value:
        raise InputError(f"{name} contains a NUL character: {_show(value)}")
    if len(value) > MAX_TEXT:
        raise InputError(f"{name} is {len(value)} characters long; at most {MAX_TEXT}")
    return value


def _check_field(name: str, value: Any, label: str) -> Any:
    """``value`` of field ``name`` checked (and, for list fields, made a list)."""
    kind = _KINDS[name]
    if value is None and kind.endswith("?"):
        return None
    kind = kind.rstrip("?")
    if kind == "text":
        return _check_text(value, label)
    if kind in ("lengths", "seeds"):  # "N or A-B", one reader (parse_numbers)
        if not isinstance(value, (list, tuple)):
            value = [value]  # a single value for a list field
        if not value:
            raise InputError(f"{label} is empty")
        example = "1-6" if kind == "lengths" else "0-9"
        for v in value:
            if not (_is_int(v) or isinstance(v, str)):
                raise InputError(f"{label} must be whole numbers or ranges such as "
                                 f"\"{example}\", got {_show(v)} ({type(v).__name__})")
        try:
            return parse_lengths(value) if kind == "lengths" else parse_seeds(value)
        except InputError as exc:
            raise InputError(f"{label}: {exc}") from None
    if kind == "texts":
        if not isinstance(value, (list, tuple, dict)):
            value = [value]  # a single value for a list field
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{label} must be a list, got {type(value).__name__} "
                             f"{_show(value)}")
        if not value:
            raise InputError(f"{label} is empty")
        if len(value) > MAX_LENGTHS:
            raise InputError(f"{label} has {len(value)} values; at most {MAX_LENGTHS}")
        return [_check_text(v, f"{label} entry {i + 1}") for i, v in enumerate(value)]
    if kind in ("count", "workers"):
        if not _is_int(value):
            raise InputError(f"{label} must be a whole number, got {type(value).__name__} "
                             f"{_show(value)}")
        if value < 1:
            raise InputError(f"{label} must be ≥ 1, got {value}")
        if kind == "workers" and value > MAX_WORKERS:
            raise InputError(f"{label} must be at most {MAX_WORKERS}, got {_show(value)}")
        return value
    if kind == "number":
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise InputError(f"{label} must be a number, got {type(value).__name__} "
                             f"{_show(value)}")
        if not (abs(value) < 1e308 and math.isfinite(value) and value > 0):
            raise InputError(f"{label} must be a finite number > 0, got {_show(value)}")
        return value
    assert kind == "bool", kind
    if not isinstance(value, bool):
        raise InputError(f"{label} must be true or false, got {type(value).__name__} "
                         f"{_show(value)}")
    return value


class FieldError(InputError):
    """A scene field's value refused: ``field`` and ``detail``, the message after the
    field's name (``" must be ≥ 1, got 0"``), so that a caller can name the field as its
    source does (:meth:`Scene.of`)."""

    def __init__(self, field: str, detail: str) -> None:
        self.field, self.detail = field, detail
        super().__init__(f"scene field '{field}'{detail}")


def check_fields(values: Mapping[str, Any]) -> dict[str, Any]:
    """Check the type and range of every field of a scene (a :class:`Scene`'s, or a
    scene file's table) and return them normalised: single values of list fields become
    lists, window lengths and seeds are parsed (lengths ≥ 1). Raises :class:`FieldError`
    naming the field."""
    out: dict[str, Any] = {}
    for name, value in values.items():
        label = f"scene field '{name}'"
        try:
            out[name] = _check_field(name, value, label)
            if name == "L" and any(n < 1 for n in out[name]):
                raise InputError(f"{label} must be ≥ 1, got {[n for n in out[name] if n < 1]}")
        except FieldError:
            raise
        except InputError as exc:  # every message of _check_field starts with the label
            raise FieldError(name, str(exc)[len(label):]) from None
    return out


@dataclass(frozen=True)
class Design:
    """What a scene decides once, before any work, and every look and report reads.

    ``primary``: the confirmatory questions (:func:`primary_of`); ``seed_order``: the
    seeds in the order runs are made (the scene's and, with ``until``, the next unused
    whole numbers up to ``max_runs``); ``looks``: the run counts of the looks
    (:func:`schedule`; empty for a run that is not ``--until``); ``budget`` and
    ``budget_seconds``: no batch begun past it (None: none). Made from a :class:`Scene`
    (:attr:`Scene.design`) or from the scene a folder's rows store (:func:`design_of`),
    never by building a scene again.
    """

    primary: tuple[str, ...]
    seed_order: tuple[int, ...]
    looks: tuple[int, ...] = ()
    budget: str | None = None
    budget_seconds: float | None = None

    @property
    def max_runs(self) -> int:
        """The most runs the design makes: its last look's, else every seed's."""
        return self.looks[-1] if self.looks else len(self.seed_order)


def schedule(max_runs: int, look_every: int, first: int = FIRST_LOOK) -> list[int]:
    """The run counts of the looks: ``first``, ``first + look_every``, … up to
    ``max_runs`` (always the last); the scene checked both numbers."""
    return [*range(first, max_runs, look_every), max_runs]


#: The fields a :class:`Design` is made of.
_DESIGN_FIELDS = ("seeds", "until", "max_runs", "look_every", "budget", "primary", "encoders")


def design_of(scene: "Scene | Mapping[str, Any]") -> Design:
    """The :class:`Design` of a scene, or of its fields as a row stores them: read back,
    so the fields the design needs are checked (no :class:`Scene` is built again); a
    field older rows lack takes the scene's default. A stored scene refused is one
    :class:`InputError` line."""
    if isinstance(scene, Scene):
        v = {name: getattr(scene, name) for name in _DESIGN_FIELDS}
    else:
        v = _stored_design_fields(scene)
    seeds, until, max_runs = list(v["seeds"]), v["until"], v["max_runs"]
    if until:  # the scene's seeds, then the next unused whole numbers up to max_runs
        extra = (n for n in itertools.count(max(seeds) + 1) if n not in seeds)
        seeds = (seeds + list(itertools.islice(extra, max(0, max_runs - len(seeds)))))[:max_runs]
    budget = v["budget"] if until else None
    return Design(primary=tuple(primary_of(v["primary"], v["encoders"])),
                  seed_order=tuple(seeds),
                  looks=tuple(schedule(max_runs, v["look_every"])) if until else (),
                  budget=budget, budget_seconds=parse_duration(budget) if budget else None)


def _stored_design_fields(record: Mapping[str, Any]) -> dict[str, Any]:
    """The design's fields of a scene as a row stores it, checked as a scene checks them."""
    defaults = {f.name: f.default_factory() if f.default is MISSING else f.default
                for f in fields(Scene) if f.name in _DESIGN_FIELDS}
    defaults["encoders"] = []  # rows that store no scene ask no default question
    if not isinstance(record, Mapping):
        raise InputError(f"the rows' stored scene must be a table, got {_show(record)}")
    try:
        v = {**defaults, **check_fields({name: record[name] for name in _DESIGN_FIELDS
                                         if name in record})}
        if v["until"] is not None:
            check_max_runs(v["max_runs"], "scene field 'max_runs'")
        if v["budget"] is not None:
            parse_duration(v["budget"])
    except InputError as exc:
        raise InputError(f"the rows' stored scene: {exc}") from None
    return v


def check_max_runs(max_runs: int, label: str) -> None:
    """The one bound of ``max_runs`` (with ``until``): from the first look to the most
    seeds a run takes; refused in one line naming it as ``label``."""
    if not FIRST_LOOK <= max_runs <= MAX_LENGTHS:
        raise InputError(f"{label} must be from {FIRST_LOOK} (the first look) to "
                         f"{MAX_LENGTHS} (the most seeds a run takes), got {max_runs}")


#: Scene fields that only mean something with ``until`` (refused at another value
#: without it: :func:`_check_together`).
UNTIL_ONLY = ("max_runs", "look_every", "budget")


def _field_default(name: str) -> Any:
    """The :class:`Scene` field ``name``'s default."""
    f = next(f for f in fields(Scene) if f.name == name)
    return f.default_factory() if f.default is MISSING else f.default


def _check_together(scene: Scene) -> None:
    """What a scene's fields need together, without the plugins, a dataset or the disk:
    a profile, precision, executor and input kind that exist, a split and a test window
    written in their grammar, a scheduler only for dask, a grid of at most
    :data:`MAX_CELLS`."""
    get_profile(scene.profile)
    check_choice(scene.resolved_precision(), "precision", PRECISIONS)
    check_choice(scene.executor, "executor", EXECUTORS)
    if scene.scheduler:
        check_scheduler(scene.scheduler)
    if scene.input is not None:
        check_choice(scene.input, "--input", INPUT_KINDS)
    parse_split(scene.split)
    parse_spec(scene.test_window)
    if scene.until is not None:
        check_choice(scene.until, "--until", UNTIL)
        check_max_runs(scene.max_runs, "--max-runs")
        if not scene.design.primary:  # the design, made once and kept (Scene.design)
            raise InputError("--until answered needs a primary comparison: give --primary "
                             f"A..B (the default, {DEFAULT_PRIMARY}, needs both "
                             "encoders)")
    else:  # what only means something with --until, given without it
        lone = [name for name in UNTIL_ONLY
                if getattr(scene, name) != _field_default(name)]
        if lone:
            raise FieldError(lone[0], f" only means something with --until answered")
    if scene.budget is not None:
        parse_duration(scene.budget)
    if scene.memory is not None:
        scene.memory_mb()
    if scene.primary is not None:
        _check_distinct_questions(scene.primary)
    n_cells = (len(set(scene.encoders)) * len(set(scene.classifiers)) * len(set(scene.L))
               * len(set(scene.seeds)) * len(set(scene.init_seeds or [None])))
    if n_cells > MAX_CELLS:
        raise InputError(f"the grid has {n_cells} cells (encoders × classifiers × L × "
                         f"seeds); a run takes at most {MAX_CELLS}")


def _question(text: str) -> frozenset:
    """A contrast ``A..B`` as the question it asks: its two sides, each a set of
    ``factor=value`` (spaces and order aside), in no order (``B..A`` asks it too)."""
    sides = str(text).split("..")
    return frozenset(frozenset(part.strip().replace(" ", "") for part in side.split(",")
                               if part.strip()) for side in sides)


def _check_distinct_questions(primary: Sequence[str]) -> None:
    """Refuse a primary family that names one question twice (``A..B`` twice, or with
    ``B..A``): it would count twice in the family (Holm and the looks' α)."""
    seen: dict[frozenset, str] = {}
    for text in primary:
        q = _question(text)
        if q in seen:
            raise InputError(f"--primary names one question twice: {seen[q]!r} and "
                             f"{text!r}; give each question once")
        seen[q] = text


def primary_of(primary: Sequence[str] | None, encoders: Iterable[str]) -> list[str]:
    """The primary comparisons of a scene: ``primary`` as given, else
    :data:`DEFAULT_PRIMARY` where ``encoders`` has both of its encoders, else none."""
    if primary is not None:
        return list(primary)
    return [DEFAULT_PRIMARY] if {"raw", "farneback"} <= set(encoders) else []


def parse_duration(text: str) -> float:
    """Seconds of ``"90s"``, ``"30m"``, ``"2h"``, ``"1h30m"``, ``"7d"`` (a bare number
    alone: seconds); ``"1h30"`` is refused: every part after the first names its unit."""
    clean = str(text).strip().lower()
    m = _DURATION.fullmatch(clean)
    if not m or not any(m.groups()) or \
            (m.group(4) and any(m.groups()[:3]) and not clean.endswith("s")):
        raise InputError(f"bad duration {_show(text)}: use e.g. 90s, 30m, 2h, 1h30m or 7d "
                         f"(every part with its unit)")
    days, h, mins, secs = (float(g) if g else 0.0 for g in m.groups())
    seconds = 86400 * days + 3600 * h + 60 * mins + secs
    if not 0 < seconds < 1e9:
        raise InputError(f"duration {_show(text)} must be more than 0 and finite")
    return seconds


def show_duration(seconds: float) -> str:
    """``5400`` → ``"1 h 30 min"``: a duration as it is echoed back to the user."""
    h, rest = divmod(int(round(seconds)), 3600)
    mins, secs = divmod(rest, 60)
    return " ".join(f"{v} {unit}" for v, unit in ((h, "h"), (mins, "min"), (secs, "s"))
                    if v) or "0 s"


_DURATION = re.compile(r"(?:(\d{1,5}(?:\.\d+)?)d)?"
                       r"(?:(\d{1,7}(?:\.\d+)?)h)?(?:(\d{1,7}(?:\.\d+)?)m)?"
                       r"(?:(\d{1,9}(?:\.\d+)?)s?)?")
