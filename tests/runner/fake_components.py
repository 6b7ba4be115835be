"""Classifier, split and test window plugins for the runner's tests, importable in worker
processes.

This folder is put on ``sys.path`` and ``PYTHONPATH`` by the ``fake_registry`` fixture
(tests/runner/conftest.py), so ``fake_components:...`` targets load in spawned and dask
workers too. The module itself is the plugin object (``register_classifiers``, ``register_splits``,
``register_test_windows``).
"""

from __future__ import annotations

import os

import numpy as np

from tactbench import hookimpl
from tactbench.classifiers.classical import PooledLogReg
from tactbench.data.splits import Split
from tactbench.data.windows import Windows, training_windows

#: Set to "1" to make :class:`FailingLogReg` raise in ``fit``; unset, it trains.
FAIL_ENV = "TACTBENCH_TEST_FAIL"


class AddedLogReg(PooledLogReg):
    """logreg under a name only this plugin registers."""

    name = "added-logreg"


class FailingLogReg(PooledLogReg):
    """logreg that raises in ``fit`` while ``$TACTBENCH_TEST_FAIL`` is "1" (a plugin bug)."""

    name = "failing"

    def fit(self, train, val=None, **kwargs):
        if os.environ.get(FAIL_ENV) == "1":
            raise RuntimeError("deliberate failure in fit")
        return super().fit(train, val, **kwargs)


class InterruptedLogReg(PooledLogReg):
    """logreg whose ``fit`` is interrupted as by Ctrl-C."""

    name = "interrupted"

    def fit(self, train, val=None, **kwargs):
        raise KeyboardInterrupt


class ConstantClassifier(PooledLogReg):
    """logreg that fits, then always answers class 0 (a model that learned nothing)."""

    name = "constant"

    def predict_proba(self, windows):
        proba = np.zeros((len(windows), self.n_classes), dtype=np.float32)
        proba[:, 0] = 1.0
        return proba

    def predict(self, windows):
        return np.zeros(len(windows), dtype=np.int64)


@hookimpl
def register_classifiers(register):
    for name, cls in (("added-logreg", "AddedLogReg"), ("failing", "FailingLogReg"),
                      ("interrupted", "InterruptedLogReg"), ("constant", "ConstantClassifier")):
        register(name, f"fake_components:{cls}", summary=f"test classifier ({name})")


class ParitySplit:
    """``parity``: two folds, the even recordings tested in one, the odd in the other;
    a test recording's group is ``even`` or ``odd``."""

    def split(self, data, *, seed):
        index = np.arange(len(data.labels))
        out = []
        for fold, name in enumerate(("even", "odd")):
            test = index[index % 2 == fold]
            out.append(Split(index[index % 2 != fold], test, (name,) * len(test), fold=fold,
                             left_out=(name,)))
        return out


class LastWindow:
    """``last``: train on every window; test on each recording's last ``L`` frames."""

    def training(self, sequences, labels, L, *, prepared=None):
        return training_windows(sequences, labels, L)

    def test(self, sequences, labels, L, *, prepared=None):
        starts = np.asarray([max(0, s.shape[0] - L) for s in sequences], dtype=np.int64)
        return Windows(list(sequences), np.arange(len(sequences), dtype=np.int64), starts,
                       np.asarray(labels, dtype=np.int64), L)

    def combine(self, classifier, windows, n):
        return np.asarray(classifier.predict(windows))


@hookimpl
def register_splits(register):
    register("parity", "fake_components:ParitySplit", summary="test split (parity)")


@hookimpl
def register_test_windows(register):
    register("last", "fake_components:LastWindow", summary="test window (last L frames)")
