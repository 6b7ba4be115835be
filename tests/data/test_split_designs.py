"""Splits declare their design: the built-ins' designs and group keys, the checks of every
draw against what a split declares, and the ``sklearn:`` split adapter (its folds are
scikit-learn's own; a bad splitter or option is one line)."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.contracts import SPLIT, SPLIT_DESIGNS, check
from tactbench.data.splits import (
    DESIGN_FIELD,
    Split,
    SplitData,
    build_split,
    describe_splits,
    draw_splits,
    split_design,
    split_spec,
)
from tactbench.errors import ContractError, InputError
from tactbench.plugins import load_registry
from tactbench.seeds import derive_seed

N = 24
LABELS = np.array([i % 2 for i in range(N)])
USERS = [f"u{i % 6}" for i in range(N)]
POSITIONS = [("front", "side", "back")[i % 3] for i in range(N)]
DATA = SplitData(LABELS, {"user": USERS, "position": POSITIONS})


@pytest.fixture(scope="module")
def registry():
    return load_registry()


def _draw(spec, registry, seed=0):
    strategy = build_split(spec, registry)
    return strategy, draw_splits(strategy, DATA, seed, f"split {spec!r}")


@pytest.mark.parametrize("spec, design, key", [
    ("paper", "resampled", None), ("users", "resampled", "user"),
    ("group:position", "resampled", "position"), ("users:folds=3", "kfold", "user"),
    ("group:position:folds=3", "kfold", "position"), ("kfold:folds=3", "kfold", None),
    ("group:position:test=side", "fixed", "position"),
    ("group:user:test=u1|u2", "fixed", "user"),
])
def test_each_builtin_declares_its_design_and_the_groups_it_keeps_apart(registry, spec,
                                                                         design, key):
    strategy, splits = _draw(spec, registry)
    assert (SPLIT.get(strategy, "design"), SPLIT.get(strategy, "group_key")) == (design, key)
    assert split_design(strategy, splits) == design
    row = describe_splits(split_spec(strategy, spec), 0, splits,
                          design=split_design(strategy, splits))
    assert row[DESIGN_FIELD] == design
    if key is not None:  # what the check holds it to: no value on both sides
        values = np.asarray(DATA.groups[key])
        assert all(not set(values[s.train]) & set(values[s.test]) for s in splits)


def test_a_fixed_split_is_the_same_for_every_seed_and_a_resampled_one_is_not(registry):
    _, a = _draw("group:position:test=side", registry, seed=0)
    _, b = _draw("group:position:test=side", registry, seed=7)
    assert np.array_equal(a[0].test, b[0].test)
    _, c = _draw("users", registry, seed=0)
    assert any(not np.array_equal(c[0].test, _draw("users", registry, seed=s)[1][0].test)
               for s in range(1, 4))


class _Plugin:
    """A plugin split: ``make(data, seed)`` gives its splits; it declares what it is given."""

    def __init__(self, make, **declared):
        self.make = make
        for name, value in declared.items():
            setattr(self, name, value)

    def split(self, data, *, seed):
        return self.make(data, seed)


def _pair(train, test, fold=0):
    return Split(np.asarray(train), np.asarray(test), tuple("g" * len(test)), fold=fold)


HALVES = [_pair(range(12, N), range(12)), _pair(range(12), range(12, N), fold=1)]


def test_an_undeclared_split_reads_as_before_corrected_never_plain():
    one = _Plugin(lambda d, s: HALVES[:1])
    assert SPLIT.get(one, "design") is None
    assert split_design(one, draw_splits(one, DATA, 0, "split 'one'")) == "resampled"
    two = _Plugin(lambda d, s: HALVES)
    assert split_design(two, draw_splits(two, DATA, 0, "split 'two'")) == "kfold"


@pytest.mark.parametrize("declared, make, match", [
    ({"design": "kfold"}, lambda d, s: HALVES[:1], "declares design 'kfold' and returned one"),
    ({"design": "resampled"}, lambda d, s: HALVES, "declares design 'resampled'"),
    ({"design": "fixed"}, lambda d, s: [_pair(range(s % 2, N, 2), range(1 - s % 2, N, 2))],
     "declares design 'fixed' and gave other recordings for seeds 4 and 5"),
])
def test_a_split_that_is_not_what_it_declares_is_refused(declared, make, match):
    with pytest.raises(ContractError, match=match) as info:
        draw_splits(_Plugin(make, **declared), DATA, 4, "split 'liar'")
    assert str(info.value).startswith("split 'liar'") and "\n" not in str(info.value)


def test_a_group_split_that_tests_a_group_it_trains_on_fails_naming_the_rule():
    # trains on recordings 0..11 and tests 12..23: users u0..u5 on both sides
    leaky = _Plugin(lambda d, s: HALVES[:1], design="resampled", group_key="user")
    with pytest.raises(ContractError, match=r"^split 'leaky' breaks its group_key rule "
                                            r"\(train and test disjoint by user\): fold 0 "
                                            r"trains and tests user 'u0', 'u1', 'u2' …$"):
        draw_splits(leaky, DATA, 0, "split 'leaky'")
    # the same halves are sound by a key they do keep apart
    halves = SplitData(LABELS, {"user": USERS, "session": ["a"] * 12 + ["b"] * 12})
    sound = _Plugin(lambda d, s: HALVES[:1], design="resampled", group_key="session")
    assert draw_splits(sound, halves, 0, "split 'sound'")
    with pytest.raises(InputError, match="keeps 'session' apart, and the recordings have no"):
        draw_splits(sound, DATA, 0, "split 'sound'")


@pytest.mark.parametrize("member, value", [("design", "random"), ("design", 3),
                                           ("group_key", "two words"), ("group_key", 1)])
def test_the_contract_refuses_a_design_or_group_key_it_does_not_know(member, value):
    with pytest.raises(ContractError, match=f"'{member}' must be"):
        check("split", _Plugin(lambda d, s: HALVES[:1], **{member: value}), name="odd")
    assert set(SPLIT_DESIGNS) == {"resampled", "kfold", "fixed", "independent"}


# ------------------------------------------------------------------- sklearn: splits


@pytest.fixture(scope="module")
def model_selection():
    return pytest.importorskip("sklearn.model_selection")


def _sk_folds(splitter, groups=None):
    return [(np.sort(tr), np.sort(te))
            for tr, te in splitter.split(np.zeros((N, 1)), LABELS, groups)]


def _ours(splits):
    return [(s.train, s.test) for s in splits]


def _same(a, b):
    return len(a) == len(b) and all(np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1])
                                    for x, y in zip(a, b))


def test_sklearn_folds_are_scikit_learns_own(registry, model_selection):
    ms = model_selection
    state = derive_seed(3, "split", "sklearn", "GroupKFold") % 2 ** 32
    strategy, splits = _draw("sklearn:GroupKFold:n_splits=3", registry, seed=3)
    assert _same(_ours(splits), _sk_folds(ms.GroupKFold(3, shuffle=True, random_state=state),
                                          np.asarray(USERS)))
    assert (strategy.design, strategy.group_key, strategy.spec) == \
        ("kfold", "user", "sklearn:GroupKFold:n_splits=3")
    assert not _same(_ours(splits), _ours(_draw("sklearn:GroupKFold:n_splits=3", registry,
                                                seed=4)[1]))  # every seed deals anew
    _, logo = _draw("sklearn:LeaveOneGroupOut:groups=position", registry, seed=9)
    assert _same(_ours(logo), _sk_folds(ms.LeaveOneGroupOut(), np.asarray(POSITIONS)))
    assert [s.left_out for s in logo] == [("back",), ("front",), ("side",)]
    assert all(set(s.groups) == set(s.left_out) for s in logo)
    _, strat = _draw("sklearn:StratifiedKFold:n_splits=4,shuffle=false", registry)
    assert _same(_ours(strat), _sk_folds(ms.StratifiedKFold(4)))
    assert [s.fold for s in strat] == [0, 1, 2, 3] and strat[0].groups == \
        tuple(str(i) for i in strat[0].test)  # over recordings: each its own group


def test_sklearn_shuffle_splits_are_resampled_one_pair_per_seed(registry, model_selection):
    strategy, [s] = _draw("sklearn:GroupShuffleSplit:test_size=0.34", registry, seed=2)
    assert (strategy.design, strategy.group_key) == ("resampled", "user")
    state = derive_seed(2, "split", "sklearn", "GroupShuffleSplit") % 2 ** 32
    [expected] = _sk_folds(model_selection.GroupShuffleSplit(1, test_size=0.34,
                                                              random_state=state),
                           np.asarray(USERS))
    assert _same([(s.train, s.test)], [expected])
    assert not set(np.asarray(USERS)[s.train]) & set(s.left_out)


@pytest.mark.parametrize("spec, match", [
    ("sklearn:GroupKFld", "no splitter 'GroupKFld' a run can use; did you mean 'GroupKFold'"),
    ("sklearn:Nonsense", "splitters: GroupKFold, GroupShuffleSplit, KFold"),
    ("sklearn:RepeatedKFold", "repeats K-fold within a run"),
    ("sklearn:LeavePGroupsOut:n_groups=2", "tests a group in several folds"),
    ("sklearn:GroupKFold:n_split=3", "no parameter 'n_split' \\(did you mean 'n_splits'\\?\\)"),
    ("sklearn:KFold:groups=position", "splits recordings, not groups"),
    ("sklearn:ShuffleSplit:n_splits=5", "one train/test pair per run seed"),
    ("sklearn:KFold:random_state=1", "random_state is the run seed's"),
    ("sklearn:KFold:n_splits=1", "n_splits=2 or more"),
    ("sklearn", "names its splitter"),
])
def test_a_bad_sklearn_splitter_or_option_is_one_line(registry, model_selection, spec, match):
    with pytest.raises(InputError, match=match) as info:
        build_split(spec, registry)
    assert "\n" not in str(info.value)


def test_a_sklearn_split_the_data_cannot_give_is_one_line(registry, model_selection):
    for spec, match in (("sklearn:GroupKFold:n_splits=9", "greater than the number of groups"),
                        ("sklearn:GroupKFold:groups=repetition", "have no 'repetition'")):
        with pytest.raises(InputError, match=match) as info:
            _draw(spec, registry)
        assert "\n" not in str(info.value)
