"""The built-in paired tests (docs/statistics.md, "Choosing the paired test"): what
``register_paired_tests`` of :mod:`tactbench.paired` registers — the runner's default
:class:`CorrectedT` and :class:`WilcoxonSignedRank`. No module of the runner imports this
one: it knows paired tests through the registry. The contract is
:data:`tactbench.contracts.PAIRED_TEST`; the seam that calls a test is
:mod:`tactbench.runner.analysis.paired_tests`."""

from __future__ import annotations

from typing import Any

import numpy as np

from tactbench.runner.analysis.paired_tests import CorrectedT  # the default, registered too

__all__ = ["CorrectedT", "WilcoxonSignedRank", "hodges_lehmann_interval", "signed_rank_cdf"]


class WilcoxonSignedRank:
    """The Wilcoxon signed-rank test over runs (scipy's p: exact below 50 runs without
    ties or zeros), with the Hodges–Lehmann interval of the pseudo-median: the Walsh
    averages between the exact signed-rank distribution's quantiles (Hollander & Wolfe
    1999, ch. 3). It assumes the runs are independent and their differences symmetric
    about the centre, so it is valid for runs of one fixed split (they differ by the
    initialisation only) and for independent runs; runs that re-split one data set
    overlap, and a rank test has no correction for that. With 5 runs or fewer no
    95 % interval exists (the smallest two-sided p is 2 / 2^J): the interval is the
    whole range. ``ratio`` is 0 for every design it is valid for, and unused."""

    label = "Wilcoxon signed-rank test"
    designs = frozenset({"fixed", "independent"})

    def test(self, d: np.ndarray, *, ratio: float, confidence: float) -> dict[str, Any]:
        from scipy import stats

        d = np.asarray(d, dtype=np.float64)
        if np.all(d == 0):
            return {"low": 0.0, "high": 0.0, "p": 1.0, "df": None}
        p = float(stats.wilcoxon(d, zero_method="wilcox").pvalue)
        low, high = hodges_lehmann_interval(d, confidence)
        return {"low": low, "high": high, "p": min(1.0, p), "df": None}


def signed_rank_cdf(n: int) -> np.ndarray:
    """P(W+ ≤ w) for w = 0 … n(n + 1)/2 under the null of the signed-rank test over
    ``n`` differences without ties: the exact distribution, by adding one rank at a
    time (each in or out of W+ with probability ½)."""
    dist = np.ones(1)
    for k in range(1, n + 1):
        grown = np.zeros(len(dist) + k)
        grown[:len(dist)] += dist / 2
        grown[k:] += dist / 2
        dist = grown
    return np.cumsum(dist)


def hodges_lehmann_interval(d: Any, confidence: float = 0.95) -> tuple[float, float]:
    """The distribution-free interval of the pseudo-median of ``d`` that inverts the
    Wilcoxon signed-rank test: the (c + 1)-th smallest and (c + 1)-th largest of the
    n(n + 1)/2 Walsh averages ``(d_i + d_j)/2``, i ≤ j, c the largest w with
    P(W+ ≤ w) ≤ (1 − confidence)/2; ``(-1, 1)`` (the range of a difference of
    accuracies) where no such w exists."""
    conf = float(confidence)
    d = np.sort(np.asarray(d, dtype=np.float64))
    i, j = np.triu_indices(len(d))
    walsh = np.sort((d[i] + d[j]) / 2)
    below = np.flatnonzero(signed_rank_cdf(len(d)) <= (1 - conf) / 2 + 1e-12)
    if not len(below):
        return -1.0, 1.0
    c = int(below[-1])
    return float(walsh[c]), float(walsh[len(walsh) - 1 - c])
