"""Summaries of result rows: accuracy and costs over seeds, and paired comparisons.

Rows of failed cells (``status: "failed"``, see :mod:`tactbench.runner.results`) are left
out of every summary and listed on their own (:func:`failed_cells`). The statistics
themselves are :mod:`tactbench.runner.statistics`; this module groups rows into cells and
pairs of cells and hands them over.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter
from typing import Any, Iterable, Mapping, Sequence

from tactbench.data.splits import user_folds
from tactbench.errors import InputError
from tactbench.runner.results import failed_rows, ok_rows
from tactbench.runner.statistics import (
    TARGET_HALF_WIDTH,
    corrected_t,
    holm,
    mcnemar_p,
    pairs_differing_in_one_factor,
    runs_needed,
    seed_summary,
    sign_flip_p,
    tost_p,
    variance_components,
    verdict,
)

GROUP_KEYS = ("dataset", "split", "encoder", "classifier", "L")
#: The factors a paired comparison may differ in (the rest of GROUP_KEYS is shared).
FACTORS = ("encoder", "classifier", "L")
CONFIDENCE = 0.95
#: The verdict's p: False (the choice, docs/statistics.md), the corrected t's, with the
#: exact sign-flip p reported beside it as a distribution-free check; True, the larger of
#: the two (the sign-flip's floor 2 / 2^J then forbids any verdict below 6 runs).
PERMUTATION_GOVERNS = False


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
    sequences. Failed cells are left out (:func:`failed_cells` lists them).
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


def _cell_groups(rows: Iterable[dict[str, Any]]) -> dict[tuple, dict[tuple, dict[str, Any]]]:
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


def comparisons(rows: Iterable[dict[str, Any]], *, contrasts: Sequence[str] = (),
                margin: float | None = None, users: Sequence[str] | None = None,
                confidence: float = CONFIDENCE) -> list[dict[str, Any]]:
    """Paired comparisons at run level: every two cells that differ in one of
    :data:`FACTORS`, and every pair a ``contrasts`` entry names (:func:`parse_contrast`).

    Only runs (seeds) both cells finished, and test sequences both predicted with the
    same label, are paired; rows without ``test_predictions`` are left out. A is the
    cell that comes first in the run (the scene's order), so a run listing ``raw`` before
    ``farneback`` reports farneback − raw; a contrast gives its own A and B.

    Every comparison of one run forms one family: its p-values (the corrected t's; see
    :data:`PERMUTATION_GOVERNS`) are Holm-adjusted together, and the verdicts
    rest on the adjusted ones (:func:`tactbench.runner.statistics.verdict`). ``margin``
    (points) adds the equivalence test; ``users`` (the user of each dataset sample, by
    index) adds per-user gains. See :func:`paired_runs` for each entry's fields.
    """
    if margin is not None and not (isinstance(margin, (int, float)) and margin > 0):
        raise InputError(f"margin must be a number of points > 0, got {margin!r}")
    groups = _cell_groups(rows)
    blocks: dict[tuple, list[tuple]] = {}
    for key in groups:  # first-appearance order within each (dataset, split)
        blocks.setdefault(key[:2], []).append(key)
    out: list[dict[str, Any]] = []
    for (dataset, split), keys in blocks.items():
        cells = [dict(zip(FACTORS, key[2:])) for key in keys]
        labels = spec_labels(c["classifier"] for c in cells)
        todo = [(p.a, p.b, p.factor, p.value_a, p.value_b)
                for p in pairs_differing_in_one_factor(cells)]
        for text in contrasts:
            a_side, b_side = parse_contrast(text)
            for i, j in contrast_pairs(text, cells):
                todo.append((i, j, "contrast", _side_label(cells[i], a_side, labels),
                             _side_label(cells[j], b_side, labels)))
        for i, j, factor, value_a, value_b in todo:
            res = paired_runs(groups[keys[i]], groups[keys[j]], margin=margin, users=users,
                              confidence=confidence)
            if res is None:
                continue
            named = set(parse_contrast_factors(factor, value_a))
            shared = {k: v for k, v in cells[i].items() if k != factor and k not in named}
            out.append({"dataset": dataset, "split": split, "factor": factor,
                        "a": value_a, "b": value_b, **shared, **res})
    # the family: this run's comparisons; Holm on the governing p (NaN: too few runs)
    alpha = 1 - confidence
    p = holm([c["p"] if c["p"] is not None else math.nan for c in out])
    eq = holm([c["equivalence_p"] if c.get("equivalence_p") is not None else math.nan
               for c in out])
    for c, p_adj, eq_adj in zip(out, p, eq):
        c["p_holm"] = None if math.isnan(p_adj) else float(p_adj)
        c["equivalence_p_holm"] = None if math.isnan(eq_adj) else float(eq_adj)
        c["family_size"] = int(sum(x["p"] is not None for x in out))
        c["verdict"], c["note"] = verdict(
            c["low"], c["high"], 1.0 if c["p_holm"] is None else c["p_holm"], c["runs"],
            alpha=alpha, discordant_recordings=c["discordant_recordings"],
            equivalence_p_adjusted=c["equivalence_p_holm"])
        floor = 2.0 ** (1 - c["runs"])
        if PERMUTATION_GOVERNS and c["verdict"] == "unresolved" and not c["note"] \
                and floor >= alpha:
            c["note"] = (f"{c['runs']} runs: the sign-flip floor is p = {floor:.3g}; a "
                         f"verdict needs ≥ {_runs_for_floor(alpha)} runs")
        elif c["verdict"] in ("A better", "B better") and floor >= alpha:
            c["note"] = (f"rests on the corrected t: with {c['runs']} runs the exact "
                         f"sign-flip test cannot go below p = {floor:.3g}")
    return out


def _runs_for_floor(alpha: float) -> int:
    """The fewest runs whose smallest sign-flip p (2 / 2^J) is below ``alpha``."""
    j = 1
    while 2.0 ** (1 - j) >= alpha:
        j += 1
    return j


def _side_label(cell: dict[str, Any], side: dict[str, str],
                labels: Mapping[str, str] | None = None) -> str:
    """``encoder=raw,L=6`` with the cell's own values (a classifier by its label in
    ``labels``, :func:`spec_labels`)."""
    return ",".join(f"{f}={spec_label(cell[f], labels) if f == 'classifier' else cell[f]}"
                    for f in side)


def parse_contrast_factors(factor: str, label: Any) -> list[str]:
    """The factors a comparison's ``a`` value sets: a contrast's (``encoder=raw,L=6``),
    or the one factor of a one-factor pair."""
    if factor != "contrast":
        return [factor]
    return [item.partition("=")[0] for item in str(label).split(",")]


def _aligned(row_a: dict[str, Any], row_b: dict[str, Any]):
    """(sequence ids, true labels, correct A, correct B) of the test sequences both rows
    predicted with the same label."""
    import numpy as np

    ta, tb = _predictions(row_a), _predictions(row_b)
    ids = [i for i in sorted(set(ta) & set(tb)) if ta[i][0] == tb[i][0]]
    y = np.array([ta[i][0] for i in ids], dtype=np.int64)
    ca = np.array([ta[i][1] == ta[i][0] for i in ids], dtype=bool)
    cb = np.array([tb[i][1] == tb[i][0] for i in ids], dtype=bool)
    return np.array(ids, dtype=np.int64), y, ca, cb


def _ratio(rows: Sequence[dict[str, Any]]) -> tuple[float, str]:
    """The correction n_test/n_train of these runs and the test's name."""
    folds = rows[0].get("folds")
    if folds:
        return 1.0 / (int(folds) - 1), (f"corrected repeated {int(folds)}-fold t "
                                        "(Bouckaert–Frank)")
    ratios = [r["n_test"] / r["n_train"] for r in rows if r.get("n_train") and r.get("n_test")]
    return (statistics.fmean(ratios) if ratios else 1.0,
            "corrected resampled t (Nadeau–Bengio)")


