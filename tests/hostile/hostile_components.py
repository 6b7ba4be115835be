"""Hostile plugin components for tests/test_hardening_boundary.py: encoders and
classifiers whose outputs break their contracts. Importable in worker processes (this
folder is put on ``sys.path`` and ``PYTHONPATH`` by the test's fixture)."""

from __future__ import annotations

import numpy as np

from tactbench import hookimpl
from tactbench.classifiers.classical import PooledLogReg


class _Image:
    channels = ("v",)
    ranges = ((0.0, 1.0),)
    version = "1"

    def encode(self, seq):
        seq = np.asarray(seq, dtype=np.float32)
        return self.out(seq[:, None])

    def encode_vectors(self, seq):
        return self.out(np.asarray(seq, dtype=np.float32))


class NaNEncoder(_Image):
    def out(self, x):
        return np.full_like(x, np.nan)


class HugeEncoder(_Image):
    """float64 values a million times the declared range."""

    def out(self, x):
        return x.astype(np.float64) * 1e6


class ScaledEncoder(_Image):
    """float32, in dtype, but far outside the declared range."""

    def out(self, x):
        return x * 1e6


class TwoChannelEncoder(_Image):
    """Declares one channel, returns two."""

    def out(self, x):
        return np.concatenate([x, x], axis=1)


class _Proba(PooledLogReg):
    def predict_proba(self, x):
        p = super().predict_proba(x)
        return self.bend(np.asarray(p))

    def predict(self, x):
        return np.asarray(self.predict_proba(x)).argmax(axis=1).astype(np.int64)


class NaNProba(_Proba):
    def bend(self, p):
        return np.full_like(p, np.nan)


class FewColumns(_Proba):
    def bend(self, p):
        q = p[:, :-1]
        return q / q.sum(axis=1, keepdims=True)


class NegativeProba(_Proba):
    def bend(self, p):
        q = p.copy()
        q[:, 0] -= 0.5
        q[:, 1] += 0.5
        return q


class UnnormalisedProba(_Proba):
    def bend(self, p):
        return p * 3


class MinusOne(PooledLogReg):
    def predict(self, x):
        return np.full(len(x), -1, dtype=np.int64)


ENCODERS = {"nan-enc": "NaNEncoder", "huge-enc": "HugeEncoder",
            "scaled-enc": "ScaledEncoder", "two-channel-enc": "TwoChannelEncoder"}
CLASSIFIERS = {"nan-proba": "NaNProba", "few-columns": "FewColumns",
               "negative-proba": "NegativeProba", "unnormalised-proba": "UnnormalisedProba",
               "minus-one": "MinusOne"}


@hookimpl
def register_encoders(register):
    for name, cls in ENCODERS.items():
        register(name, f"hostile_components:{cls}", summary=f"hostile encoder ({name})")


@hookimpl
def register_classifiers(register):
    for name, cls in CLASSIFIERS.items():
        register(name, f"hostile_components:{cls}", summary=f"hostile classifier ({name})")
