"""Summaries of result rows: accuracy and costs over seeds, and paired comparisons.

Rows of failed cells (``status: "failed"``, see :mod:`tactbench.runner.store`) are left
out of every summary and listed on their own (:func:`failed_cells`). The statistics
themselves are :mod:`tactbench.runner.statistics`; this module groups rows into cells and
pairs of cells and hands them over.
"""

from __future__ import annotations

import math
import statistics
from typing import Any, Iterable, Sequence

from tactbench.runner.store import failed_rows, ok_rows

GROUP_KEYS = ("dataset", "split", "encoder", "classifier", "L")


#: The factors a paired comparison may differ in (the rest of GROUP_KEYS is shared).
FACTORS = ("encoder", "classifier", "L")


CONFIDENCE = 0.95


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    if not vals:
        return float("nan"), float("nan")
    if len(vals) == 1:
        return vals[0], 0.0
    return statistics.fmean(vals), statistics.stdev(vals)


def short_name(spec: str) -> str:
    """``small-cnn-lstm:epochs=4,...`` → ``small-cnn-lstm``; a component's ``estimator``
    stays in the name (``sklearn:C=10,estimator=SVC`` → ``sklearn:SVC``), as it says what
    the component is."""
    name, _, rest = spec.partition(":")
    for item in rest.split(","):
        key, _, value = item.partition("=")
        if key.strip() == "estimator" and value.strip():
            return f"{name}:{value.strip()}"
    return name


def summarise(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """One summary per (dataset, split, encoder, classifier, L), over seeds.

    Accuracy and costs as mean and sample standard deviation; per-class accuracy as
    means; the confusion matrix row-normalised per seed, then averaged. Failed cells
    are left out (:func:`failed_cells_markdown` lists them).
    """
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
        out.append(summary)
    out.sort(key=lambda s: (s["dataset"], s["split"], s["L"], short_name(s["classifier"]),
                            s["encoder"]))
    return out


def _seed_interval(accuracies: Sequence[float]) -> list[float] | None:
    """95 % t-interval of the mean accuracy over seeds (None for one seed)."""
    from tactbench.runner.statistics import seed_summary

    vals = [float(a) for a in accuracies if a is not None and not math.isnan(a)]
    if len(vals) < 2:
        return None
    res = seed_summary(vals, confidence=CONFIDENCE)
    # an accuracy lies in [0, 1]; the t-interval of a mean near either end can pass it
    return None if res.low is None else [max(0.0, res.low), min(1.0, res.high)]


def comparisons(rows: Iterable[dict[str, Any]], *, n_resamples: int | None = None
                ) -> list[dict[str, Any]]:
    """Paired comparisons of every two summaries that differ in one of :data:`FACTORS`.

    Only seeds both cells finished, and test sequences both predicted, are compared
    (rows without ``test_predictions``, written before they were kept, are left out).
    Each entry: ``factor``, ``a``/``b`` (the two cells' factor values), the shared
    ``dataset``, ``split`` and other factors, and the fields of
    :class:`tactbench.runner.statistics.PairedDifference` (``difference`` = accuracy of B − A).
    A is the cell that comes first in the run (the scene's order), so a run listing
    ``raw`` before ``farneback`` reports farneback − raw.
    """
    import numpy as np

    from tactbench.runner.statistics import N_RESAMPLES, paired_difference, pairs_differing_in_one_factor

    groups: dict[tuple, dict[int, dict[str, Any]]] = {}
    for row in ok_rows(rows):
        if not row.get("test_predictions"):
            continue
        groups.setdefault(tuple(row[k] for k in GROUP_KEYS), {})[int(row["seed"])] = row
    blocks: dict[tuple, list[tuple]] = {}
    for key in groups:  # first-appearance order within each (dataset, split)
        blocks.setdefault(key[:2], []).append(key)
    out = []
    for (dataset, split), keys in blocks.items():
        cells = [dict(zip(FACTORS, key[2:])) for key in keys]
        for pair in pairs_differing_in_one_factor(cells):
            ga, gb = groups[keys[pair.a]], groups[keys[pair.b]]
            y, pa, pb, seeds, seqs = [], [], [], [], []
            for seed in sorted(set(ga) & set(gb)):
                ta, tb = _predictions(ga[seed]), _predictions(gb[seed])
                for index in sorted(set(ta) & set(tb)):
                    if ta[index][0] != tb[index][0]:  # same sequence, other label: not paired
                        continue
                    y.append(ta[index][0])
                    pa.append(ta[index][1])
                    pb.append(tb[index][1])
                    seeds.append(seed)
                    seqs.append(index)
            if not y:
                continue
            res = paired_difference(np.asarray(y), np.asarray(pa), np.asarray(pb),
                                    np.asarray(seeds), sequence_ids=np.asarray(seqs),
                                    confidence=CONFIDENCE,
                                    n_resamples=n_resamples or N_RESAMPLES, seed=0)
            shared = {k: v for k, v in cells[pair.a].items() if k != pair.factor}
            out.append({"dataset": dataset, "split": split, "factor": pair.factor,
                        "a": pair.value_a, "b": pair.value_b, **shared, **res.as_dict()})
    return out


def _predictions(row: dict[str, Any]) -> dict[int, tuple[int, int]]:
    """Test sequence index → (true label, predicted label) of one row."""
    tp = row["test_predictions"]
    return {int(i): (int(t), int(p))
            for i, t, p in zip(tp["indices"], tp["labels"], tp["predictions"])}


def peak_step(rows: Sequence[dict[str, Any]]) -> str:
    """The step that set the peak memory of most of ``rows`` (the first seed's on a tie);
    "-" for rows that do not say (written before steps were recorded)."""
    steps = [r.get("peak_step") for r in rows if r.get("peak_step")]
    if not steps:
        return "-"
    return max(dict.fromkeys(steps), key=steps.count)


def failed_cells(rows: Iterable[dict[str, Any]]) -> list[dict[str, str]]:
    """One line per failed cell: ``encoder``, ``classifier`` (short), ``L``, ``seed``,
    ``error`` (``Type: message``, first line) and ``key``."""
    out = []
    for r in failed_rows(rows):
        error = r.get("error", {})
        message = str(error.get("message", "")).strip().splitlines()
        out.append({"encoder": r["encoder"], "classifier": short_name(r["classifier"]),
                    "L": str(r["L"]), "seed": str(r["seed"]), "key": r["key"],
                    "error": f"{error.get('type', 'Error')}: {message[0] if message else ''}"})
    return out

