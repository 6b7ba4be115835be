"""Train/test splits: what a split yields, the built-in designs' functions, the grammar.

A *split* is a small strategy object, registered like any other component (hook
``register_splits``; contract :data:`tactbench.contracts.SPLIT`): its
``split(data, *, seed)`` returns the :class:`Split` of each fold, and each
:class:`Split` names the fold and, for every test recording, the *group* it was left
out with. Rows store both (``test_predictions["folds"]`` and ``["groups"]``), so no
statistic has to draw a fold again. The built-in designs (classes in
:mod:`tactbench.data.strategies`) are deterministic functions, here, of the recordings'
labels and metadata (:class:`SplitData`) and a seed, so a split is recorded by its spec
and seed and recomputed anywhere:

- ``paper``: ``test_per_class`` random recordings of each class are the test set (the
  study's); a test recording's group is its own index;
- ``users``: a random fifth of the users (at least one) is the test set;
- ``users:folds=K``: the users are dealt at random into ``K`` folds and each fold is the
  test set once, training on the others (every user is tested exactly once), so a small
  set of people still gives a figure over all of them; a cell trains ``K`` models and
  pools their test predictions;
- ``group:KEY`` (``group:KEY:folds=K``, ``group:KEY:test=A|B``): the same over any
  recording metadata a dataset has (:func:`dataset_groups`: ``user``, ``position``,
  ``repetition``, and the samples' attributes, such as CoST's ``variant``): a random
  fifth of its values, ``K`` folds of them, or the named values as the test set
  (``group:position:test=side`` trains on the front, tests on the side).
  ``group:user`` is ``users`` (same spec in a cell's identity, same split);
- ``kfold:folds=K``: repeated stratified K-fold over recordings: for each run seed the
  recordings of each class are shuffled and dealt into ``K`` folds, each fold tested
  once (every recording is tested once per run); a test recording's group is its own
  index.

A split declares its *design* (``design``, one of
:data:`~tactbench.contracts.SPLIT_DESIGNS`): ``resampled`` (``paper``, ``users``,
``group:KEY``), ``kfold`` (every ``folds=K``, ``kfold``), ``fixed`` (``group:KEY:test=A|B``:
the same split every seed) or ``independent``; each row records it
(:data:`DESIGN_FIELD`), and the comparisons pick their t from it (docs/statistics.md). A
split over groups names the metadata it keeps apart (``group_key``: ``user`` for
``users``, ``KEY`` for ``group:KEY``); :func:`draw_splits` checks every draw against both.

The split spec grammar (:func:`parse_split`) is the component grammar ``name:key=value``
with one more spelling: a leading value may be followed by ``:`` (``group:position:folds=3``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from tactbench.contracts import SPLIT
from tactbench.errors import ContractError, InputError, check_positive_float, check_positive_int
from tactbench.plugins import load_registry
from tactbench.seeds import derive_seed
from tactbench.specs import format_spec, parse_spec

#: Sample metadata a group split can leave out, in the order errors list them.
GROUP_KEYS = ("user", "position", "repetition")
#: The row field that records the design of the split its cell was tested on (rows made
#: before splits declared designs lack it: :func:`split_design` says how they read).
DESIGN_FIELD = "split_design"


@dataclass(frozen=True, eq=False)
class Split:
    """One train/test pair of a split: indices into a dataset's recordings.

    ``train`` ``(n_train,)`` and ``test`` ``(n_test,)`` are sorted int64 indices that never
    overlap; ``groups`` ``(n_test,)`` is the group id of each test recording, what it was
    left out with (its user for ``users``, its ``KEY`` for ``group:KEY``, its own index for
    ``paper`` and ``kfold``); ``fold`` is the fold this pair is (0 for a split of one
    fold); ``left_out`` the values of the key left out (a row's ``test_users``).
    """

    train: np.ndarray
    test: np.ndarray
    groups: tuple[str, ...]
    fold: int = 0
    left_out: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("train", "test"):
            idx = np.asarray(getattr(self, name))
            if idx.ndim != 1 or (idx.size and idx.dtype.kind not in "iu"):
                raise ContractError(f"a split's {name} indices must be integers (n,), got "
                                    f"{idx.dtype} {idx.shape}")
            if idx.size and (idx.min() < 0 or idx.max() > np.iinfo(np.int64).max):
                # a negative index (or an unsigned one at the top of its type, which
                # wraps to one) would point at a recording from the end: a test one
                raise ContractError(f"a split's {name} indices must be ≥ 0, got "
                                    f"{int(idx.min()) if idx.min() < 0 else int(idx.max())}")
            object.__setattr__(self, name, np.sort(idx.astype(np.int64)))
        object.__setattr__(self, "groups", tuple(str(g) for g in self.groups))
        object.__setattr__(self, "left_out", tuple(str(v) for v in self.left_out))
        if len(self.groups) != len(self.test):
            raise ContractError(f"a split names {len(self.groups)} groups for "
                                f"{len(self.test)} test recordings; one each")
        if isinstance(self.fold, bool) or not isinstance(self.fold, (int, np.integer)) \
                or self.fold < 0:
            raise ContractError(f"a split's fold must be an integer ≥ 0, got {self.fold!r}")
        object.__setattr__(self, "fold", int(self.fold))
        if np.intersect1d(self.train, self.test).size or \
                len(np.unique(self.test)) != len(self.test):
            raise ContractError("a split's train and test sets overlap, or its test set "
                                "names a recording twice")


@dataclass(frozen=True, eq=False)
class SplitData:
    """What a split sees of a dataset: every recording's class and metadata.

    ``labels`` ``(n,)`` int class indices; ``groups`` ``{key: value of every recording}``
    (:func:`dataset_groups`, ``user`` always present, ``""`` where unknown);
    ``test_per_class`` is the scene's, for the ``paper`` split.
    """

    labels: np.ndarray
    groups: Mapping[str, Sequence[str]] = field(default_factory=dict)
    test_per_class: int = 30

    def __post_init__(self) -> None:
        labels = np.asarray(self.labels, dtype=np.int64)
        groups = {k: tuple(str(v) for v in vals) for k, vals in dict(self.groups).items()}
        groups.setdefault("user", ("",) * len(labels))
        for key, vals in groups.items():
            if len(vals) != len(labels):  # made by the runner: a mismatch is a bug
                raise ValueError(f"{len(vals)} values of {key!r} for {len(labels)} recordings")
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "groups", groups)

    @classmethod
    def of(cls, dataset: Any, *, test_per_class: int = 30) -> "SplitData":
        """The split data of a :class:`~tactbench.data.dataset.Dataset`."""
        return cls(np.asarray(dataset.labels), dataset_groups(dataset), test_per_class)

    def __len__(self) -> int:
        return len(self.labels)


def recording_ids(indices: np.ndarray) -> tuple[str, ...]:
    """Group ids of recordings that are their own group: their indices, as text."""
    return tuple(str(int(i)) for i in indices)


def paper_split(labels: Sequence[int], *, seed: int, test_per_class: int = 30) -> Split:
    """The study's split: ``test_per_class`` random samples of each class for test.

    A class with fewer than ``2 * test_per_class`` samples gives half of them (at
    least one) to the test set, so small datasets still train on every class.
    """
    test_per_class = check_positive_int(test_per_class, "test_per_class")
    labels = np.asarray(labels)
    rng = np.random.default_rng(derive_seed(seed, "split", "paper", test_per_class))
    test = []
    for cls in np.unique(labels):
        idx = np.flatnonzero(labels == cls)
        n = min(test_per_class, max(1, len(idx) // 2))
        if len(idx) < 2:
            raise InputError(f"class {cls} has {len(idx)} sample(s); a split needs ≥ 2")
        test.append(rng.choice(idx, size=n, replace=False))
    test_idx = np.sort(np.concatenate(test)).astype(np.int64)
    train_idx = np.setdiff1d(np.arange(len(labels)), test_idx).astype(np.int64)
    return Split(train_idx, test_idx, recording_ids(test_idx))


def dataset_groups(dataset: Any) -> dict[str, list[str]]:
    """The recording metadata of ``dataset`` a group split can use: ``{key: value of every
    sample}`` for each of :data:`GROUP_KEYS` that some sample has (a missing user or
    position is ``""``; a missing repetition is 0), then each of the samples' attributes
    (``variant``, ``substrate``: ``group:variant`` leaves variants out)."""
    out = {"user": [str(u) for u in dataset.users],
           "position": [str(p) for p in dataset.positions],
           "repetition": [str(int(r)) if int(r) else "" for r in dataset.repetitions],
           **getattr(dataset, "attributes", {})}  # a duck-typed dataset may lack them
    return {k: v for k, v in out.items() if any(v)}


def group_values(groups: Mapping[str, Sequence[str]], key: str, spec: str) -> np.ndarray:
    """The value of ``key`` of every recording; refused, naming the keys there are, when
    no recording has one (``spec`` names the split in the message)."""
    if key not in groups or not any(str(v) for v in groups[key]):
        have = [k for k in groups if any(str(v) for v in groups[k])]
        raise InputError(f"split {spec!r}: the recordings have no {key!r}; this dataset's "
                         f"groups are: {', '.join(have) if have else 'none'}"
                         + (" (a folder of recordings takes users from "
                            "users=prefix|folder|FILE.csv, see docs/own-data.md)"
                            if key == "user" else ""))
    return np.asarray([str(v) for v in groups[key]])


def _noun(key: str) -> str:
    return "users" if key == "user" else f"{key} groups"


def group_split(groups: Sequence[str], labels: Sequence[int], *, key: str, seed: int,
                test_fraction: float = 0.2, test: Sequence[str] | None = None,
                name: str | None = None) -> Split:
    """Leave-groups-out: a random ``test_fraction`` of the values of ``key`` (at least one;
    or exactly the values ``test``) is the test set, so no value is in both. Every class
    must keep training samples. ``key="user"`` is the users split (same seeds)."""
    test_fraction = check_positive_float(test_fraction, "test_fraction")
    if test_fraction >= 1:
        raise InputError(f"test_fraction must be < 1 (some {_noun(key)} must train), got "
                         f"{test_fraction}")
    values = np.asarray([str(u) for u in groups])
    labels = np.asarray(labels)
    unique = np.unique(values)
    label = name or ("users" if key == "user" else f"group:{key}")
    if len(unique) < 2:
        raise InputError(f"a {label} split needs ≥ 2 {_noun(key)}; the dataset has "
                         f"{len(unique)}"
                         + (" (recordings without users: a folder of recordings takes them "
                            "from users=prefix|folder|FILE.csv, see docs/own-data.md)"
                            if unique.tolist() == [""] else ""))
    if test is not None:
        test_values = np.sort(np.asarray([str(t) for t in test]))
        unknown = sorted(set(test_values.tolist()) - set(unique.tolist()))
        if unknown:
            raise InputError(f"split {label!r}: no recording has {key} "
                             f"{', '.join(map(repr, unknown))}; its values: "
                             f"{', '.join(unique[:12])}" + (" …" if len(unique) > 12 else ""))
        if len(test_values) >= len(unique):
            raise InputError(f"split {label!r} tests on every {key}; leave some to train on")
    else:
        what = ("split", "users", test_fraction) if key == "user" else \
            ("split", "group", key, test_fraction)
        rng = np.random.default_rng(derive_seed(seed, *what))
        n_test = min(len(unique) - 1, max(1, round(test_fraction * len(unique))))
        test_values = np.sort(rng.choice(unique, size=n_test, replace=False))
    is_test = np.isin(values, test_values)
    missing = set(np.unique(labels)) - set(np.unique(labels[~is_test]))
    if missing:
        raise InputError(f"leave-{_noun(key).replace(' ', '-')}-out split {label!r} left no "
                         f"training sample for classes {sorted(int(m) for m in missing)}")
    test_idx = np.flatnonzero(is_test)
    return Split(np.flatnonzero(~is_test), test_idx, tuple(values[test_idx].tolist()),
                 left_out=tuple(test_values.tolist()))


def users_split(users: Sequence[str], labels: Sequence[int], *, seed: int,
                test_fraction: float = 0.2) -> Split:
    """Leave-users-out: a random ``test_fraction`` of the users (at least one) is the test
    set, so no user is in both. Every class must keep training samples."""
    return group_split(users, labels, key="user", seed=seed, test_fraction=test_fraction)


def group_folds(groups: Sequence[str], labels: Sequence[int], *, key: str, seed: int,
                folds: int) -> list[Split]:
    """``folds`` leave-groups-out splits whose test sets partition the values of ``key``
    (and so the samples): values are shuffled by ``seed`` and dealt into folds of
    near-equal size. ``key="user"`` is ``users:folds=K`` (same seeds)."""
    label = "users" if key == "user" else f"group:{key}"
    folds = check_positive_int(folds, f"{label} split folds", minimum=2)
    values = np.asarray([str(u) for u in groups])
    labels = np.asarray(labels)
    unique = np.unique(values)
    if len(unique) < folds:
        raise InputError(f"{label}:folds={folds} needs ≥ {folds} {_noun(key)}; the dataset "
                         f"has {len(unique)}" + (" (recordings without users: see "
                                                 "docs/own-data.md)"
                                                 if unique.tolist() == [""] else ""))
    what = ("split", "users-folds", folds) if key == "user" else \
        ("split", "group-folds", key, folds)
    rng = np.random.default_rng(derive_seed(seed, *what))
    order = rng.permutation(unique)
    out = []
    for k, fold_values in enumerate(np.array_split(order, folds)):
        fold_values = np.sort(fold_values)
        is_test = np.isin(values, fold_values)
        missing = sorted(set(np.unique(labels).tolist()) - set(labels[~is_test].tolist()))
        if missing:
            raise InputError(f"{label}:folds={folds}: fold {k + 1} ({_noun(key)} "
                             f"{', '.join(fold_values[:5])}) leaves no training sample for "
                             f"class(es) {missing}; use fewer folds")
        test_idx = np.flatnonzero(is_test)
        out.append(Split(np.flatnonzero(~is_test), test_idx, tuple(values[test_idx].tolist()),
                         fold=k, left_out=tuple(fold_values.tolist())))
    return out


def user_folds(users: Sequence[str], labels: Sequence[int], *, seed: int, folds: int
               ) -> list[Split]:
    """``folds`` leave-users-out splits whose test sets partition the users (and so the
    samples): users are shuffled by ``seed`` and dealt into folds of near-equal size."""
    return group_folds(users, labels, key="user", seed=seed, folds=folds)


def kfold_folds(labels: Sequence[int], *, seed: int, folds: int) -> list[Split]:
    """Stratified K-fold over recordings: each class's recordings are shuffled by ``seed``
    and dealt in turn into ``folds`` folds (one class after another, so fold sizes differ
    by at most one, as do a class's counts in two folds); fold ``k`` is the test set of
    split ``k``. Every recording is tested exactly once; every class keeps training
    recordings in every fold (each class needs ≥ 2). A test recording's group is its own
    index. Repeated over run seeds, this is repeated stratified K-fold."""
    folds = check_positive_int(folds, "kfold split folds", minimum=2)
    labels = np.asarray(labels, dtype=np.int64)
    if len(labels) < folds:
        raise InputError(f"kfold:folds={folds} needs ≥ {folds} recordings; the dataset has "
                         f"{len(labels)}")
    classes, counts = np.unique(labels, return_counts=True)
    if (counts < 2).any():
        raise InputError(f"kfold:folds={folds}: class(es) "
                         f"{sorted(int(c) for c in classes[counts < 2])} have one recording; "
                         f"every fold must train on every class (each needs ≥ 2)")
    rng = np.random.default_rng(derive_seed(seed, "split", "kfold", folds))
    order = np.concatenate([rng.permutation(np.flatnonzero(labels == c)) for c in classes])
    fold_of = np.empty(len(labels), dtype=np.int64)
    fold_of[order] = np.arange(len(labels)) % folds
    return [Split(np.flatnonzero(fold_of != k), test, recording_ids(test), fold=k)
            for k in range(folds) for test in (np.flatnonzero(fold_of == k),)]


_LEADING_VALUE = re.compile(r"^([^=,:]+):(.*)$")
SPLIT_EXAMPLES = ("'paper', 'users', 'users:folds=5', 'group:position', "
                  "'group:KEY:folds=K' or 'kfold:folds=5'")


def parse_split(spec: str) -> tuple[str, dict[str, Any]]:
    """A split spec's name and options: ``"users:folds=5"`` → ``("users", {"folds": 5})``;
    ``"group:position:test=side"`` → ``("group", {"_": "position", "test": "side"})``
    (a leading value, :data:`~tactbench.specs.POSITIONAL`, goes to the split's
    ``positional_option``; it may be followed by ``:`` or ``,``)."""
    if not isinstance(spec, str):
        raise InputError(f"split must be text such as {SPLIT_EXAMPLES}, got {spec!r}")
    name, sep, rest = spec.strip().partition(":")
    m = _LEADING_VALUE.match(rest)
    if m is not None:
        rest = f"{m.group(1)},{m.group(2)}"
    return parse_spec(f"{name}{sep}{rest}")


def build_split(spec: str, registry: Any) -> Any:
    """The split strategy of ``spec``, built by ``registry`` (checked against its
    contract there)."""
    name, options = parse_split(spec)
    return registry.build("split", name, **options)


def split_spec(strategy: Any, spec: str) -> str:
    """How a cell's identity and row record the split ``strategy`` built from ``spec``:
    its ``spec`` attribute (the built-ins': ``users:folds=5``, ``group:position``), else
    the name with its options sorted."""
    own = SPLIT.get(strategy, "spec")
    if own:
        return own
    name, options = parse_split(spec)
    return format_spec(name, options)


def canonical_split(spec: str, registry: Any = None) -> str:
    """The split spec as recorded in a cell's identity (``users:folds=5``,
    ``group:position:test=side``); ``group:user`` is recorded as ``users``."""
    return split_spec(build_split(spec, registry or load_registry()), spec)


def check_splits(splits: Sequence[Split], n: int, name: str = "split") -> list[Split]:
    """``splits`` if they are what a split must return for ``n`` recordings: at least
    one :class:`Split`, folds numbered ``0, 1, ...`` in order, indices below ``n``, no
    recording tested twice. Raises :class:`~tactbench.errors.ContractError` naming the
    split: a plugin's mistake, refused before a model is trained on it."""
    splits = list(splits)
    problem = None
    if not splits or not all(isinstance(s, Split) for s in splits):
        problem = "must return a non-empty list of Split"
    elif [s.fold for s in splits] != list(range(len(splits))):
        problem = f"numbered its folds {[s.fold for s in splits]}, not 0, 1, ... in order"
    elif any(len(s.train) == 0 or len(s.test) == 0 for s in splits):
        problem = "returned a fold without training or test recordings"
    elif min(int(min(s.train.min(), s.test.min())) for s in splits) < 0:
        problem = "names a negative recording index"
    elif max(int(max(s.train.max(), s.test.max())) for s in splits) >= n:
        problem = f"names a recording beyond the dataset's {n}"
    elif len(np.unique(np.concatenate([s.test for s in splits]))) != \
            sum(len(s.test) for s in splits):
        problem = "tests a recording in two folds"
    if problem:
        raise ContractError(f"{name} {problem}")
    return splits


def draw_splits(strategy: Any, data: "SplitData", seed: int, name: str) -> list[Split]:
    """What ``strategy.split(data, seed=seed)`` returns, checked as a classifier's output
    is (:func:`check_splits`) and for what a paired comparison needs of it: the same
    splits when drawn twice for one seed, ``data`` left as it was given (a split that
    changed the labels would score every cell against other classes), and what the split
    declares (:func:`check_design`): its design, and train and test disjoint by its
    ``group_key``. Raises :class:`~tactbench.errors.ContractError` naming the split and
    the rule."""
    labels, groups = data.labels.copy(), {k: tuple(v) for k, v in data.groups.items()}
    first = check_splits(strategy.split(data, seed=seed), len(labels), name)
    if not np.array_equal(data.labels, labels) or \
            {k: tuple(v) for k, v in data.groups.items()} != groups:
        raise ContractError(f"{name} changed the labels or metadata it was given")
    again = check_splits(strategy.split(data, seed=seed), len(labels), name)
    if not _same_draw(first, again):
        raise ContractError(f"{name} gave other recordings when drawn twice with seed "
                            f"{seed}: a split must be a function of its seed, or the cells "
                            f"compared as paired would not share their test recordings")
    check_design(strategy, data, seed, name, first)
    return first


def _same_draw(first: Sequence[Split], again: Sequence[Split]) -> bool:
    return len(again) == len(first) and all(
        np.array_equal(a.train, b.train) and np.array_equal(a.test, b.test)
        for a, b in zip(first, again))


def split_design(strategy: Any, splits: Sequence[Split]) -> str:
    """The design of ``strategy`` (:data:`~tactbench.contracts.SPLIT_DESIGNS`), as its
    rows record it: the one it declares; an undeclared one is read as every split was
    before splits declared designs, ``kfold`` where it returned several folds, else
    ``resampled``: a corrected t, never the plain one."""
    declared = SPLIT.get(strategy, "design")
    if declared is not None:
        return declared
    return "kfold" if len(splits) > 1 else "resampled"


def check_design(strategy: Any, data: "SplitData", seed: int, name: str,
                 splits: Sequence[Split]) -> None:
    """Refuse, as :class:`~tactbench.errors.ContractError` naming the split and the
    rule, ``splits`` (drawn with ``seed``) that are not what ``strategy`` declares: a
    ``kfold`` design of one fold, a ``resampled`` one of several, a ``fixed`` one that
    another seed draws otherwise, or a test set that shares a value of its ``group_key``
    with the training set of its fold."""
    design = SPLIT.get(strategy, "design")
    if design == "kfold" and len(splits) < 2:
        raise ContractError(f"{name} declares design 'kfold' and returned one fold; K folds "
                            f"need K ≥ 2 (one train/test pair per seed is 'resampled' or "
                            f"'fixed')")
    if design == "resampled" and len(splits) > 1:
        raise ContractError(f"{name} declares design 'resampled' (one random train/test "
                            f"pair per seed) and returned {len(splits)} folds; a split of "
                            f"K folds declares 'kfold'")
    if design == "fixed" and not _same_draw(splits, check_splits(
            strategy.split(data, seed=seed + 1), len(data), name)):
        raise ContractError(f"{name} declares design 'fixed' and gave other recordings "
                            f"for seeds {seed} and {seed + 1}: a fixed split is the same "
                            f"for every seed (one drawn anew is 'resampled')")
    key = SPLIT.get(strategy, "group_key")
    if key is None:
        return
    values = [str(v) for v in data.groups.get(key, ())]
    if not any(values):
        raise InputError(f"{name} keeps {key!r} apart, and the recordings have no "
                         f"{key!r}; this dataset's groups are: "
                         f"{', '.join(k for k in data.groups if any(data.groups[k])) or 'none'}")
    values_arr = np.asarray(values)
    for s in splits:
        both = np.intersect1d(values_arr[s.train], values_arr[s.test])
        if both.size:
            raise ContractError(
                f"{name} breaks its group_key rule (train and test disjoint by {key}): "
                f"fold {s.fold} trains and tests {key} "
                f"{', '.join(repr(str(v)) for v in both[:3])}" + (" …" if both.size > 3 else ""))


def make_splits(spec: str, *, labels: Sequence[int], users: Sequence[str], seed: int,
                test_per_class: int = 30, groups: Mapping[str, Sequence[str]] | None = None,
                registry: Any = None) -> list[Split]:
    """Every split of ``spec`` (one, or ``K`` folds), as a run draws them: built by
    ``registry`` (default: every installed plugin). ``groups`` (:func:`dataset_groups`)
    gives each sample's metadata for group splits; ``users`` serves as its ``user`` when
    it has none."""
    merged = dict(groups or {})
    merged.setdefault("user", [str(u) for u in users])
    strategy = build_split(spec, registry or load_registry())
    data = SplitData(np.asarray(labels), merged, test_per_class)
    return draw_splits(strategy, data, seed, f"split {spec!r}")


def describe_splits(spec: str, seed: int, splits: Sequence[Split],
                    design: str | None = None) -> dict:
    """What a cell's row records of its split(s): the spec and seed, its ``design``
    (:func:`split_design`, as :data:`DESIGN_FIELD`) where given, and one split's sizes or
    the folds' together (``folds``, ``n_train`` the mean per fold, ``n_test`` the total,
    every value left out)."""
    out: dict[str, Any] = {"split": spec, "split_seed": seed}
    if design is not None:
        out[DESIGN_FIELD] = design
    if len(splits) > 1:
        out["folds"] = len(splits)
    out.update({"n_train": int(round(float(np.mean([len(s.train) for s in splits])))),
                "n_test": int(sum(len(s.test) for s in splits)),
                "test_users": [u for s in splits for u in s.left_out]})
    return out
