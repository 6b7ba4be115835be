"""Conformance checks for classifiers: the same checks for built-ins and plugins.

::

    from tactbench.classifiers.conformance import check_classifier
    check_classifier("my-classifier:epochs=1")   # raises AssertionError listing failures

Pass a spec with cheap options: the checks fit the classifier three times on a
few dozen tiny windows (12 × 12 images, or 20-taxel vectors for a classifier
whose ``frame_rank`` is 1). What is checked, after the contract
(:data:`tactbench.contracts.CLASSIFIER`, checked when the registry builds it):

- ``fit`` returns a JSON-ready dict with ``epochs``, ``train_seconds`` and
  ``final_loss``; ``n_classes`` from ``fit(n_classes=K)`` is honoured;
- ``predict_proba`` gives float32 ``(B, K)`` rows that sum to 1, ``predict``
  int64 ``(B,)`` equal to their argmax, for a ``Windows`` and an array alike;
- the same seed gives identical probabilities on the CPU;
- ``save``/``load_model`` round-trips the predictions and the metadata;
- predicting before ``fit`` raises.
"""

from __future__ import annotations

import json
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from tactbench.boundary import labels_problem, proba_problem
from tactbench.classifiers.io import load_model
from tactbench.contracts import CLASSIFIER
from tactbench.data.windows import test_windows, training_windows
from tactbench.plugins import load_registry


def tiny_windows(frame_rank: int | None, *, n: int = 18, L: int = 3, seed: int = 0):
    """Training and test :class:`~tactbench.data.windows.Windows` of an easy 3-class task."""
    rng = np.random.default_rng(seed)
    seqs, labels = [], []
    for i in range(n):
        k = i % 3
        t_len = int(rng.integers(2, 6))
        if frame_rank == 1:
            seq = rng.random((t_len, 20), dtype=np.float32) * 0.1
            seq[:, k * 6:(k + 1) * 6] += 0.8
        else:
            seq = rng.random((t_len, 1, 12, 12), dtype=np.float32) * 0.1
            seq[:, :, 4 * k:4 * k + 4, 2:10] += 0.8
        seqs.append(seq.clip(0, 1))
        labels.append(k)
    return training_windows(seqs, labels, L), test_windows(seqs, labels, L)


def check_classifier(spec: str, *, registry: Any = None) -> None:
    """Run every check on the classifier ``spec``; ``AssertionError`` lists the failures."""
    registry = registry or load_registry()
    build = lambda: registry.build("classifier", spec)  # noqa: E731
    clf = build()
    train, test = tiny_windows(CLASSIFIER.get(clf, "frame_rank"))
    failures: list[str] = []

    def expect(ok: bool, message: str) -> None:
        if not ok:
            failures.append(message)

    try:
        clf.predict(test)
        failures.append("predict before fit did not raise")
    except Exception:  # any clear error will do
        pass
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = clf.fit(train, None, seed=5, device="cpu", progress=None, n_classes=4)
        twin = build()
        twin.fit(train, None, seed=5, device="cpu", progress=None, n_classes=4)
    expect(isinstance(report, dict), f"fit returned {type(report).__name__}, not a dict")
    if isinstance(report, dict):
        for key in ("epochs", "train_seconds", "final_loss"):
            expect(key in report, f"fit report lacks '{key}'")
        try:
            json.dumps(report)
        except (TypeError, ValueError) as exc:
            failures.append(f"fit report is not JSON-serialisable: {exc}")
    proba = clf.predict_proba(test)
    expect(isinstance(proba, np.ndarray) and proba.dtype == np.float32
           and proba.shape == (len(test), 4),
           f"predict_proba gave {getattr(proba, 'dtype', type(proba))} "
           f"{getattr(proba, 'shape', '')}, expected float32 ({len(test)}, 4)")
    proba = np.asarray(proba)
    if proba.shape == (len(test), 4):
        expect(bool(np.allclose(proba.sum(1), 1, atol=1e-4)), "probabilities do not sum to 1")
        # the rules the runner applies to what a classifier returns (tactbench.boundary)
        problem = proba_problem(proba, len(test), 4)
        expect(problem is None, str(problem))
        pred = clf.predict(test)
        problem = labels_problem(pred, len(test), 4)
        expect(problem is None, str(problem))
        expect(pred.dtype == np.int64 and pred.shape == (len(test),),
               f"predict gave {pred.dtype} {pred.shape}, expected int64 ({len(test)},)")
        expect(np.array_equal(pred, proba.argmax(1)), "predict is not the argmax of "
                                                      "predict_proba")
        as_array = clf.predict_proba(test.batch(slice(None)))
        expect(bool(np.allclose(as_array, proba, atol=1e-5)),
               "an array of windows and the Windows object give different probabilities")
        expect(np.array_equal(twin.predict_proba(test), proba),
               "the same seed gave different probabilities on the CPU")
        with tempfile.TemporaryDirectory() as tmp:
            meta = {"encoder": "raw", "classes": ["a", "b", "c", "d"]}
            path = clf.save(Path(tmp) / "model.safetensors", meta)
            loaded, got = load_model(path, registry=registry)
            expect(got == meta, f"metadata came back as {got!r}")
            expect(np.array_equal(loaded.predict_proba(test), proba),
                   "a saved and loaded model predicts differently")
    if failures:
        raise AssertionError(f"classifier '{spec}' fails {len(failures)} check(s):\n- "
                             + "\n- ".join(failures))
