"""Splits: the study's per-class split, leave-users-out and leave-any-group-out."""

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
    ("paper:folds=2", "only 'users' and 'group:KEY' take options"),
    ("users:k=2", "only 'users' and 'group:KEY' take options"),
    ("users:test=u1", "only 'users' and 'group:KEY' take options"),
    ("group", "names the metadata to leave out"),
    ("group:position:folds=2,test=side", "folds=K or test=A|B, not both"),
    ("group:surface", "the recordings have no 'surface'; this dataset's groups are: "
                      "user, position$"),
    ("group:position:test=top", "no recording has position 'top'; its values: front, side"),
    ("group:position:test=front|side", "tests on every position"),
    ("group:position:folds=3", "needs ≥ 3 position groups; the dataset has 2"),
    ("user", "did you mean 'users'"),
])
def test_bad_split_specs_are_one_line(spec, message):
    from tactbench.data.splits import make_splits

    users = [f"u{i % 7}" for i in range(70)]
    groups = {"user": users, "position": ["front", "side"] * 35}
    with pytest.raises(InputError, match=message):
        make_splits(spec, labels=[i % 5 for i in range(70)], users=users, seed=0,
                    groups=groups)


def test_a_fold_that_leaves_a_class_untrained_is_refused():
    from tactbench.data.splits import make_splits

    users = ["a", "a", "b", "b", "c", "c"]
    labels = [0, 1, 0, 1, 0, 2]  # class 2 only from user c
    with pytest.raises(InputError, match=r"leaves no training sample for class\(es\) \[2\]"):
        make_splits("users:folds=3", labels=labels, users=users, seed=0)


# ------------------------------------------------------------------ any group

GROUP_USERS = [f"u{i % 7}" for i in range(140)]
GROUP_LABELS = [i % 5 for i in range(140)]
GROUPS = {"user": GROUP_USERS, "position": ["front" if (i // 7) % 2 else "side"
                                            for i in range(140)],
          "repetition": [str(1 + (i // 14) % 5) for i in range(140)]}


def test_group_user_is_the_users_split():
    from tactbench.data.splits import canonical_split, make_splits

    for spec, same in (("group:user", "users"), ("group:user:folds=3", "users:folds=3"),
                       ("group:user,folds=3", "users:folds=3")):
        assert canonical_split(spec) == same
        a = make_splits(spec, labels=GROUP_LABELS, users=GROUP_USERS, seed=3, groups=GROUPS)
        b = make_splits(same, labels=GROUP_LABELS, users=GROUP_USERS, seed=3)
        assert [(x.name, x.test.tolist()) for x in a] == [(x.name, x.test.tolist()) for x in b]


def test_train_on_front_test_on_side():
    from tactbench.data.splits import canonical_split, make_splits

    spec = "group:position:test=side"
    assert canonical_split(spec) == "group:position:test=side"
    (s,) = make_splits(spec, labels=GROUP_LABELS, users=GROUP_USERS, seed=0, groups=GROUPS)
    pos = np.asarray(GROUPS["position"])
    assert set(pos[s.train]) == {"front"} and set(pos[s.test]) == {"side"}
    assert s.test_users == ("side",) and len(s.train) + len(s.test) == 140
    # the seed does not matter when the test group is named
    (other,) = make_splits(spec, labels=GROUP_LABELS, users=GROUP_USERS, seed=9,
                           groups=GROUPS)
    assert np.array_equal(other.test, s.test)


def test_group_folds_leave_each_value_out_once():
    from tactbench.data.splits import describe_splits, make_splits

    folds = make_splits("group:repetition:folds=5", labels=GROUP_LABELS, users=GROUP_USERS,
                        seed=1, groups=GROUPS)
    rep = np.asarray(GROUPS["repetition"])
    assert sorted(np.concatenate([f.test for f in folds]).tolist()) == list(range(140))
    for f in folds:
        assert len(set(rep[f.test])) == 1 and not set(rep[f.test]) & set(rep[f.train])
    assert describe_splits(folds)["split"] == "group:repetition:folds=5"
    (one,) = make_splits("group:position", labels=GROUP_LABELS, users=GROUP_USERS, seed=1,
                         groups=GROUPS)
    assert one.name == "group:position" and len(one.test_users) == 1


def test_dataset_groups_lists_the_metadata_a_dataset_has():
    from tactbench.data.splits import dataset_groups
    from tactbench.datasets.synthetic_forearm import generate

    ds = generate(users=2, repetitions=2, positions=2)
    g = dataset_groups(ds)
    assert list(g) == ["user", "position", "repetition"]
    assert g["position"] == ds.positions and set(g["repetition"]) == {"1", "2"}

    class Bare:  # a reader that knows neither users nor positions
        users = positions = [""] * 4
        repetitions = np.zeros(4, dtype=np.int64)

    assert dataset_groups(Bare()) == {}


def test_train_on_front_test_on_side_is_one_run(tmp_path):
    """The runner takes a group split end to end: every test recording is from the side."""
    from tactbench.datasets.synthetic_forearm import generate
    from tactbench.runner import EncodingCache, Scene, run

    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
                  classifiers=["logreg"], L=[3], seeds=[0], pixel_mm=10.0, threads=1,
                  split="group:position:test=side", out=str(tmp_path / "out"))
    [row] = run(scene, progress=False, cache=EncodingCache(tmp_path / "cache")).rows
    assert row["status"] == "ok", row.get("error")
    assert (row["split"], row["test_users"]) == ("group:position:test=side", ["side"])
    positions = np.asarray(generate(users=2, repetitions=1).positions)
    assert set(positions[row["test_predictions"]["indices"]]) == {"side"}
    assert row["n_test"] == 10
    with pytest.raises(InputError, match="this dataset's groups are: user, position"):
        run(Scene(**{**scene.__dict__, "split": "group:surface"}), progress=False,
            cache=EncodingCache(tmp_path / "cache"))
