"""Statistics for comparing training procedures: the training run is the unit of evidence.

A verdict ("B beats A") is a claim about two *training procedures* on this kind of data,
not about two fitted models on one test set (see docs/statistics.md and the references
there). Every seed of a run redraws the split and the initialisation, so each seed gives
one *run*: one trained pair and one difference of accuracy ``d_s = acc_B − acc_A``.
The functions here are pure (numpy arrays in, numbers out); scipy is imported inside them.

- :func:`corrected_t`: the corrected resampled t-test of Nadeau & Bengio (2003) over the
  per-run differences, ``var × (1/J + n_test/n_train)``, J − 1 degrees of freedom; for a
  K-fold split repeated over seeds the same correction with ``n_test/n_train = 1/(K − 1)``
  (Bouckaert & Frank 2004). Its interval is the one shown beside every verdict.
- :func:`sign_flip_p`: the exact sign-flip permutation test over runs; with J runs its
  smallest two-sided p is ``2 / 2^J``; reported beside the corrected t's p, which governs.
- :func:`holm`: Holm's step-down adjustment within a family of comparisons.
- :func:`tost_p`: two one-sided tests (Schuirmann 1987) for equivalence within ±margin.
- :func:`runs_needed`: how many runs the observed variance needs for an interval of ±h.
- :func:`verdict`: the rules that turn the above into "B better", "A better",
  "equivalent", "unresolved" or "too few runs".
- :func:`variance_components`: split / initialisation / test-sampling variance of runs
  that vary split and initialisation separately.
- :func:`mcnemar_p`: McNemar's exact test on one seed's paired predictions — a statement
  about *those two trained models* on that test set only.
- :func:`seed_summary`: the t-interval of a cell's mean accuracy over seeds.
- :func:`pairs_differing_in_one_factor`: which cells of a grid to compare.

:func:`sign_flip_p`, :func:`corrected_t` and :func:`holm` are written with numpy and work
on arrays of many families at once (the leading axes), which keeps the simulation checks
of tests/runner/analysis/test_statistics.py fast; each is checked there against scipy's own
(``scipy.stats.permutation_test``, ``scipy.stats.ttest_1samp``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Hashable, Mapping, Sequence

import numpy as np

from tactbench.errors import InputError

#: Fewer runs than this give no verdict: one model pair says nothing about the procedure.
MIN_RUNS = 3
#: Fewer distinct test recordings on which the two cells ever disagree than this give no
#: verdict: a handful of recordings (however many rows they fill) is too little evidence.
MIN_DISCORDANT_RECORDINGS = 10
#: An interval end within this of 0 (accuracy as a fraction) touches 0: floating-point
#: noise of a mean of zeros is not a difference.
ZERO_TOLERANCE = 1e-9
#: The interval half-width (accuracy fraction) :func:`runs_needed` aims at without a margin.
TARGET_HALF_WIDTH = 0.02
#: Runs beyond this are not searched by :func:`runs_needed` (the answer is "more than").
MAX_RUNS_SEARCHED = 1000
#: Exact sign-flip enumeration up to this many runs; above, this many random sign vectors.
_EXACT_RUNS = 16
_RANDOM_FLIPS = 1 << 16


def _check_confidence(confidence: float) -> float:
    try:
        c = float(confidence)
    except (TypeError, ValueError):
        c = float("nan")
    if not 0 < c < 1:
        raise InputError(f"confidence must be between 0 and 1 (e.g. 0.95), got {confidence!r}")
    return c


def _check_ratio(ratio: float) -> float:
    try:
        r = float(ratio)
    except (TypeError, ValueError):
        r = float("nan")
    if not (math.isfinite(r) and r >= 0):
        raise InputError(f"n_test/n_train must be a finite number ≥ 0, got {ratio!r}")
    return r


# --------------------------------------------------------------------- one cell over seeds


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


def seed_summary(accuracies: Sequence[float] | np.ndarray, *,
                 confidence: float = 0.95) -> SeedSummary:
    """Mean ± std of ``accuracies`` (one per seed) and a t-interval of the mean.

    The interval is ``mean ± t(n − 1) · std / √n`` (``scipy.stats.t``): where the mean
    over seeds would lie with other seeds on the same data. Seeds share the data, so it
    is narrower than an interval over data sets would be; the comparisons of cells use
    :func:`corrected_t`. With one seed there is no interval (``note`` says so).
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


