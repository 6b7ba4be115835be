"""Any scikit-learn splitter as a split: ``sklearn:GroupKFold:n_splits=5``.

``sklearn:NAME[:option=value,...]`` runs the splitter ``NAME`` of
``sklearn.model_selection`` over a dataset's recordings (its ``X`` a column of zeros, its
``y`` the classes, its ``groups`` a recording metadata, :data:`~tactbench.data.splits.
GROUP_KEYS`), as the ``sklearn`` classifier runs an estimator: ``sklearn:GroupKFold``,
``sklearn:LeaveOneGroupOut``, ``sklearn:StratifiedKFold:n_splits=5``,
``sklearn:GroupShuffleSplit:test_size=0.2``. Every option but ``groups`` is a parameter of
the splitter (checked against its signature when the split is built, and by scikit-learn
when it is drawn, which a run's planning does once before any work), so a typo is one line
naming the parameters there are. scikit-learn is an optional extra and is imported only
when this split is built.

- ``groups=KEY`` (the splitters over groups only: ``Group…``, ``LeaveOneGroupOut``) picks
  the metadata the splitter keeps apart, ``user`` by default; train and test never share
  a value of it (its ``group_key``, checked on every draw), a test recording's group is
  its value and a fold's ``left_out`` the values it tests.
- What a run seed means: ``random_state`` is derived from the run seed (a given one is
  refused), and a splitter with ``shuffle`` shuffles (``shuffle=true`` unless given), so
  every seed deals other folds: repeated K-fold, or a new random split. A splitter
  without either (``LeaveOneGroupOut``, ``LeaveOneOut``; ``shuffle=false``) gives the same
  folds every seed, and its seeds differ by the models' initialisation only.
- Its design (:data:`~tactbench.contracts.SPLIT_DESIGNS`) follows from the splitter: the
  shuffle-split ones (``ShuffleSplit``, ``StratifiedShuffleSplit``, ``GroupShuffleSplit``)
  draw one random train/test pair per seed, ``resampled`` (``n_splits`` is 1; more seeds
  give more pairs); every other one deals K folds, each recording tested once per run,
  ``kfold``.
- Refused, each saying why (:data:`REFUSED`): the splitters that repeat themselves, test a
  recording in several folds, need an array a spec cannot give, or order recordings in
  time.

A fold that leaves a class without training recordings is refused, as the built-in
splits refuse it.
"""

from __future__ import annotations

import difflib
import functools
import inspect
from typing import Any

import numpy as np

from tactbench.data.splits import GROUP_KEYS, Split, SplitData, group_values, recording_ids
from tactbench.errors import InputError
from tactbench.seeds import derive_seed
from tactbench.specs import format_spec

#: Splitters of ``sklearn.model_selection`` a run cannot use, and why (what to use).
REFUSED = {
    "RepeatedKFold": "repeats K-fold within a run; a run repeats over its seeds: use KFold "
                     "and --seeds",
    "RepeatedStratifiedKFold": "repeats K-fold within a run; a run repeats over its seeds: "
                               "use StratifiedKFold and --seeds",
    "LeavePOut": "tests a recording in several folds; use LeaveOneOut or KFold",
    "LeavePGroupsOut": "tests a group in several folds; use LeaveOneGroupOut or GroupKFold",
    "PredefinedSplit": "needs a test_fold array, which a spec cannot give; write a split "
                       "plugin (docs/plugins.md)",
    "TimeSeriesSplit": "orders the recordings in time and never tests the first ones; a "
                       "data set's recordings have no such order",
}
#: The options of this split itself; every other one is the splitter's.
OWN_OPTIONS = ("splitter", "groups")


@functools.lru_cache(maxsize=1)
def splitter_classes() -> dict[str, type]:
    """Every splitter of ``sklearn.model_selection`` a run can use, by class name: its
    public classes with ``split`` and ``get_n_splits``, but the base classes and
    :data:`REFUSED`."""
    import sklearn.model_selection as ms

    found = {}
    for name in ms.__all__:
        try:
            obj = getattr(ms, name)
        except ImportError:  # the experimental searches need an explicit enable
            continue
        if isinstance(obj, type) and hasattr(obj, "split") and hasattr(obj, "get_n_splits") \
                and not name.startswith("Base") and name not in REFUSED:
            found[name] = obj
    return found


def find_splitter(name: Any) -> type:
    """The scikit-learn splitter class called ``name``; an unknown or refused name is one
    line listing those there are."""
    known = splitter_classes()
    if isinstance(name, str) and name in known:
        return known[name]
    text = str(name)
    if text in REFUSED:
        raise InputError(f"sklearn:{text} {REFUSED[text]}")
    by_lower = {k.lower(): k for k in known}
    close = ([by_lower[text.lower()]] if text.lower() in by_lower
             else difflib.get_close_matches(text, list(known), n=2, cutoff=0.6))
    hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
    raise InputError(f"scikit-learn has no splitter '{text}' a run can use; {hint}"
                     f"splitters: {', '.join(sorted(known))}")