def paired_runs(runs_a: dict[tuple, dict[str, Any]], runs_b: dict[tuple, dict[str, Any]], *,
                margin: float | None = None, users: Sequence[str] | None = None,
                confidence: float = CONFIDENCE) -> dict[str, Any] | None:
    """Two cells compared run by run (``runs_*``: run key → row); None when they share
    no run with a paired test sequence.

    A run is one split seed; where the rows vary the initialisation too (``init_seed``),
    a split's runs are averaged first and the split is the unit. Fields:

    - ``difference`` (B − A, mean over runs), ``low``/``high``: the run-level interval
      (``method``: corrected resampled t with ``ratio`` = n_test/n_train, or corrected
      repeated k-fold t with 1/(K − 1)); ``per_run`` (seed → d_s), ``runs``,
      ``b_better_runs``/``a_better_runs``/``tied_runs``, ``p_b_better`` (share of runs
      where B is higher);
    - ``t_p``, ``permutation_p`` (exact sign-flip over runs), ``p`` = the larger (None
      with fewer than 2 runs);
    - ``equivalence_margin`` (points) and ``equivalence_p`` (TOST) with a margin;
    - ``runs_needed`` for an interval of ±``runs_needed_half_width`` points;
    - ``discordant_rows`` (``a_only``, ``b_only``), ``discordant_recordings``,
      ``test_recordings``; ``mcnemar_per_seed`` (seed → p; about those trained models
      only);
    - ``per_class``: class → gain with its run-level interval;
    - ``per_user`` (with ``users``): users tested, helped, hurt, median and quartiles of
      the per-user gain (points), and user → gain.
    """
    import numpy as np

    shared = sorted(set(runs_a) & set(runs_b), key=lambda k: (k[0], -1 if k[1] is None else k[1]))
    per_seed: dict[tuple, Any] = {}
    for key in shared:
        ids, y, ca, cb = _aligned(runs_a[key], runs_b[key])
        if len(ids):
            per_seed[key] = (ids, y, ca, cb)
    if not per_seed:
        return None
    rows_a = [runs_a[k] for k in per_seed]
    ratio, method = _ratio(rows_a)
    classes = list(rows_a[0]["classes"])

    # the unit: a split seed (its init seeds averaged)
    splits: dict[int, list[tuple]] = {}
    for key in per_seed:
        splits.setdefault(key[0], []).append(key)
    d_run = np.array([np.mean([(per_seed[k][3].mean() - per_seed[k][2].mean())
                               for k in ks]) for ks in splits.values()])
    acc_a = float(np.mean([per_seed[k][2].mean() for k in per_seed]))
    acc_b = float(np.mean([per_seed[k][3].mean() for k in per_seed]))
    j = len(d_run)
    diff = float(d_run.mean())
    # K folds repeated over seeds, with the users known: Bouckaert & Frank's k·r per-fold
    # differences carry the t; the sign-flip test stays over the seeds
    d_t = d_run
    folds = rows_a[0].get("folds")
    if folds and users is not None:
        per_fold = _fold_differences(per_seed, splits, runs_a, users, int(folds))
        if per_fold is not None:
            d_t = per_fold
            method += f" over {len(per_fold)} fold differences"
    res: dict[str, Any] = {
        "difference": diff, "low": diff, "high": diff, "confidence": confidence,
        "method": method, "ratio": ratio, "df": None, "runs": j,
        "per_run": {str(s): float(v) for s, v in zip(splits, d_run)},
        "b_better_runs": int(np.sum(d_run > 0)), "a_better_runs": int(np.sum(d_run < 0)),
        "tied_runs": int(np.sum(d_run == 0)), "p_b_better": float(np.mean(d_run > 0)),
        "t_p": None, "permutation_p": float(sign_flip_p(d_run)), "p": None,
        "accuracy_a": acc_a, "accuracy_b": acc_b,
    }
    sd = float(d_run.std(ddof=1)) if j > 1 else None
    if j >= 2:
        t = corrected_t(d_t, ratio, confidence=confidence)
        # a difference of accuracies lies in [−1, 1]; the t-interval of a few runs can pass it
        res.update(low=max(-1.0, float(t["low"])), high=min(1.0, float(t["high"])),
                   df=int(t["df"]), t_p=float(t["p"]))
        res["p"] = (max(res["t_p"], res["permutation_p"]) if PERMUTATION_GOVERNS
                    else res["t_p"])
    half = (margin / 100) if margin else TARGET_HALF_WIDTH
    res["equivalence_margin"] = margin
    res["equivalence_p"] = (float(tost_p(d_run, ratio, margin / 100))
                            if margin and j >= 2 else None)
    res["runs_needed"] = runs_needed(sd, ratio, half, confidence=confidence)
    res["runs_needed_half_width"] = 100 * half
    a_only = sum(int(np.sum(v[2] & ~v[3])) for v in per_seed.values())
    b_only = sum(int(np.sum(v[3] & ~v[2])) for v in per_seed.values())
    discordant = set()
    recordings = set()
    for ids, _, ca, cb in per_seed.values():
        discordant.update(ids[ca != cb].tolist())
        recordings.update(ids.tolist())
    res.update(a_only=a_only, b_only=b_only, discordant_recordings=len(discordant),
               test_recordings=len(recordings),
               mcnemar_per_seed={_seed_label(k): mcnemar_p(v[2], v[3])
                                 for k, v in per_seed.items()})
    res["per_class"] = _per_class_gains(per_seed, splits, classes, ratio, confidence)
    res["per_user"] = (_per_user_gains(per_seed, users) if users is not None else None)
    return res


