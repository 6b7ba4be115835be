"""Paired statistics for comparing cells: pure functions over numpy arrays.

Two encoders (or classifiers) in one run are tested on the same test sequences under the
same seeds, so they are compared *paired*, sequence by sequence (see docs/statistics.md):

- :func:`seed_summary`: mean, standard deviation and a 95 % t-interval of the mean
  accuracy over seeds;
- :func:`paired_difference`: the mean difference of accuracy B − A with a bootstrap
  interval over test sequences (``scipy.stats.bootstrap``, resampling within each seed),
  how many seeds agree on its sign, the exact McNemar p-value on the pooled paired
  predictions (``scipy.stats.binomtest``) and a verdict;
- :func:`pairs_differing_in_one_factor`: which cells of a grid to compare.

Nothing here imports the runner; scipy is imported inside the functions.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Hashable, Mapping, Sequence

import numpy as np

from tactbench.errors import InputError

#: Bootstrap resamples in :func:`paired_difference` unless told.
N_RESAMPLES = 4000
#: Fewer test sequences than this give an interval but no verdict: a percentile bootstrap
#: of a handful of sequences is too narrow to call a winner.
MIN_SEQUENCES_FOR_VERDICT = 10
#: Resampled values held at once during the bootstrap (resamples × sequences).
_BOOTSTRAP_BATCH_VALUES = 2_000_000


@dataclass(frozen=True)
class SeedSummary:
    """Accuracy over seeds: ``mean``, ``std`` (ddof = 1; None for one seed), ``n`` seeds,
    and the t-interval of the mean ``[low, high]`` at ``confidence`` (None for one seed,
    with ``note`` saying so)."""

    mean: float
    std: float | None
    n: int
    low: float | None
    high: float | None
    confidence: float
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _check_confidence(confidence: float) -> float:
    try:
        c = float(confidence)
    except (TypeError, ValueError):
        c = float("nan")
    if not 0 < c < 1:
        raise InputError(f"confidence must be between 0 and 1 (e.g. 0.95), got {confidence!r}")
    return c


def seed_summary(accuracies: Sequence[float] | np.ndarray, *,
                 confidence: float = 0.95) -> SeedSummary:
    """Mean ± std of ``accuracies`` (one per seed) and a t-interval of the mean.

    The interval is ``mean ± t(n − 1) · std / √n`` (``scipy.stats.t``): it says where the
    mean over *seeds* would lie with other seeds on the same data, not over other data.
    With one seed there is no interval (``low``/``high`` None, ``note`` says so); with
    identical accuracies it is the point itself.
    """
    from scipy import stats

    conf = _check_confidence(confidence)
    acc = np.asarray(accuracies, dtype=np.float64).ravel()
    if acc.size == 0:
        raise InputError("seed_summary needs at least one accuracy")
    if not np.all(np.isfinite(acc)):
        raise InputError(f"accuracies must be finite numbers, got {acc.tolist()}")
    n, mean = int(acc.size), float(acc.mean())
    if n == 1:
        return SeedSummary(mean=mean, std=None, n=1, low=None, high=None, confidence=conf,
                           note="one seed: no interval over seeds")
    std = float(acc.std(ddof=1))
    half = float(stats.t.ppf(0.5 + conf / 2, n - 1)) * std / math.sqrt(n)
    return SeedSummary(mean=mean, std=std, n=n, low=mean - half, high=mean + half,
                       confidence=conf)


@dataclass(frozen=True)
class PairedDifference:
    """B − A on the same test sequences (see :func:`paired_difference`)."""

    difference: float  # mean over seeds of (accuracy B − accuracy A)
    low: float  # bootstrap interval of ``difference``
    high: float
    confidence: float
    accuracy_a: float  # mean over seeds
    accuracy_b: float
    seeds: int
    b_better_seeds: int  # seeds where B's accuracy is higher
    a_better_seeds: int
    tied_seeds: int
    a_only: int  # pooled rows A got right and B wrong (McNemar's b)
    b_only: int  # pooled rows B got right and A wrong (McNemar's c)
    mcnemar_p: float  # exact two-sided; 1.0 when no row is discordant
    verdict: str  # "B better", "A better" or "unresolved"
    resampling: str  # "within each seed" or "sequences jointly across seeds"
    n_resamples: int
    sequences: int  # test rows, all seeds together
    per_seed: dict[str, float] = field(default_factory=dict)  # seed → B − A
    note: str = ""  # why the interval is not a bootstrap one, when it is not

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _rows(name: str, x: Any, n: int | None) -> np.ndarray:
    arr = np.asarray(x)
    if arr.ndim != 1:
        raise InputError(f"{name} must be one value per test sequence (1-D), "
                         f"got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise InputError(f"{name} has {arr.shape[0]} rows, y_true has {n}")
    return arr


def paired_difference(y_true: Any, pred_a: Any, pred_b: Any, groups: Any, *,
                      sequence_ids: Any = None, confidence: float = 0.95,
                      n_resamples: int = N_RESAMPLES, seed: int = 0) -> PairedDifference:
    """Compare predictions A and B of the same test sequences under several seeds.

    ``y_true``, ``pred_a``, ``pred_b`` and ``groups`` (the seed of each row) are pooled
    1-D arrays, one row per (seed, test sequence). The difference is B − A: per seed, the
    mean of ``correct_B − correct_A`` over its rows; then the mean over seeds (each seed
    weighs the same, as in the accuracy table).

    Its interval is a percentile bootstrap (``scipy.stats.bootstrap``, ``n_resamples``
    resamples, RNG seeded by ``seed``) of that same statistic, resampling test sequences
    with replacement *within each seed* (stratified by seed; each seed keeps its size).
    When ``sequence_ids`` (the test sequence of each row) show that every seed tested
    exactly the same sequences, one draw of sequences is applied to every seed instead
    (``resampling = "sequences jointly across seeds"``): the seeds' results on one
    sequence are not independent, and resampling them together keeps that.

    McNemar's exact test runs on the pooled rows: ``a_only`` rows only A got right,
    ``b_only`` rows only B got right, ``p = binomtest(b_only, a_only + b_only, 0.5)``
    two-sided, and 1 when no row is discordant. The verdict is "B better" when the
    interval lies above zero, "A better" below, else "unresolved"; it is "unresolved"
    too with fewer than :data:`MIN_SEQUENCES_FOR_VERDICT` test sequences (``note`` says so).
    """
    from scipy import stats

    conf = _check_confidence(confidence)
    if isinstance(n_resamples, bool) or not isinstance(n_resamples, (int, np.integer)) \
            or n_resamples < 100:
        raise InputError(f"n_resamples must be an integer ≥ 100, got {n_resamples!r}")
    y = _rows("y_true", y_true, None)
    n = y.shape[0]
    if n == 0:
        raise InputError("paired_difference needs at least one test sequence")
    a = _rows("pred_a", pred_a, n)
    b = _rows("pred_b", pred_b, n)
    g = _rows("groups", groups, n)
    correct_a = a == y
    correct_b = b == y
    d = correct_b.astype(np.float64) - correct_a.astype(np.float64)

    seeds = list(dict.fromkeys(g.tolist()))  # first-seen order
    idx = [np.flatnonzero(g == s) for s in seeds]
    per_seed = np.array([d[i].mean() for i in idx])
    acc_a = float(np.mean([correct_a[i].mean() for i in idx]))
    acc_b = float(np.mean([correct_b[i].mean() for i in idx]))
    diff = float(per_seed.mean())

    joint = False
    if sequence_ids is not None:
        ids = _rows("sequence_ids", sequence_ids, n)
        order = [i[np.argsort(ids[i], kind="stable")] for i in idx]
        first = ids[order[0]]
        joint = (len(np.unique(first)) == len(first)
                 and all(np.array_equal(ids[o], first) for o in order[1:]))
        if joint:
            idx = order  # rows of every seed aligned by sequence
    units = len(idx[0]) if joint else n  # what is resampled: sequences or rows
    note = ""
    if units == 1:
        low, high = -1.0, 1.0
        note = "one test sequence: no interval (the full range −1 … 1)"
    elif np.all(d == d[0]):  # no variation to resample: the interval is the point
        low = high = diff
    else:
        low, high = _bootstrap_interval(d, idx, joint, conf, int(n_resamples), seed)
        # The percentile interval of a mean always contains the point up to rounding.
        low, high = min(low, diff), max(high, diff)

    a_only = int(np.sum(correct_a & ~correct_b))
    b_only = int(np.sum(correct_b & ~correct_a))
    discordant = a_only + b_only
    p = 1.0 if discordant == 0 else float(stats.binomtest(b_only, discordant, 0.5).pvalue)
    verdict = "B better" if low > 0 else "A better" if high < 0 else "unresolved"
    if units < MIN_SEQUENCES_FOR_VERDICT and verdict != "unresolved":
        verdict = "unresolved"
        note = note or (f"{units} test sequences: no verdict below "
                        f"{MIN_SEQUENCES_FOR_VERDICT} (the interval is too narrow at this size)")
    return PairedDifference(
        difference=diff, low=low, high=high, confidence=conf, accuracy_a=acc_a,
        accuracy_b=acc_b, seeds=len(seeds), b_better_seeds=int(np.sum(per_seed > 0)),
        a_better_seeds=int(np.sum(per_seed < 0)), tied_seeds=int(np.sum(per_seed == 0)),
        a_only=a_only, b_only=b_only, mcnemar_p=min(1.0, p), verdict=verdict,
        resampling="sequences jointly across seeds" if joint else "within each seed",
        n_resamples=int(n_resamples), sequences=n,
        per_seed={str(s): float(v) for s, v in zip(seeds, per_seed)}, note=note)


def _bootstrap_interval(d: np.ndarray, idx: list[np.ndarray], joint: bool, conf: float,
                        n_resamples: int, seed: int) -> tuple[float, float]:
    """Percentile bootstrap interval of ``mean over seeds of mean(d[rows of seed])``.

    Joint: every seed's rows are aligned by sequence and one draw of sequences serves
    every seed (``paired=True``). Else each seed is resampled alone; seeds with a single
    row cannot be, so their rows are resampled together as one stratum (the bootstrap
    over those seeds), or, when only one seed has a single row, it stays as it is.
    """
    from scipy import stats

    n_seeds = len(idx)
    if joint:
        strata, weights, constant = [d[i] for i in idx], [1.0] * n_seeds, 0.0
    else:
        strata = [d[i] for i in idx if len(i) > 1]
        weights = [1.0] * len(strata)
        singles = np.concatenate([d[i] for i in idx if len(i) == 1] or [np.zeros(0)])
        constant = 0.0
        if len(singles) > 1:
            strata.append(singles)
            weights.append(float(len(singles)))
        elif len(singles) == 1:
            constant = float(singles[0])
    w = np.asarray(weights) / n_seeds

    def statistic(*parts, axis=-1):
        return sum(wi * np.mean(p, axis=axis) for wi, p in zip(w, parts)) + constant / n_seeds

    batch = max(1, _BOOTSTRAP_BATCH_VALUES // len(d))
    res = stats.bootstrap(tuple(strata), statistic, n_resamples=n_resamples,
                          confidence_level=conf, method="percentile", paired=joint,
                          vectorized=True, batch=batch,
                          random_state=np.random.default_rng(seed))
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


@dataclass(frozen=True)
class FactorPair:
    """Cells ``a`` and ``b`` (indices into the list given) differ only in ``factor``,
    from ``value_a`` to ``value_b``."""

    a: int
    b: int
    factor: str
    value_a: Hashable | Any
    value_b: Hashable | Any

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def pairs_differing_in_one_factor(cells: Sequence[Mapping[str, Any]]) -> list[FactorPair]:
    """Every pair of ``cells`` (dicts of factors, e.g. ``{"encoder": "raw", "classifier":
    "logreg", "L": 5}``) that differ in exactly one factor.

    Ordered by the factor's first appearance in the cells' keys, then by the cells' order
    (``a`` < ``b``): A is the cell listed first, so a run listing ``raw`` before
    ``farneback`` compares farneback − raw. Identical cells are no pair. Every cell must
    name the same factors.
    """
    cells = list(cells)
    if not cells:
        return []
    keys = list(cells[0].keys())
    for i, c in enumerate(cells):
        if not isinstance(c, Mapping):
            raise InputError(f"cell {i} is a {type(c).__name__}, not a dict of factors")
        if set(c.keys()) != set(keys):
            raise InputError(f"cell {i} has factors {sorted(c.keys())}; cell 0 has "
                             f"{sorted(keys)}: every cell must name the same factors")
    found = []
    for i in range(len(cells)):
        for j in range(i + 1, len(cells)):
            differ = [k for k in keys if cells[i][k] != cells[j][k]]
            if len(differ) == 1:
                k = differ[0]
                found.append((keys.index(k), i, j,
                              FactorPair(i, j, k, cells[i][k], cells[j][k])))
    return [p for *_, p in sorted(found, key=lambda t: t[:3])]


__all__ = ["FactorPair", "PairedDifference", "SeedSummary", "paired_difference",
           "pairs_differing_in_one_factor", "seed_summary"]
