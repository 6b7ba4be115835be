"""Train/test splits: the study's per-class split and a leave-users-out split.

Both are deterministic functions of the labels (and users) and a seed, so a split can
be recorded by its name and seed and recomputed anywhere.
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


def make_split(name: str, *, labels: Sequence[int], users: Sequence[str], seed: int,
               test_per_class: int = 30) -> Split:
    """The split called ``name`` (one of :data:`SPLITS`) of these samples."""
    if check_choice(name, "split", SPLITS) == "paper":
        return paper_split(labels, seed=seed, test_per_class=test_per_class)
    return users_split(users, labels, seed=seed)
