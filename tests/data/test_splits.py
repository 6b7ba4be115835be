"""Splits: the study's per-class split, leave-users-out, leave-any-group-out, stratified
K-fold; each a registered strategy whose splits carry fold and group ids."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tactbench.classifiers.training import derive_seed
from tactbench.data.splits import make_splits, paper_split, users_split
from tactbench.errors import ContractError, InputError, UnknownComponentError

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
    assert not train_users & test_users and test_users == set(s.left_out) == set(s.groups)
    assert len(test_users) == round(0.2 * 38)


def test_bad_splits_are_named():
    with pytest.raises(UnknownComponentError,
                       match="unknown split 'random'.*Known splits: group, kfold, paper, sklearn, users"):
        make_splits("random", labels=LABELS, users=USERS, seed=0)
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
    assert sorted(u for f in folds for u in f.left_out) == sorted(set(users))
    for f in folds:
        assert not set(f.train) & set(f.test)
        assert not {users[i] for i in f.train} & set(f.left_out)
    assert [len(f.left_out) for f in folds] == [3, 2, 2]
    again = make_splits("users:folds=3", labels=labels, users=users, seed=4)
    assert all(np.array_equal(a.test, b.test) for a, b in zip(folds, again))
    other = make_splits("users:folds=3", labels=labels, users=users, seed=5)
    assert any(not np.array_equal(a.test, b.test) for a, b in zip(folds, other))
    d = describe_splits("users:folds=3", 4, folds)
    assert (d["split"], d["folds"], d["n_test"]) == ("users:folds=3", 3, 70)
    single = make_splits("users", labels=labels, users=users, seed=4)
    assert len(single) == 1 and "folds" not in describe_splits("users", 4, single)


@pytest.mark.parametrize("spec, message", [
    ("users:folds=1", "folds must be ≥ 2"),
    ("users:folds=8", "needs ≥ 8 users; the dataset has 7"),
    ("paper:folds=2", "split 'paper' has no option 'folds'"),
    ("users:k=2", "split 'users' has no option 'k'. Options: folds"),
    ("users:test=u1", "split 'users' has no option 'test'"),
    ("users:u1", "split 'users' takes no value without a name"),
    ("group", "names the metadata to leave out"),
    ("group:position:folds=2,test=side", "folds=K or test=A|B, not both"),
    ("kfold:folds=1", "folds must be ≥ 2"),
    ("kfold:folds=71", "needs ≥ 71 recordings; the dataset has 70"),
    ("group:surface", "the recordings have no 'surface'; this dataset's groups are: "
                      "user, position$"),
    ("group:position:test=top", "no recording has position 'top'; its values: front, side"),
    ("group:position:test=front|side", "tests on every position"),
    ("group:position:folds=3", "needs ≥ 3 position groups; the dataset has 2"),
    ("user", "did you mean 'users'"),
])
def test_bad_split_specs_are_one_line(spec, message):
    from tactbench.errors import TactbenchError

    users = [f"u{i % 7}" for i in range(70)]
    groups = {"user": users, "position": ["front", "side"] * 35}
    with pytest.raises(TactbenchError, match=message):
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
        assert [(x.fold, x.test.tolist(), x.groups) for x in a] == \
            [(x.fold, x.test.tolist(), x.groups) for x in b]


def test_train_on_front_test_on_side():
    from tactbench.data.splits import canonical_split, make_splits

    spec = "group:position:test=side"
    assert canonical_split(spec) == "group:position:test=side"
    (s,) = make_splits(spec, labels=GROUP_LABELS, users=GROUP_USERS, seed=0, groups=GROUPS)
    pos = np.asarray(GROUPS["position"])
    assert set(pos[s.train]) == {"front"} and set(pos[s.test]) == {"side"}
    assert s.left_out == ("side",) and len(s.train) + len(s.test) == 140
    # the seed does not matter when the test group is named
    (other,) = make_splits(spec, labels=GROUP_LABELS, users=GROUP_USERS, seed=9,
                           groups=GROUPS)
    assert np.array_equal(other.test, s.test)


def test_group_folds_leave_each_value_out_once():
    from tactbench.data.splits import make_splits

    folds = make_splits("group:repetition:folds=5", labels=GROUP_LABELS, users=GROUP_USERS,
                        seed=1, groups=GROUPS)
    rep = np.asarray(GROUPS["repetition"])
    assert sorted(np.concatenate([f.test for f in folds]).tolist()) == list(range(140))
    for f in folds:
        assert len(set(rep[f.test])) == 1 and not set(rep[f.test]) & set(rep[f.train])
    assert [f.fold for f in folds] == list(range(5))
    for f in folds:  # a test recording's group: its repetition, the value left out
        assert list(f.groups) == rep[f.test].tolist() and list(f.left_out) == [f.groups[0]]
    (one,) = make_splits("group:position", labels=GROUP_LABELS, users=GROUP_USERS, seed=1,
                         groups=GROUPS)
    assert one.fold == 0 and len(one.left_out) == 1


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
        run(dataclasses.replace(scene, split="group:surface"), progress=False,
            cache=EncodingCache(tmp_path / "cache"))


# ------------------------------------------------- every split: folds and groups

SPECS = ["paper", "users", "users:folds=3", "group:position", "group:position:test=side",
         "group:repetition:folds=5", "kfold:folds=4"]


@pytest.mark.parametrize("spec", SPECS)
def test_every_split_yields_disjoint_sets_with_a_fold_and_a_group_per_test_recording(spec):
    splits = make_splits(spec, labels=GROUP_LABELS, users=GROUP_USERS, seed=2, groups=GROUPS,
                         test_per_class=3)
    key = {"users": "user", "group:position": "position",
           "group:repetition": "repetition"}.get(spec.split(":folds")[0].split(":test")[0])
    assert [s.fold for s in splits] == list(range(len(splits)))
    for s in splits:
        assert not set(s.train.tolist()) & set(s.test.tolist())
        assert len(s.groups) == len(s.test) and all(isinstance(g, str) for g in s.groups)
        if key is None:  # paper, kfold: each test recording is its own group
            assert list(s.groups) == [str(i) for i in s.test]
        else:  # the value of the key that was left out
            assert list(s.groups) == [str(GROUPS[key][i]) for i in s.test]
            assert set(s.groups) == set(s.left_out)
            assert not set(s.groups) & {str(GROUPS[key][i]) for i in s.train}
    if len(splits) > 1:  # folds: every recording tested once
        tested = sorted(i for s in splits for i in s.test.tolist())
        assert tested == list(range(len(GROUP_LABELS)))


def test_kfold_tests_every_recording_once_per_run_stratified_and_by_seed():
    labels = np.repeat(np.arange(3), [10, 7, 5])  # unbalanced classes
    runs = {seed: make_splits("kfold:folds=4", labels=labels, users=[""] * 22, seed=seed)
            for seed in (0, 0, 1)}
    for seed, folds in runs.items():
        assert len(folds) == 4
        tested = np.concatenate([f.test for f in folds])
        assert sorted(tested.tolist()) == list(range(22))  # each exactly once
        sizes = [len(f.test) for f in folds]
        assert max(sizes) - min(sizes) <= 1
        for c, n in enumerate((10, 7, 5)):  # stratified: a class's share of each fold
            per_fold = [int((labels[f.test] == c).sum()) for f in folds]
            assert sum(per_fold) == n and max(per_fold) - min(per_fold) <= 1
        for f in folds:  # every class trains in every fold
            assert set(labels[f.train].tolist()) == {0, 1, 2}
    again = make_splits("kfold:folds=4", labels=labels, users=[""] * 22, seed=0)
    assert [f.test.tolist() for f in again] == [f.test.tolist() for f in runs[0]]
    assert [f.test.tolist() for f in runs[1]] != [f.test.tolist() for f in runs[0]]
    with pytest.raises(InputError, match=r"class\(es\) \[2\] have one recording"):
        make_splits("kfold:folds=2", labels=[0, 0, 1, 1, 2], users=[""] * 5, seed=0)
    assert canonical("kfold") == "kfold:folds=5"  # the default is recorded: one identity


def canonical(spec):
    from tactbench.data.splits import canonical_split

    return canonical_split(spec)


def test_a_split_that_breaks_its_contract_is_refused_naming_it():
    from tactbench.data.splits import Split, check_splits

    with pytest.raises(ContractError, match="overlap"):
        Split(np.array([0, 1]), np.array([1, 2]), ("1", "2"))
    with pytest.raises(ContractError, match="2 groups for 1 test recordings"):
        Split(np.array([0]), np.array([1]), ("1", "2"))
    a = Split(np.array([0, 1]), np.array([2]), ("2",))
    b = Split(np.array([0, 2]), np.array([1]), ("1",), fold=1)
    assert check_splits([a, b], 3) == [a, b]
    for splits, message in [([], "non-empty list of Split"), ([b, a], "numbered its folds"),
                            ([a, Split(np.array([0]), np.array([2]), ("2",), fold=1)],
                             "tests a recording in two folds"),
                            ([a], "beyond the dataset's 2")]:
        with pytest.raises(ContractError, match=f"split 'x' .*{message}"):
            check_splits(splits, 2 if "beyond" in message else 3, "split 'x'")
