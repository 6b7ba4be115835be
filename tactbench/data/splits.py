"""Train/test splits: the study's per-class split, leave-users-out, and k-fold over users.

Each is a deterministic function of the labels (and users) and a seed, so a split can
be recorded by its spec and seed and recomputed anywhere. Specs:

- ``paper``: ``test_per_class`` random samples of each class are the test set (the study's);
- ``users``: a random fifth of the users (at least one) is the test set;
- ``users:folds=K``: the users are dealt at random into ``K`` folds and each fold is the
  test set once, training on the others (every user is tested exactly once), so a small
  set of people still gives a figure over all of them. :func:`make_splits` returns the
  ``K`` splits; a cell trains ``K`` models and pools their test predictions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tactbench.errors import InputError, check_choice, check_positive_float, check_positive_int
from tactbench.seeds import derive_seed

SPLITS = ("paper", "users")


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


def users_split(users: Sequence[str], labels: Sequence[int], *, seed: int,
                test_fraction: float = 0.2) -> Split:
    """Leave-users-out: a random ``test_fraction`` of the users (at least one) is the test
    set, so no user is in both. Every class must keep training samples."""
    test_fraction = check_positive_float(test_fraction, "test_fraction")
    if test_fraction >= 1:
        raise InputError(f"test_fraction must be < 1 (some users must train), got "
                         f"{test_fraction}")
    users_arr = np.asarray([str(u) for u in users])
    labels = np.asarray(labels)
    unique = np.unique(users_arr)
    if len(unique) < 2:
        raise InputError(f"a users split needs ≥ 2 users; the dataset has {len(unique)}"
                         + (" (recordings without users: a folder of recordings takes them "
                            "from users=prefix|folder|FILE.csv, see docs/own-data.md)"
                            if unique.tolist() == [""] else ""))
    rng = np.random.default_rng(derive_seed(seed, "split", "users", test_fraction))
    n_test = min(len(unique) - 1, max(1, round(test_fraction * len(unique))))
    test_users = np.sort(rng.choice(unique, size=n_test, replace=False))
    is_test = np.isin(users_arr, test_users)
    missing = set(np.unique(labels)) - set(np.unique(labels[~is_test]))
    if missing:
        raise InputError(f"leave-users-out split left no training sample for classes "
                         f"{sorted(int(m) for m in missing)}")
    return Split("users", seed, np.flatnonzero(~is_test).astype(np.int64),
                 np.flatnonzero(is_test).astype(np.int64), tuple(test_users.tolist()))


def user_folds(users: Sequence[str], labels: Sequence[int], *, seed: int, folds: int
               ) -> list[Split]:
    """``folds`` leave-users-out splits whose test sets partition the users (and so the
    samples): users are shuffled by ``seed`` and dealt into folds of near-equal size."""
    folds = check_positive_int(folds, "users split folds", minimum=2)
    users_arr = np.asarray([str(u) for u in users])
    labels = np.asarray(labels)
    unique = np.unique(users_arr)
    if len(unique) < folds:
        raise InputError(f"users:folds={folds} needs ≥ {folds} users; the dataset has "
                         f"{len(unique)}" + (" (recordings without users: see "
                                             "docs/own-data.md)" if unique.tolist() == [""]
                                             else ""))
    rng = np.random.default_rng(derive_seed(seed, "split", "users-folds", folds))
    order = rng.permutation(unique)
    out = []
    for k, fold_users in enumerate(np.array_split(order, folds)):
        fold_users = np.sort(fold_users)
        is_test = np.isin(users_arr, fold_users)
        missing = sorted(set(np.unique(labels).tolist()) - set(labels[~is_test].tolist()))
        if missing:
            raise InputError(f"users:folds={folds}: fold {k + 1} (users "
                             f"{', '.join(fold_users[:5])}) leaves no training sample for "
                             f"class(es) {missing}; use fewer folds")
        out.append(Split(f"users:folds={folds}", seed,
                         np.flatnonzero(~is_test).astype(np.int64),
                         np.flatnonzero(is_test).astype(np.int64), tuple(fold_users.tolist())))
    return out


def parse_split(spec: str) -> tuple[str, int | None]:
    """``"paper"`` → ``("paper", None)``; ``"users:folds=5"`` → ``("users", 5)``."""
    from tactbench.specs import parse_spec

    if not isinstance(spec, str):
        raise InputError(f"split must be text such as 'paper', 'users' or 'users:folds=5', "
                         f"got {spec!r}")
    name, options = parse_spec(spec)
    check_choice(name, "split", SPLITS)
    unknown = sorted(set(options) - {"folds"})
    if unknown or (options and name != "users"):
        raise InputError(f"split {spec!r}: only 'users' takes an option, folds=K "
                         f"(users:folds=5)")
    folds = options.get("folds")
    if folds is not None:
        folds = check_positive_int(folds, f"split {spec!r}: folds", minimum=2)
    return name, folds


def canonical_split(spec: str) -> str:
    """The split spec as recorded in a cell's identity (``users:folds=5``)."""
    name, folds = parse_split(spec)
    return name if folds is None else f"{name}:folds={folds}"


def make_splits(spec: str, *, labels: Sequence[int], users: Sequence[str], seed: int,
                test_per_class: int = 30) -> list[Split]:
    """Every split of ``spec``: one, or ``K`` folds for ``users:folds=K``."""
    name, folds = parse_split(spec)
    if folds is not None:
        return user_folds(users, labels, seed=seed, folds=folds)
    return [make_split(name, labels=labels, users=users, seed=seed,
                       test_per_class=test_per_class)]


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
    if check_choice(name, "split", SPLITS) == "paper":
        return paper_split(labels, seed=seed, test_per_class=test_per_class)
    return users_split(users, labels, seed=seed)
