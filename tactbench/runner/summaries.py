"""Summaries of result rows: accuracy and costs over seeds, the cells a run compares.

Rows of failed cells (``status: "failed"``, see :mod:`tactbench.runner.results`) are left
out of every summary and listed on their own (:func:`failed_cells`). This module groups
rows into cells (:func:`cell_groups`), names them (:func:`spec_labels`) and reads the
contrasts that pair them (:func:`parse_contrast`); the paired comparisons are
:mod:`tactbench.runner.comparisons`, the statistics :mod:`tactbench.runner.statistics`.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter
from typing import Any, Iterable, Mapping, Sequence

from tactbench.errors import InputError
from tactbench.runner.learning import LEARNING_FIELD, flagged_runs
from tactbench.runner.results import failed_rows, ok_rows
from tactbench.runner.statistics import seed_summary, variance_components

GROUP_KEYS = ("dataset", "split", "encoder", "classifier", "L")
#: The factors a paired comparison may differ in (the rest of GROUP_KEYS is shared).
FACTORS = ("encoder", "classifier", "L")
#: The confidence of every interval of the reports.
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


def spec_labels(specs: Iterable[str]) -> dict[str, str]:
    """Spec → the name the reports show for it, among ``specs`` (those of one run).

    A spec whose :func:`short_name` no other spec shares is shown by it, as always. Specs
    that share one are told apart by the options that differ among them, by key:
    ``small-cnn-lstm (width=16)`` and ``small-cnn-lstm (width=8)``, several joined by
    ``"; "`` (a label holds no comma: contrast labels join factors with commas); an option
    one of them lacks shows as ``key=default``. Specs still shown alike (the same options
    spelled in another order) are shown whole.
    """
    groups: dict[str, list[str]] = {}
    for spec in dict.fromkeys(str(s) for s in specs):
        groups.setdefault(short_name(spec), []).append(spec)
    labels: dict[str, str] = {}
    for short, members in groups.items():
        if len(members) == 1:
            labels[members[0]] = short
            continue
        options = {spec: _options_text(spec) for spec in members}
        keys = sorted({k for o in options.values() for k in o})
        differ = [k for k in keys if len({o.get(k) for o in options.values()}) > 1]
        for spec in members:
            shown = "; ".join(f"{k}={options[spec].get(k, 'default')}" for k in differ)
            labels[spec] = f"{short} ({shown})"
    count = Counter(labels.values())
    return {spec: spec if count[label] > 1 else label for spec, label in labels.items()}


def spec_label(spec: Any, labels: Mapping[str, str] | None = None) -> str:
    """``spec``'s label in ``labels`` (:func:`spec_labels`); its short name where
    ``labels`` does not name it."""
    return (labels or {}).get(str(spec)) or short_name(str(spec))


def _options_text(spec: str) -> dict[str, str]:
    """A spec's options as written (``key`` → value text; a bare first value under
    ``_``), for labels: no typing, so a value shows as the spec spells it."""
    options = {}
    for item in spec.partition(":")[2].split(","):
        key, eq, value = item.partition("=")
        if key.strip():
            options[key.strip() if eq else "_"] = value.strip() if eq else key.strip()
    return options


def summarise(rows: Iterable[dict[str, Any]], *, users: Sequence[str] | None = None
              ) -> list[dict[str, Any]]:
    """One summary per (dataset, split, encoder, classifier, L), over seeds.

    Accuracy and costs as mean and sample standard deviation; per-class accuracy as
    means; the confusion matrix row-normalised per seed, then averaged; ``input``: what
    the classifier was fed (images or vectors). With ``users`` (the user of each dataset
    sample, by index), ``per_user_accuracy``: user → accuracy on that user's test
    sequences. Failed cells are left out (:func:`failed_cells` lists them). ``learning``
    (only where a run's model did not learn or transfer, :mod:`tactbench.runner.learning`):
    status → seeds.
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
        flagged = flagged_runs(members)  # status → seeds that did not learn
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


def parse_contrast(text: str) -> tuple[dict[str, str], dict[str, str]]:
    """``"encoder=raw,L=6..encoder=farneback,L=3"`` → the factors of cell A and cell B.

    Each side names the factors (of :data:`FACTORS`) it sets, ``factor=value`` joined by
    commas; both sides name the same factors; the factors neither names are shared, so
    the contrast is made once for each of their combinations in the run. An encoder or
    classifier spec keeps its own commas (``encoder=farneback:levels=3,winsize=9,L=3``):
    a comma starts a new factor only where a factor's name and ``=`` follow it. The
    difference is B − A. Raises :class:`InputError` naming the mistake.
    """
    example = "e.g. encoder=raw,L=6..encoder=farneback,L=3"
    if not isinstance(text, str) or text.count("..") != 1:
        raise InputError(f"contrast {text!r} must be two cells joined by '..' ({example})")
    sides = []
    for part in text.split(".."):
        side: dict[str, str] = {}
        for item in _contrast_items(part):
            factor, eq, value = item.partition("=")
            factor, value = factor.strip(), value.strip()
            if not eq or not factor or not value:
                raise InputError(f"contrast {text!r}: {item.strip()!r} is not factor=value "
                                 f"({example})")
            if factor not in FACTORS:
                raise InputError(f"contrast {text!r}: unknown factor {factor!r} (factors: "
                                 f"{', '.join(FACTORS)})")
            if factor in side:
                raise InputError(f"contrast {text!r}: factor {factor!r} is given twice")
            if factor == "L":
                try:
                    int(value)
                except ValueError:
                    raise InputError(f"contrast {text!r}: L must be a whole number, got "
                                     f"{value!r}") from None
            side[factor] = value
        sides.append(side)
    a, b = sides
    if set(a) != set(b):
        raise InputError(f"contrast {text!r}: both sides must set the same factors "
                         f"({', '.join(sorted(a))} against {', '.join(sorted(b))})")
    if a == b:
        raise InputError(f"contrast {text!r} compares a cell with itself")
    return a, b


def _contrast_items(side: str) -> list[str]:
    """One side of a contrast split into its ``factor=value`` items: a comma-separated
    piece that does not start with a factor's name and ``=`` continues the spec before
    it (an option of an encoder or classifier spec, ``farneback:levels=3,winsize=9``)."""
    items: list[str] = []
    for piece in side.split(","):
        starts_factor = piece.partition("=")[0].strip() in FACTORS
        if items and not starts_factor and ":" in items[-1]:
            items[-1] += "," + piece
        else:
            items.append(piece)
    return items


def _matches(cell: dict[str, Any], side: dict[str, str], labels: Mapping[str, str]) -> bool:
    for factor, value in side.items():
        got = cell[factor]
        if factor == "L":
            if int(got) != int(value):
                return False
        elif factor == "classifier":
            if value not in (str(got), short_name(str(got)), str(got).split(":")[0],
                             spec_label(got, labels)):
                return False
        elif str(got) != value:
            return False
    return True


def contrast_pairs(contrast: str, cells: Sequence[dict[str, Any]]) -> list[tuple[int, int]]:
    """The pairs (index of A, index of B) of ``cells`` (dicts of :data:`FACTORS`) that
    ``contrast`` (:func:`parse_contrast`) names: A and B match their sides and agree on
    every factor the contrast does not set. A side names a classifier by its full spec,
    its name, its short name or its label among the cells' (:func:`spec_labels`)."""
    a_side, b_side = parse_contrast(contrast)
    rest = [f for f in FACTORS if f not in a_side]
    labels = spec_labels(c["classifier"] for c in cells)
    return [(i, j) for i, ci in enumerate(cells) for j, cj in enumerate(cells)
            if i != j and _matches(ci, a_side, labels) and _matches(cj, b_side, labels)
            and all(ci[f] == cj[f] for f in rest)]


def check_contrasts(contrasts: Sequence[str], cells: Sequence[dict[str, Any]]) -> None:
    """Refuse a contrast that names no pair of ``cells`` (before any work)."""
    for text in contrasts:
        if not contrast_pairs(text, cells):
            raise InputError(f"contrast {text!r} names no two cells of this run (cells "
                             f"that match each side and share every other factor)")


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
    (:func:`tactbench.runner.statistics.variance_components`; test sampling as
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

