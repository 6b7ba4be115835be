"""The built-in splits and test windows: the small objects ``tactbench.data``'s hooks
register (``register_splits``, ``register_test_windows``), as a plugin registers its own.

A split is built from its spec (``users:folds=5`` → ``UsersSplit(folds=5)``) and answers
``split(data, *, seed)`` with one :class:`~tactbench.data.splits.Split` per fold; its
``spec`` is how cell identities record it. A test window answers ``training`` and
``test`` with the :class:`~tactbench.data.windows.Windows` of some recordings, and
``combine`` with each test recording's class from its windows' predictions. Their
contracts are :data:`tactbench.contracts.SPLIT` and :data:`tactbench.contracts.TEST_WINDOW`;
the designs themselves are the functions of :mod:`tactbench.data.splits` and
:mod:`tactbench.data.windows`.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from tactbench.data.splits import (
    Split,
    SplitData,
    group_folds,
    group_split,
    group_values,
    kfold_folds,
    paper_split,
)
from tactbench.data.windows import (
    Windows,
    dataset_onsets,
    onset_test_windows,
    onset_training_windows,
    test_windows,
    training_windows,
)
from tactbench.errors import InputError, check_positive_int

# ------------------------------------------------------------------------------ splits


class PaperSplit:
    """``paper``: ``test_per_class`` random recordings of each class (the scene's) are the
    test set, the rest train (the study's split). One fold, drawn anew for every seed."""

    spec = "paper"
    design = "resampled"
    group_key = None

    def split(self, data: SplitData, *, seed: int) -> list[Split]:
        return [paper_split(data.labels, seed=seed, test_per_class=data.test_per_class)]


class GroupSplit:
    """``group:KEY``: leave values of the recording metadata ``key`` out: a random fifth,
    ``folds`` folds of them (each tested once), or exactly the values ``test``
    (``A|B``). ``group:user`` is the ``users`` split. Its design: ``resampled`` (a fifth,
    drawn anew for every seed), ``kfold`` (``folds``) or ``fixed`` (``test``: the same
    split every seed); train and test never share a value of ``key`` (its
    ``group_key``)."""

    positional_option = "key"

    def __init__(self, *, key: str = "", folds: int | None = None,
                 test: Any = None) -> None:
        if not isinstance(key, str) or not key.isidentifier():
            raise InputError(f"a group split names the metadata to leave out, as in "
                             f"'group:position' or 'group:user:folds=5' (got {key!r})")
        if folds is not None and test is not None:
            raise InputError("give folds=K or test=A|B, not both")
        self.key = key
        self.folds = None if folds is None else check_positive_int(folds, "folds", minimum=2)
        self.test = None if test is None else tuple(sorted(dict.fromkeys(
            v.strip() for v in str(test).split("|") if v.strip())))
        if self.test == ():
            raise InputError("test= names the test group(s), as in test=side or "
                             "test=u01|u02")

    @property
    def design(self) -> str:
        return "kfold" if self.folds is not None else \
            "resampled" if self.test is None else "fixed"

    @property
    def group_key(self) -> str:
        return self.key

    @property
    def spec(self) -> str:
        head = "users" if self.key == "user" and self.test is None else f"group:{self.key}"
        if self.folds is not None:
            return f"{head}:folds={self.folds}"
        return head if self.test is None else f"{head}:test={'|'.join(self.test)}"

    def split(self, data: SplitData, *, seed: int) -> list[Split]:
        values = group_values(data.groups, self.key, self.spec)
        if self.folds is not None:
            return group_folds(values, data.labels, key=self.key, seed=seed, folds=self.folds)
        return [group_split(values, data.labels, key=self.key, seed=seed, test=self.test,
                            name=None if self.test is None else self.spec)]


class UsersSplit(GroupSplit):
    """``users``: leave a random fifth of the users out; ``users:folds=K``: the users
    dealt into ``K`` folds, each tested once."""

    positional_option = None

    def __init__(self, *, folds: int | None = None) -> None:
        super().__init__(key="user", folds=folds)


class KFoldSplit:
    """``kfold:folds=K``: repeated stratified K-fold over recordings (each recording
    tested once per run seed; :func:`~tactbench.data.splits.kfold_folds`)."""

    design = "kfold"
    group_key = None

    def __init__(self, *, folds: int = 5) -> None:
        self.folds = check_positive_int(folds, "folds", minimum=2)

    @property
    def spec(self) -> str:
        return f"kfold:folds={self.folds}"

    def split(self, data: SplitData, *, seed: int) -> list[Split]:
        return kfold_folds(data.labels, seed=seed, folds=self.folds)


# ------------------------------------------------------------------------ test windows


class FirstWindow:
    """``first``: train on every window, test on each recording's first ``L`` frames (the
    study's protocol); a recording's class is its one window's."""

    def training(self, sequences: Sequence[Any], labels: Sequence[int], L: int, *,
                 prepared: Sequence[Any] | None = None) -> Windows:
        return training_windows(sequences, labels, L)

    def test(self, sequences: Sequence[Any], labels: Sequence[int], L: int, *,
             prepared: Sequence[Any] | None = None) -> Windows:
        return test_windows(sequences, labels, L)

    def combine(self, classifier: Any, windows: Windows, n: int) -> np.ndarray:
        return np.asarray(classifier.predict(windows))


class OnsetWindow(FirstWindow):
    """``onset``: the ``L`` frames from each recording's contact onset (prepared once per
    run: :func:`~tactbench.data.windows.dataset_onsets`); training from each training
    recording's own onset window on."""

    def prepare(self, dataset: Any) -> tuple[int, ...]:
        return dataset_onsets(dataset)

    def training(self, sequences: Sequence[Any], labels: Sequence[int], L: int, *,
                 prepared: Sequence[Any] | None = None) -> Windows:
        return onset_training_windows(sequences, labels, L, _onsets(prepared))

    def test(self, sequences: Sequence[Any], labels: Sequence[int], L: int, *,
             prepared: Sequence[Any] | None = None) -> Windows:
        return onset_test_windows(sequences, labels, L, _onsets(prepared))


def _onsets(prepared: Sequence[Any] | None) -> Sequence[int]:
    if prepared is None:  # the runner prepares what prepare() asks for: a bug
        raise ValueError("onset windows need the recordings' onsets (prepare)")
    return prepared


class VoteWindow(FirstWindow):
    """``vote``: every window of a test recording is classified and the class
    probabilities averaged (training on every window, as ``first``)."""

    def test(self, sequences: Sequence[Any], labels: Sequence[int], L: int, *,
             prepared: Sequence[Any] | None = None) -> Windows:
        return training_windows(sequences, labels, L)

    def combine(self, classifier: Any, windows: Windows, n: int) -> np.ndarray:
        proba = np.asarray(classifier.predict_proba(windows), dtype=np.float64)
        summed = np.zeros((n, proba.shape[1]))
        np.add.at(summed, windows.seq_index, proba)
        return summed.argmax(axis=1)
