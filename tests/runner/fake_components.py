"""Classifier plugins for the runner's tests, importable in worker processes.

This folder is put on ``sys.path`` and ``PYTHONPATH`` by the ``fake_registry`` fixture
(tests/runner/conftest.py), so ``fake_components:...`` targets load in spawned and dask
workers too. The module itself is the plugin object (``register_classifiers``).
"""

from __future__ import annotations

import os

from tactbench import hookimpl
from tactbench.classifiers.classical import PooledLogReg

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


@hookimpl
def register_classifiers(register):
    for name, cls in (("added-logreg", "AddedLogReg"), ("failing", "FailingLogReg"),
                      ("interrupted", "InterruptedLogReg")):
        register(name, f"fake_components:{cls}", summary=f"test classifier ({name})")