def _fold_differences(per_seed, splits, runs, users, folds: int):
    """The differences B − A of every (split seed, fold) of a ``users:folds=K`` run —
    each fold's test recordings found again from the seed, as the cell drew them
    (:func:`tactbench.data.splits.user_folds`), a split seed's init seeds averaged — or
    None when the folds cannot be made again here."""
    import numpy as np

    users = [str(u) for u in users]
    out = []
    for seed, keys in splits.items():
        row = runs[keys[0]]
        tp = row["test_predictions"]
        labels = np.zeros(len(users), dtype=np.int64)
        try:
            labels[np.asarray(tp["indices"], dtype=np.int64)] = tp["labels"]
            made = user_folds(users, labels, seed=int(row.get("split_seed", seed)),
                              folds=folds)
        except (InputError, IndexError):
            return None
        fold_of = np.full(len(users), -1)
        for k, split in enumerate(made):
            fold_of[split.test] = k
        for k in range(folds):
            vals = []
            for key in keys:
                ids, _, ca, cb = per_seed[key]
                m = fold_of[ids] == k
                if m.any():
                    vals.append(float(cb[m].mean() - ca[m].mean()))
            if vals:
                out.append(float(np.mean(vals)))
    return np.array(out) if len(out) >= 2 else None


def _seed_label(key: tuple) -> str:
    return str(key[0]) if key[1] is None else f"{key[0]}/{key[1]}"


