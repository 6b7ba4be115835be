"""Summaries of result rows: accuracy and costs over seeds, the cells a run compares.

Rows of failed cells (``status: "failed"``, see :mod:`tactbench.runner.execution.results`)
are left out of every summary and listed on their own (:func:`failed_cells`). This module
groups rows into cells (:func:`cell_groups`); the cells' names and the contrasts that pair
them are :mod:`tactbench.runner.execution.questions`; the paired comparisons are
:mod:`tactbench.runner.analysis.comparisons`, the statistics
:mod:`tactbench.runner.analysis.statistics`.
"""

from __future__ import annotations

import math
import statistics
from typing import Any, Iterable, Sequence

from tactbench.runner.execution.learning import LEARNING_FIELD, summary_learning
from tactbench.runner.execution.questions import short_name, spec_labels
from tactbench.runner.execution.results import failed_rows, ok_rows
from tactbench.runner.analysis.statistics import seed_summary, variance_components

GROUP_KEYS = ("dataset", "split", "encoder", "classifier", "L")
#: The confidence of every interval of the reports.
CONFIDENCE = 0.95


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    if not vals:
        return float("nan"), float("nan")
    if len(vals) == 1:
        return vals[0], 0.0
    return statistics.fmean(vals), statistics.stdev(vals)


def summarise(rows: Iterable[dict[str, Any]], *, users: Sequence[str] | None = None
              ) -> list[dict[str, Any]]:
    """One summary per (dataset, split, encoder, classifier, L), over seeds.

    Accuracy and costs as mean and sample standard deviation; per-class accuracy as
    means; the confusion matrix row-normalised per seed, then averaged; ``input``: what
    the classifier was fed (images or vectors). With ``users`` (the user of each dataset
    sample, by index), ``per_user_accuracy``: user → accuracy on that user's test
    sequences. Failed cells are left out (:func:`failed_cells` lists them). ``learning``
    (only where the cell's runs together did not learn or transfer,
    :func:`tactbench.runner.execution.learning.cell_learning`): status → the seeds judged.
    """
    rows = list(rows)
    by_user = per_user_accuracy(rows, users) if users is not None else {}
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in ok_rows(rows):
        groups.setdefault(tuple(row[k] for k in GROUP_KEYS), []).append(row)
    out = []
    for key, members in groups.items():
        members.sort(key=lambda r: r["seed"])
        classes = members[0]["classes"]
        acc_mean, acc_std = _mean_std([r["accuracy"] for r in members])
        per_class = {c: _mean_std([r["per_class_accuracy"].get(c) for r in members])[0]
                     for c in classes}
        k = len(classes)
        confusion = [[0.0] * k for _ in range(k)]
        for r in members:
            for i, line in enumerate(r["confusion"]):
                total = sum(line) or 1
                for j, v in enumerate(line):
                    confusion[i][j] += v / total / len(members)
        summary = dict(zip(GROUP_KEYS, key))
        imaging = members[0].get("imaging")
        summary["input"] = imaging.get("kind", "-") if isinstance(imaging, dict) else "-"
        interval = _seed_interval([r["accuracy"] for r in members])
        summary.update({
            "seeds": [r["seed"] for r in members],
            "accuracy_mean": acc_mean, "accuracy_std": acc_std,
            "accuracy_ci95": interval,
            "per_class_accuracy": per_class,
            "confusion_normalised": confusion,
            "classes": classes,
        })
        for cost in ("encode_ms_per_frame", "train_s", "inference_ms_per_sequence",
                     "peak_rss_mb"):
            summary[cost + "_mean"], summary[cost + "_std"] = _mean_std(
                [r.get(cost) for r in members])
        summary["peak_step"] = peak_step(members)
        trained = [r["train_accuracy"] for r in members if "train_accuracy" in r]
        if trained:  # rows made before recorded none
            summary["train_accuracy_mean"] = statistics.fmean(trained)
        flagged = summary_learning(members)  # status → seeds, judged together
        if flagged:
            summary[LEARNING_FIELD] = flagged
        if users is not None:
            summary["per_user_accuracy"] = by_user.get(key, {})
        out.append(summary)
    out.sort(key=lambda s: (s["dataset"], s["split"], s["L"], short_name(s["classifier"]),
                            s["encoder"]))
    return out


