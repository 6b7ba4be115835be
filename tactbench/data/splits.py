"""Train/test splits: the study's per-class split, and leaving out whole groups.

Each is a deterministic function of the labels (and the samples' groups) and a seed, so
a split can be recorded by its spec and seed and recomputed anywhere. Specs:

- ``paper``: ``test_per_class`` random samples of each class are the test set (the study's);
- ``users``: a random fifth of the users (at least one) is the test set;
- ``users:folds=K``: the users are dealt at random into ``K`` folds and each fold is the
  test set once, training on the others (every user is tested exactly once), so a small
  set of people still gives a figure over all of them. :func:`make_splits` returns the
  ``K`` splits; a cell trains ``K`` models and pools their test predictions.
- ``group:KEY`` (``group:KEY:folds=K``, ``group:KEY:test=A|B``): the same over any
  recording metadata a dataset has (:func:`dataset_groups`: ``user``, ``position``,
  ``repetition``): a random fifth of its values, ``K`` folds of them, or the named values
  as the test set (``group:position:test=side`` trains on the front, tests on the side).
  ``group:user`` is ``users`` (same spec in a cell's identity, same split).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np

from tactbench.errors import InputError, check_choice, check_positive_float, check_positive_int
from tactbench.seeds import derive_seed
from tactbench.specs import parse_spec

SPLITS = ("paper", "users", "group")

#: Sample metadata a group split can leave out, in the order errors list them.
GROUP_KEYS = ("user", "position", "repetition")


@dataclass(frozen=True)
class Split:
    """Indices into a dataset's samples; ``train`` and ``test`` never overlap."""

    name: str
    seed: int
    train: np.ndarray  # (n_train,) int64, sorted
    test: np.ndarray  # (n_test,) int64, sorted
    test_users: tuple[str, ...] = ()

    def describe(self) -> dict:
        return {"split": self.name, "split_seed": self.seed, "n_train": int(len(self.train)),
                "n_test": int(len(self.test)), "test_users": list(self.test_users)}


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
    return Split("paper", seed, train_idx, test_idx)


def dataset_groups(dataset: Any) -> dict[str, list[str]]:
    """The recording metadata of ``dataset`` a group split can use: ``{key: value of every
    sample}`` for each of :data:`GROUP_KEYS` that some sample has (a missing user or
    position is ``""``; a missing repetition is 0)."""
    out = {"user": [str(u) for u in dataset.users],
           "position": [str(p) for p in dataset.positions],
           "repetition": [str(int(r)) if int(r) else "" for r in dataset.repetitions]}
    return {k: v for k, v in out.items() if any(v)}


def _group_values(groups: Mapping[str, Sequence[str]], key: str, spec: str) -> np.ndarray:
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
    return Split(label, seed, np.flatnonzero(~is_test).astype(np.int64),
                 np.flatnonzero(is_test).astype(np.int64), tuple(test_values.tolist()))


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
        out.append(Split(f"{label}:folds={folds}", seed,
                         np.flatnonzero(~is_test).astype(np.int64),
                         np.flatnonzero(is_test).astype(np.int64), tuple(fold_values.tolist())))
    return out


def user_folds(users: Sequence[str], labels: Sequence[int], *, seed: int, folds: int
               ) -> list[Split]:
    """``folds`` leave-users-out splits whose test sets partition the users (and so the
    samples): users are shuffled by ``seed`` and dealt into folds of near-equal size."""
    return group_folds(users, labels, key="user", seed=seed, folds=folds)


class SplitSpec(NamedTuple):
    """A parsed split spec: ``(name, folds)`` first, as callers unpack it."""

    name: str  # paper, users, group
    folds: int | None = None
    key: str = ""  # the metadata a group split leaves out ("user" for users)
    test: tuple[str, ...] | None = None  # the test values of group:KEY:test=A|B


_GROUP_RE = re.compile(r"^group:([A-Za-z_]\w*)(?:[:,](.*))?$")
_SPLIT_HELP = "'paper', 'users', 'users:folds=5', 'group:position' or 'group:KEY:folds=K'"