def _per_class_gains(per_seed, splits, classes, ratio, confidence) -> dict[str, Any]:
    """Class → gain B − A on that class's test sequences, per run, with the run-level
    interval (None where fewer than 2 runs test the class)."""
    import numpy as np

    out = {}
    for c, name in enumerate(classes):
        d = []
        for ks in splits.values():
            vals = [per_seed[k][3][per_seed[k][1] == c].mean()
                    - per_seed[k][2][per_seed[k][1] == c].mean()
                    for k in ks if np.any(per_seed[k][1] == c)]
            if vals:
                d.append(float(np.mean(vals)))
        if not d:
            continue
        entry = {"difference": float(np.mean(d)), "low": None, "high": None, "runs": len(d)}
        if len(d) >= 2:
            t = corrected_t(np.array(d), ratio, confidence=confidence)
            entry.update(low=max(-1.0, float(t["low"])), high=min(1.0, float(t["high"])))
        out[name] = entry
    return out


def _per_user_gains(per_seed, users: Sequence[str]) -> dict[str, Any]:
    """Per user (the test sequences of each user, over the runs that test them): the
    gain B − A, and how many users it helped or hurt, its median and quartiles."""
    import numpy as np

    users = list(users)
    gains: dict[str, list[float]] = {}
    for ids, _, ca, cb in per_seed.values():
        who = np.array([str(users[i]) for i in ids])
        for u in dict.fromkeys(who.tolist()):
            m = who == u
            gains.setdefault(u, []).append(float(cb[m].mean() - ca[m].mean()))
    per_user = {u: float(np.mean(g)) for u, g in sorted(gains.items())}
    values = np.array(list(per_user.values()))
    q25, q50, q75 = np.percentile(values, [25, 50, 75]) if values.size else (math.nan,) * 3
    return {"users": len(per_user), "helped": int(np.sum(values > 0)),
            "hurt": int(np.sum(values < 0)), "median": float(q50), "q25": float(q25),
            "q75": float(q75), "gains": per_user}


def per_user_accuracy(rows: Iterable[dict[str, Any]], users: Sequence[str]
                      ) -> dict[tuple, dict[str, float]]:
    """Cell (GROUP_KEYS values) → user → accuracy on that user's test sequences, the
    mean over the runs that test the user."""
    import numpy as np

    users = list(users)
    out: dict[tuple, dict[str, float]] = {}
    for key, runs in _cell_groups(rows).items():
        acc: dict[str, list[float]] = {}
        for row in runs.values():
            tp = row["test_predictions"]
            who = np.array([str(users[int(i)]) for i in tp["indices"]])
            right = np.asarray(tp["labels"]) == np.asarray(tp["predictions"])
            for u in dict.fromkeys(who.tolist()):
                acc.setdefault(u, []).append(float(right[who == u].mean()))
        out[key] = {u: float(np.mean(v)) for u, v in sorted(acc.items())}
    return out


def _predictions(row: dict[str, Any]) -> dict[int, tuple[int, int]]:
    """Test sequence index → (true label, predicted label) of one row."""
    tp = row["test_predictions"]
    return {int(i): (int(t), int(p))
            for i, t, p in zip(tp["indices"], tp["labels"], tp["predictions"])}


def variance_decomposition(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """For each cell whose runs vary split and initialisation separately (rows with
    ``init_seed``, at least 2 split seeds × 2 init seeds, every pair run): the variance
    of its accuracy split into split, initialisation and test sampling
    (:func:`tactbench.runner.statistics.variance_components`; test sampling as
    p(1 − p)/n_test), as standard deviations in points."""
    import numpy as np

    out = []
    for key, runs in _cell_groups(rows).items():
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