def _seed_interval(accuracies: Sequence[float]) -> list[float] | None:
    """95 % t-interval of the mean accuracy over seeds (None for one seed)."""
    vals = [float(a) for a in accuracies if a is not None and not math.isnan(a)]
    if len(vals) < 2:
        return None
    res = seed_summary(vals, confidence=CONFIDENCE)
    # an accuracy lies in [0, 1]; the t-interval of a mean near either end can pass it
    return None if res.low is None else [max(0.0, res.low), min(1.0, res.high)]


def _run_key(row: dict[str, Any]) -> tuple[int, int | None]:
    """(split seed, init seed) of a row: the init seed is None unless the run varied it."""
    init = row.get("init_seed")
    return int(row["seed"]), (None if init is None else int(init))


def cell_groups(rows: Iterable[dict[str, Any]]) -> dict[tuple, dict[tuple, dict[str, Any]]]:
    """Cell (GROUP_KEYS values) → run key → row, for ok rows with test predictions."""
    groups: dict[tuple, dict[tuple, dict[str, Any]]] = {}
    for row in ok_rows(rows):
        if not row.get("test_predictions"):
            continue  # written before predictions were kept: nothing to pair
        groups.setdefault(tuple(row[k] for k in GROUP_KEYS), {})[_run_key(row)] = row
    return groups


def per_user_accuracy(rows: Iterable[dict[str, Any]], users: Sequence[str]
                      ) -> dict[tuple, dict[str, float]]:
    """Cell (GROUP_KEYS values) → user → accuracy on that user's test sequences, the
    mean over the runs that test the user."""
    import numpy as np

    users = list(users)
    out: dict[tuple, dict[str, float]] = {}
    for key, runs in cell_groups(rows).items():
        acc: dict[str, list[float]] = {}
        for row in runs.values():
            tp = row["test_predictions"]
            who = np.array([str(users[int(i)]) for i in tp["indices"]])
            right = np.asarray(tp["labels"]) == np.asarray(tp["predictions"])
            for u in dict.fromkeys(who.tolist()):
                acc.setdefault(u, []).append(float(right[who == u].mean()))
        out[key] = {u: float(np.mean(v)) for u, v in sorted(acc.items())}
    return out


def variance_decomposition(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """For each cell whose runs vary split and initialisation separately (rows with
    ``init_seed``, at least 2 split seeds × 2 init seeds, every pair run): the variance
    of its accuracy split into split, initialisation and test sampling
    (:func:`tactbench.runner.analysis.statistics.variance_components`; test sampling as
    p(1 − p)/n_test), as standard deviations in points."""
    import numpy as np

    out = []
    for key, runs in cell_groups(rows).items():
        if any(k[1] is None for k in runs):
            continue
        splits = sorted({k[0] for k in runs})
        inits = sorted({k[1] for k in runs})
        if len(splits) < 2 or len(inits) < 2 or len(runs) != len(splits) * len(inits):
            continue
        acc = np.array([[runs[(s, i)]["accuracy"] for i in inits] for s in splits])
        n_test = float(np.mean([r["n_test"] for r in runs.values()]))
        p = float(acc.mean())
        comp = variance_components(acc, p * (1 - p) / n_test)
        out.append({**dict(zip(GROUP_KEYS, key)), "split_seeds": len(splits),
                    "init_seeds": len(inits),
                    **{f"{k}_sd": 100 * math.sqrt(comp[k]) for k in ("split", "init", "test")},
                    "clipped": comp["clipped"]})
    return out


def peak_step(rows: Sequence[dict[str, Any]]) -> str:
    """The step that set the peak memory of most of ``rows`` (the first seed's on a tie);
    "-" for rows that do not say (written before steps were recorded)."""
    steps = [r.get("peak_step") for r in rows if r.get("peak_step")]
    if not steps:
        return "-"
    return max(dict.fromkeys(steps), key=steps.count)


def failed_cells(rows: Iterable[dict[str, Any]]) -> list[dict[str, str]]:
    """One line per failed cell: ``encoder``, ``classifier`` (its label among the rows'
    classifiers, :func:`spec_labels`), ``L``, ``seed``, ``error`` (``Type: message``,
    first line) and ``key``."""
    rows = list(rows)
    labels = spec_labels(r["classifier"] for r in rows)
    out = []
    for r in failed_rows(rows):
        error = r.get("error", {})
        message = str(error.get("message", "")).strip().splitlines()
        out.append({"encoder": r["encoder"], "classifier": labels[str(r["classifier"])],
                    "L": str(r["L"]), "seed": str(r["seed"]), "key": r["key"],
                    "error": f"{error.get('type', 'Error')}: {message[0] if message else ''}"})
    return out