def is_group_splitter(cls: type) -> bool:
    """Whether the splitter ``cls`` splits by groups (``GroupKFold``, ``LeaveOneGroupOut``)."""
    return "Group" in cls.__name__


def is_shuffle_splitter(cls: type) -> bool:
    """Whether ``cls`` draws random train/test pairs (``ShuffleSplit`` and its kin) rather
    than dealing K folds."""
    from sklearn.model_selection import BaseShuffleSplit

    return issubclass(cls, BaseShuffleSplit)


class SklearnSplit:
    """``sklearn:NAME[:option=value,...]``: the scikit-learn splitter ``NAME`` over the
    recordings (module docstring)."""

    #: ``sklearn:GroupKFold`` means ``sklearn:splitter=GroupKFold``.
    positional_option = "splitter"

    def __init__(self, splitter: str = "", groups: str | None = None, **params: Any) -> None:
        if not splitter:
            raise InputError("a sklearn split names its splitter, as in sklearn:GroupKFold, "
                             "sklearn:StratifiedKFold:n_splits=5")
        self.cls = find_splitter(splitter)
        self.name = self.cls.__name__
        if is_group_splitter(self.cls):
            self.group_key = "user" if groups is None else str(groups)
            if not self.group_key.isidentifier():
                raise InputError(f"sklearn:{self.name}: groups= names recording metadata "
                                 f"({', '.join(GROUP_KEYS)}), got {groups!r}")
        elif groups is not None:
            raise InputError(f"sklearn:{self.name} splits recordings, not groups, and takes "
                             f"no groups=; the splitters over groups: "
                             f"{', '.join(n for n in splitter_classes() if 'Group' in n)}")
        else:
            self.group_key = None
        self.design = "resampled" if is_shuffle_splitter(self.cls) else "kfold"
        self.params = dict(params)
        self._check_params()

    def _check_params(self) -> None:
        accepted = [p for p in inspect.signature(self.cls).parameters
                    if p not in ("self", "random_state")]
        for key in self.params:
            if key == "random_state" and key in inspect.signature(self.cls).parameters:
                raise InputError(f"sklearn:{self.name}: random_state is the run seed's "
                                 f"(every seed draws its own); leave it out")
            if key not in accepted:
                close = difflib.get_close_matches(key, accepted, n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise InputError(f"{self.name} has no parameter '{key}'{hint}; its "
                                 f"parameters: {', '.join(accepted) or 'none'}; this "
                                 f"split's own options: {', '.join(OWN_OPTIONS)}")
        if self.design == "resampled" and self.params.get("n_splits", 1) != 1:
            raise InputError(f"sklearn:{self.name} draws one train/test pair per run seed "
                             f"(n_splits=1); more pairs are more seeds (--seeds), not "
                             f"n_splits={self.params['n_splits']}")
        self._make(0)  # scikit-learn's own checks of the values it checks when built

    @property
    def spec(self) -> str:
        options = dict(self.params)
        if self.group_key not in (None, "user"):
            options["groups"] = self.group_key
        return format_spec(f"sklearn:{self.name}", options)

    def _make(self, seed: int) -> Any:
        """The splitter, its random state from ``seed`` and shuffling where it can."""
        accepted = inspect.signature(self.cls).parameters
        values = dict(self.params)
        if "shuffle" in accepted:
            values.setdefault("shuffle", True)
        if "n_splits" in accepted and self.design == "resampled":
            values.setdefault("n_splits", 1)
        if "random_state" in accepted and values.get("shuffle", True):
            values["random_state"] = derive_seed(seed, "split", "sklearn", self.name) % 2 ** 32
        try:
            return self.cls(**values)
        except (TypeError, ValueError) as exc:
            raise InputError(f"sklearn:{self.name}: {_one_line(exc)}") from None

    def split(self, data: SplitData, *, seed: int) -> list[Split]:
        """One :class:`~tactbench.data.splits.Split` per fold the splitter yields."""
        labels = np.asarray(data.labels)
        values = None if self.group_key is None else \
            group_values(data.groups, self.group_key, self.spec)
        try:
            pairs = list(self._make(seed).split(np.zeros((len(labels), 1)), labels, values))
        except ValueError as exc:  # too few groups for the folds, a class too small, ...
            raise InputError(f"split {self.spec!r}: {_one_line(exc)}") from None
        out = []
        for k, (train, test) in enumerate(pairs):
            missing = sorted(set(labels.tolist()) - set(labels[train].tolist()))
            if missing:
                raise InputError(f"split {self.spec!r}: fold {k + 1} leaves no training "
                                 f"recording for class(es) {missing}; use fewer folds")
            test = np.sort(np.asarray(test, dtype=np.int64))
            if values is None:
                out.append(Split(np.asarray(train), test, recording_ids(test), fold=k))
            else:
                out.append(Split(np.asarray(train), test, tuple(values[test].tolist()),
                                 fold=k, left_out=tuple(np.unique(values[test]).tolist())))
        return out


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__