# --------------------------------------------------------------------- runs as the unit


def corrected_t(d: Any, ratio: float, *, confidence: float = 0.95) -> dict[str, np.ndarray]:
    """The corrected resampled t-test of the per-run differences ``d`` (last axis: runs).

    ``se = sqrt((1/J + ratio) · s²)``, s² the sample variance of ``d`` (ddof = 1),
    ``t = mean / se`` on J − 1 degrees of freedom (Nadeau & Bengio 2003). ``ratio`` is
    ``n_test / n_train`` for repeated random splits, ``1 / (K − 1)`` for K folds
    (Bouckaert & Frank 2004); 0 gives the plain one-sample t-test over runs.

    Returns arrays over the leading axes: ``mean``, ``se``, ``low``, ``high`` (the
    interval ``mean ± t_{J−1} · se``), ``p`` (two-sided; 1 where every run is equal and
    the mean is 0, 0 where every run is equal and the mean is not) and ``df``. Needs
    J ≥ 2.
    """
    from scipy import stats

    conf = _check_confidence(confidence)
    ratio = _check_ratio(ratio)
    d = np.asarray(d, dtype=np.float64)
    j = d.shape[-1]
    if j < 2:
        raise InputError(f"a corrected t-test needs at least 2 runs, got {j}")
    mean = d.mean(axis=-1)
    var = d.var(axis=-1, ddof=1)
    se = np.sqrt((1.0 / j + ratio) * var)
    q = float(stats.t.ppf(0.5 + conf / 2, j - 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(se > 0, mean / np.where(se > 0, se, 1.0), np.where(mean == 0, 0.0, np.inf))
    p = 2 * stats.t.sf(np.abs(t), j - 1)
    return {"mean": mean, "se": se, "low": mean - q * se, "high": mean + q * se,
            "p": np.minimum(1.0, p), "df": np.full(mean.shape, j - 1)}


def sign_flip_p(d: Any) -> np.ndarray:
    """Two-sided p of the sign-flip permutation test of ``mean(d) = 0`` over runs.

    Under "no difference between the procedures" each run's difference is as likely
    positive as negative; the p-value is the share of the 2^J sign patterns whose
    |mean| reaches the observed one (exact for J ≤ 16; above, 65 536 random patterns
    from a fixed seed plus the observed one). With J runs the smallest p is 2 / 2^J
    (0.0625 for 5 runs): five runs cannot reach 5 %. Vectorised over leading axes.
    """
    d = np.asarray(d, dtype=np.float64)
    j = d.shape[-1]
    if j < 1:
        raise InputError("a sign-flip test needs at least one run")
    if j <= _EXACT_RUNS:
        bits = (np.arange(1 << j)[:, None] >> np.arange(j)) & 1
        signs = 1.0 - 2.0 * bits  # (2^J, J); row 0 is the observed pattern
    else:
        rng = np.random.default_rng(0)
        signs = np.vstack([np.ones((1, j)), rng.choice([-1.0, 1.0], size=(_RANDOM_FLIPS, j))])
    observed = np.abs(d.mean(axis=-1))[..., None]
    flipped = np.abs(d @ signs.T) / j
    # a tolerance for sums that are equal but for rounding
    reach = flipped >= observed - 1e-12 * np.maximum(1.0, observed)
    return reach.mean(axis=-1)


def holm(p: Any) -> np.ndarray:
    """Holm's step-down adjusted p-values over the last axis (one family per row).

    Sorted ascending, ``p_(i) · (m − i)`` (i from 0), made non-decreasing, capped at 1;
    NaN entries are left out of the family and stay NaN. Valid under any dependence
    between the comparisons (Holm 1979).
    """
    p = np.asarray(p, dtype=np.float64)
    if p.ndim == 0:
        return np.minimum(1.0, p)
    nan = np.isnan(p)
    filled = np.where(nan, np.inf, p)
    order = np.argsort(filled, axis=-1, kind="stable")
    sorted_p = np.take_along_axis(filled, order, axis=-1)
    m = (~nan).sum(axis=-1, keepdims=True)
    factor = np.maximum(m - np.arange(p.shape[-1]), 1)
    adjusted = np.minimum(1.0, np.maximum.accumulate(sorted_p * factor, axis=-1))
    out = np.empty_like(adjusted)
    np.put_along_axis(out, order, adjusted, axis=-1)
    return np.where(nan, np.nan, out)


def tost_p(d: Any, ratio: float, margin: float) -> np.ndarray:
    """p of two one-sided tests that the mean difference lies within ±``margin``.

    Each side is a corrected t-test (:func:`corrected_t`'s standard error, J − 1 df)
    of ``mean ≤ −margin`` and ``mean ≥ +margin``; the p is the larger (Schuirmann
    1987). Below α, the procedures are *equivalent within ±margin*: the run-level
    interval at 1 − 2α lies inside (−margin, +margin).
    """
    from scipy import stats

    if not (isinstance(margin, (int, float)) and math.isfinite(margin) and margin > 0):
        raise InputError(f"an equivalence margin must be a number > 0, got {margin!r}")
    ratio = _check_ratio(ratio)
    d = np.asarray(d, dtype=np.float64)
    j = d.shape[-1]
    if j < 2:
        raise InputError(f"an equivalence test needs at least 2 runs, got {j}")
    mean = d.mean(axis=-1)
    se = np.sqrt((1.0 / j + ratio) * d.var(axis=-1, ddof=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        lower = np.where(se > 0, (mean + margin) / np.where(se > 0, se, 1.0),
                         np.where(mean + margin > 0, np.inf, -np.inf))
        upper = np.where(se > 0, (margin - mean) / np.where(se > 0, se, 1.0),
                         np.where(margin - mean > 0, np.inf, -np.inf))
    return np.maximum(stats.t.sf(lower, j - 1), stats.t.sf(upper, j - 1))


def runs_needed(sd: float | None, ratio: float, half_width: float, *,
                confidence: float = 0.95) -> int | None:
    """The fewest runs J (≥ :data:`MIN_RUNS`) whose corrected interval would be at most
    ±``half_width`` at the observed standard deviation ``sd`` of the per-run differences:
    ``t_{J−1} · sqrt((1/J + ratio)) · sd ≤ half_width``.

    None when no number of runs gets there: the correction keeps ``ratio · sd²`` however
    many runs there are (more runs of the *same* data cannot shrink the interval below
    ``z · sqrt(ratio) · sd``), or more than :data:`MAX_RUNS_SEARCHED` would be needed.
    With ``sd`` 0 (or None: too few runs to tell) the answer is :data:`MIN_RUNS` or None.
    """
    from scipy import stats

    conf = _check_confidence(confidence)
    ratio = _check_ratio(ratio)
    if sd is None or not math.isfinite(sd):
        return None
    if sd == 0:
        return MIN_RUNS
    z = float(stats.norm.ppf(0.5 + conf / 2))
    if z * math.sqrt(ratio) * sd >= half_width:
        return None
    j = np.arange(MIN_RUNS, MAX_RUNS_SEARCHED + 1)
    width = stats.t.ppf(0.5 + conf / 2, j - 1) * np.sqrt(1.0 / j + ratio) * sd
    ok = np.flatnonzero(width <= half_width)
    return int(j[ok[0]]) if ok.size else None


#: The verdict of a comparison a run of either cell did not learn or transfer in
#: (:mod:`tactbench.runner.execution.learning`): no verdict rests on a model at chance.
NOT_LEARNED = "not learned"
#: The verdicts of a comparison (B − A): the words every table, note and decision uses.
B_BETTER, A_BETTER, EQUIVALENT = "B better", "A better", "equivalent"
UNRESOLVED, TOO_FEW_RUNS = "unresolved", "too few runs"
#: The verdicts that answer a question.
DECIDED = (B_BETTER, A_BETTER, EQUIVALENT)
#: What :func:`verdict` may return, and :data:`NOT_LEARNED`.
VERDICTS = (*DECIDED, UNRESOLVED, TOO_FEW_RUNS, NOT_LEARNED)


def verdict(low: float, high: float, p_adjusted: float, runs: int, *,
            alpha: float = 0.05, discordant_recordings: int | None = None,
            equivalence_p_adjusted: float | None = None) -> tuple[str, str]:
    """The verdict of one comparison and why, from its run-level interval and its
    family-adjusted p.

    - fewer than :data:`MIN_RUNS` runs: "too few runs";
    - fewer than :data:`MIN_DISCORDANT_RECORDINGS` distinct test recordings on which the
      cells ever disagree: "unresolved" (the note says so);
    - adjusted p < ``alpha`` and the interval clear of 0 by more than
      :data:`ZERO_TOLERANCE`: "B better" (above 0) or "A better" (below);
    - else, with a margin, equivalence p (adjusted) < ``alpha``: "equivalent";
    - else "unresolved".
    """
    if runs < MIN_RUNS:
        return TOO_FEW_RUNS, (f"{runs} run(s): no verdict below {MIN_RUNS} (one model "
                                "pair says nothing about the training procedure)")
    if discordant_recordings is not None and discordant_recordings < MIN_DISCORDANT_RECORDINGS:
        return UNRESOLVED, (f"the cells disagree on {discordant_recordings} distinct test "
                              f"recording(s): no verdict below {MIN_DISCORDANT_RECORDINGS}")
    if p_adjusted < alpha and low > ZERO_TOLERANCE:
        return B_BETTER, ""
    if p_adjusted < alpha and high < -ZERO_TOLERANCE:
        return A_BETTER, ""
    if equivalence_p_adjusted is not None and equivalence_p_adjusted < alpha:
        return EQUIVALENT, ""
    if p_adjusted < alpha:
        return UNRESOLVED, "the interval touches 0"
    return UNRESOLVED, ""


def mcnemar_p(correct_a: Any, correct_b: Any) -> float:
    """McNemar's exact two-sided p on one test set's paired outcomes (booleans):
    ``binomtest(b_only, a_only + b_only, 0.5)``, 1 when no row is discordant.

    A statement about *these two fitted models* on *this* test set only (Dietterich
    1998), not about the procedures that trained them.
    """
    from scipy import stats

    a = np.asarray(correct_a, dtype=bool)
    b = np.asarray(correct_b, dtype=bool)
    a_only, b_only = int(np.sum(a & ~b)), int(np.sum(b & ~a))
    if a_only + b_only == 0:
        return 1.0
    return float(min(1.0, stats.binomtest(b_only, a_only + b_only, 0.5).pvalue))


def variance_components(values: Any, test_variance: float) -> dict[str, float]:
    """Split / initialisation / test-sampling variance of one quantity measured on runs
    laid out as ``values[split seed, init seed]`` (at least 2 × 2).

    Within a split, the test set is fixed and the runs differ only by initialisation:
    the mean within-split variance estimates ``init``. Between splits, the split means
    vary by ``split + test + init / n_init``; ``test`` (the sampling variance of the
    quantity over test sets, ``test_variance``: e.g. p(1 − p)/n_test for an accuracy) is
    given, so ``split = var(split means) − test − init / n_init``. A negative estimate
    (noise) is reported as 0 with ``clipped`` listing it. Returns variances in the
    quantity's units squared: ``split``, ``init``, ``test``, ``clipped``.
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 2 or v.shape[0] < 2 or v.shape[1] < 2:
        raise InputError(f"a variance decomposition needs at least 2 split seeds × 2 init "
                         f"seeds, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise InputError("a variance decomposition needs every (split, init) run")
    init = float(v.var(axis=1, ddof=1).mean())
    split = float(v.mean(axis=1).var(ddof=1)) - float(test_variance) - init / v.shape[1]
    clipped = []
    if split < 0:
        split, clipped = 0.0, ["split"]
    return {"split": split, "init": init, "test": float(test_variance), "clipped": clipped}


# --------------------------------------------------------------------- which cells


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


__all__ = ["FactorPair", "MIN_DISCORDANT_RECORDINGS", "MIN_RUNS", "NOT_LEARNED",
           "SeedSummary", "TARGET_HALF_WIDTH", "VERDICTS", "ZERO_TOLERANCE", "corrected_t", "holm",
           "mcnemar_p", "pairs_differing_in_one_factor", "runs_needed", "seed_summary",
           "sign_flip_p", "tost_p", "variance_components", "verdict"]
