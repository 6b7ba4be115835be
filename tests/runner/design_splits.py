"""Split plugins that declare designs, for tests/runner/test_split_design_runs.py:
importable by name (tests/runner is on ``sys.path``, see its conftest.py), so a run's
cells can load them. The module itself is the plugin object (``register_splits``)."""

from __future__ import annotations

import numpy as np

from tactbench import hookimpl
from tactbench.data.splits import Split, recording_ids


class FixedHalves:
    """``fixed-halves``: the first half of each class's recordings tests, every seed the
    same (declared ``fixed``)."""

    design = "fixed"

    def split(self, data, *, seed):
        test = np.sort(np.concatenate([idx[: len(idx) // 2] for c in np.unique(data.labels)
                                       for idx in (np.flatnonzero(data.labels == c),)]))
        train = np.setdiff1d(np.arange(len(data.labels)), test)
        return [Split(train, test, recording_ids(test))]


class LeakyUsers:
    """``leaky-users``: declares it keeps users apart; seed 0 tests the first user's
    recordings, every later seed every other recording, users on both sides (a bug)."""

    design = "resampled"
    group_key = "user"

    def split(self, data, *, seed):
        users = np.asarray(data.groups["user"])
        index = np.arange(len(users))
        is_test = users == sorted(set(users))[0] if seed == 0 else index % 2 == 0
        return [Split(index[~is_test], index[is_test], tuple(users[is_test].tolist()))]


@hookimpl
def register_splits(register):
    register("fixed-halves", "design_splits:FixedHalves", summary="test split (fixed halves)")
    register("leaky-users", "design_splits:LeakyUsers", summary="test split (leaks users)")
