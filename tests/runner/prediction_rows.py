"""One stored row of a cell with its per-sequence predictions, for the statistics tests.

The runner's tests that replay comparisons, looks or variance decompositions from rows
build them with :func:`prediction_row`. tests/runner is put on ``sys.path`` by its
conftest.py (the suite imports with ``--import-mode=importlib``), so the tests import this
module by name.
"""

from __future__ import annotations

import numpy as np


def prediction_row(encoder: str, seed: int, truth, predicted, *, split: str = "paper",
                   L: int = 5, classifier: str = "logreg", indices=None,
                   n_train: int | None = None, **extra) -> dict:
    """A finished row of ``encoder`` × ``classifier`` at ``L`` and ``seed`` whose test
    recordings ``indices`` (default ``0..n-1``) have labels ``truth`` and predictions
    ``predicted``; its accuracy is theirs. ``n_train`` defaults to 4 × the test size;
    ``extra`` fields are added as given (e.g. ``independent_runs``)."""
    truth, predicted = list(truth), list(predicted)
    indices = list(range(len(truth))) if indices is None else list(indices)
    acc = float(np.mean(np.asarray(truth) == np.asarray(predicted)))
    return {"key": f"{encoder}-{seed}-{L}", "dataset": "d", "split": split,
            "encoder": encoder, "classifier": classifier, "L": L, "seed": seed,
            "status": "ok", "classes": ["a", "b"], "accuracy": acc,
            "per_class_accuracy": {"a": acc, "b": acc}, "confusion": [[1, 0], [0, 1]],
            "encode_ms_per_frame": 1.0, "train_s": 1.0, "inference_ms_per_sequence": 1.0,
            "peak_rss_mb": 1.0,
            "n_train": 4 * len(truth) if n_train is None else n_train,
            "n_test": len(truth),
            "test_predictions": {"indices": indices, "labels": truth,
                                 "predictions": predicted},
            **extra}
