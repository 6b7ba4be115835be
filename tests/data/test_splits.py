"""Splits: the study's per-class split and leave-users-out."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.classifiers.training import derive_seed
from tactbench.data.splits import make_split, paper_split, users_split
from tactbench.errors import InputError

LABELS = np.repeat(np.arange(5), 76)  # 5 classes × 38 users × 2 positions
USERS = np.tile(np.repeat([f"u{i:02d}" for i in range(38)], 2), 5)


def test_paper_split_takes_30_per_class_and_is_disjoint():
    s = paper_split(LABELS, seed=0)
    assert len(s.test) == 150 and len(np.intersect1d(s.train, s.test)) == 0
    assert len(s.train) + len(s.test) == len(LABELS)
    np.testing.assert_array_equal(np.bincount(LABELS[s.test]), [30] * 5)


def test_split_depends_on_the_seed_only():
    a, b, c = (paper_split(LABELS, seed=s) for s in (0, 0, 1))
    np.testing.assert_array_equal(a.test, b.test)
    assert not np.array_equal(a.test, c.test)


def test_small_classes_keep_training_samples():
    s = paper_split([0, 0, 0, 1, 1], seed=3)
    assert set(np.asarray([0, 0, 0, 1, 1])[s.train]) == {0, 1}


def test_users_split_shares_no_user():
    s = users_split(USERS, LABELS, seed=2)
    train_users, test_users = set(USERS[s.train]), set(USERS[s.test])
    assert not train_users & test_users and test_users == set(s.test_users)
    assert len(test_users) == round(0.2 * 38)


def test_bad_splits_are_named():
    with pytest.raises(ValueError, match="unknown split 'random'.*Choices: paper, users"):
        make_split("random", labels=LABELS, users=USERS, seed=0)
    with pytest.raises(ValueError, match="≥ 2 users"):
        users_split(["a"] * 4, [0, 1, 0, 1], seed=0)
    with pytest.raises(ValueError, match="1 sample"):
        paper_split([0, 1, 1], seed=0)
    with pytest.raises(ValueError, match="test_per_class must be ≥ 1"):
        paper_split(LABELS, seed=0, test_per_class=0)
    with pytest.raises(ValueError, match="test_fraction must be < 1"):
        users_split(USERS, LABELS, seed=0, test_fraction=1.0)


def test_derived_seeds_are_stable_and_distinct():
    assert derive_seed(0, "farneback", 5) == derive_seed(0, "farneback", 5)
    assert derive_seed(0, "farneback", 5) != derive_seed(1, "farneback", 5)
    import subprocess
    import sys

    code = "from tactbench.classifiers.training import derive_seed; print(derive_seed(0, 'farneback', 5))"
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env={"PYTHONHASHSEED": "12345", "PATH": ""}, check=True)
    assert int(other.stdout) == derive_seed(0, "farneback", 5)  # not salted per process


def test_user_folds_test_every_user_exactly_once():
    from tactbench.data.splits import describe_splits, make_splits

    users = [f"u{i % 7}" for i in range(70)]
    labels = [i % 5 for i in range(70)]
    folds = make_splits("users:folds=3", labels=labels, users=users, seed=4)
    assert len(folds) == 3
    tested = np.concatenate([f.test for f in folds])
    assert sorted(tested.tolist()) == list(range(70))  # every sample tested once
    assert sorted(u for f in folds for u in f.test_users) == sorted(set(users))
    for f in folds:
        assert not set(f.train) & set(f.test)
        assert not {users[i] for i in f.train} & set(f.test_users)
    assert [len(f.test_users) for f in folds] == [3, 2, 2]
    again = make_splits("users:folds=3", labels=labels, users=users, seed=4)
    assert all(np.array_equal(a.test, b.test) for a, b in zip(folds, again))
    other = make_splits("users:folds=3", labels=labels, users=users, seed=5)
    assert any(not np.array_equal(a.test, b.test) for a, b in zip(folds, other))
    d = describe_splits(folds)
    assert (d["split"], d["folds"], d["n_test"]) == ("users:folds=3", 3, 70)
    single = make_splits("users", labels=labels, users=users, seed=4)
    assert len(single) == 1 and describe_splits(single)["split"] == "users"


@pytest.mark.parametrize("spec, message", [
    ("users:folds=1", "folds must be ≥ 2"),
    ("users:folds=8", "needs ≥ 8 users; the dataset has 7"),
    ("paper:folds=2", "only 'users' takes an option"),
    ("users:k=2", "only 'users' takes an option"),
    ("user", "did you mean 'users'"),
])
def test_bad_split_specs_are_one_line(spec, message):
    from tactbench.data.splits import make_splits

    users = [f"u{i % 7}" for i in range(70)]
    with pytest.raises(InputError, match=message):
        make_splits(spec, labels=[i % 5 for i in range(70)], users=users, seed=0)


def test_a_fold_that_leaves_a_class_untrained_is_refused():
    from tactbench.data.splits import make_splits

    users = ["a", "a", "b", "b", "c", "c"]
    labels = [0, 1, 0, 1, 0, 2]  # class 2 only from user c
    with pytest.raises(InputError, match=r"leaves no training sample for class\(es\) \[2\]"):
        make_splits("users:folds=3", labels=labels, users=users, seed=0)