def parse_split(spec: str) -> SplitSpec:
    """``"paper"`` → ``("paper", None)``; ``"users:folds=5"`` → ``("users", 5, "user")``;
    ``"group:position:test=side"`` → ``("group", None, "position", ("side",))``.
    ``group:user`` is parsed as ``users``."""

    if not isinstance(spec, str):
        raise InputError(f"split must be text such as {_SPLIT_HELP}, got {spec!r}")
    text = spec.strip()
    if text == "group" or text.startswith("group:") or text.startswith("group,"):
        m = _GROUP_RE.match(text)
        if m is None:
            raise InputError(f"split {spec!r}: a group split names the metadata to leave out, "
                             f"as in 'group:position' or 'group:user:folds=5'")
        name, key = "group", m.group(1)
        options = parse_spec(f"group:{m.group(2)}")[1] if m.group(2) else {}
    else:
        name, options = parse_spec(text)
        check_choice(name, "split", SPLITS)
        key = "user" if name == "users" else ""
    unknown = sorted(set(options) - {"folds", "test"})
    if unknown or (options and name == "paper") or ("test" in options and name == "users"):
        raise InputError(f"split {spec!r}: only 'users' and 'group:KEY' take options: "
                         f"folds=K (users:folds=5), and for a group test=A|B "
                         f"(group:position:test=side)")
    folds = options.get("folds")
    if folds is not None:
        folds = check_positive_int(folds, f"split {spec!r}: folds", minimum=2)
    test = options.get("test")
    if test is not None:
        if folds is not None:
            raise InputError(f"split {spec!r}: give folds=K or test=A|B, not both")
        test = tuple(sorted(dict.fromkeys(v.strip() for v in str(test).split("|")
                                          if v.strip())))
        if not test:
            raise InputError(f"split {spec!r}: test= names the test group(s), as in "
                             f"test=side or test=u01|u02")
    if name == "group" and key == "user" and test is None:
        name = "users"  # the familiar name: same identity, same split
    return SplitSpec(name, folds, key, test)


def canonical_split(spec: str) -> str:
    """The split spec as recorded in a cell's identity (``users:folds=5``,
    ``group:position:test=side``); ``group:user`` is recorded as ``users``."""
    p = parse_split(spec)
    head = p.name if p.name != "group" else f"group:{p.key}"
    if p.folds is not None:
        return f"{head}:folds={p.folds}"
    if p.test is not None:
        return f"{head}:test={'|'.join(p.test)}"
    return head


def make_splits(spec: str, *, labels: Sequence[int], users: Sequence[str], seed: int,
                test_per_class: int = 30,
                groups: Mapping[str, Sequence[str]] | None = None) -> list[Split]:
    """Every split of ``spec``: one, or ``K`` folds for ``users:folds=K`` or
    ``group:KEY:folds=K``. ``groups`` (:func:`dataset_groups`) gives each sample's
    metadata for group splits; ``users`` serves as its ``user`` when it has none."""
    p = parse_split(spec)
    if p.name == "paper":
        return [paper_split(labels, seed=seed, test_per_class=test_per_class)]
    merged = dict(groups or {})
    merged.setdefault("user", list(users))
    values = _group_values(merged, p.key, spec) if p.name == "group" else \
        np.asarray([str(u) for u in merged["user"]])
    label = canonical_split(spec).split(":folds=")[0]
    if p.folds is not None:
        return group_folds(values, labels, key=p.key, seed=seed, folds=p.folds)
    return [group_split(values, labels, key=p.key, seed=seed, test=p.test,
                        name=None if p.test is None else label)]


def describe_splits(splits: Sequence[Split]) -> dict:
    """What a cell's row records of its split(s): one split's fields, or the folds'
    together (``n_train`` the mean per fold, ``n_test`` the total, every test user)."""
    if len(splits) == 1:
        return splits[0].describe()
    return {"split": splits[0].name, "split_seed": splits[0].seed, "folds": len(splits),
            "n_train": int(round(float(np.mean([len(s.train) for s in splits])))),
            "n_test": int(sum(len(s.test) for s in splits)),
            "test_users": [u for s in splits for u in s.test_users]}


def make_split(name: str, *, labels: Sequence[int], users: Sequence[str], seed: int,
               test_per_class: int = 30) -> Split:
    """The split called ``name`` (``paper`` or ``users``) of these samples."""
    if check_choice(name, "split", SPLITS[:2]) == "paper":
        return paper_split(labels, seed=seed, test_per_class=test_per_class)
    return users_split(users, labels, seed=seed)
