"""Runs added until an answer: a group-sequential design over the corrected variance.

A comparison is looked at after each batch of runs. Looking repeatedly at a growing
sample and stopping at the first p below α would raise the false-verdict rate far above
α; a group-sequential design spends α over the looks instead (Lan & DeMets 1983), with
the O'Brien–Fleming-type spending function ``α(t) = 2 − 2 Φ(z_{1−α/2} / √t)``, which
spends almost nothing early and keeps the last look close to a fixed design's.

The *information* of a look is the inverse of the variance of the mean difference; with
the corrected resampled t (:mod:`tactbench.runner.statistics`) it is proportional to
``1 / (1/J + ratio)`` — it grows with the runs J but saturates at ``1/ratio``: the
information fraction of a look is ``I(J) / I(J_max)``. The boundaries
(:func:`boundaries`) are values of the corrected t whose crossing probabilities under "no
difference" add up to the spent α; they are placed by simulating that statistic with the
correlation between runs the correction assumes (exact for that model up to Monte Carlo
error, and right for a handful of runs, where the normal boundaries of Jennison &
Turnbull 2000, ch. 19, used through a t-to-z conversion, overspend α).

At each look a comparison stops when it is

- ``B better`` / ``A better``: the corrected |t| reaches the look's boundary;
- ``equivalent``: with a margin, both one-sided t's of the two one-sided tests reach it;
- ``futile``: neither can happen by the last planned look even for a true difference at
  the favourable edge of the look's own 95 % interval (from the second look on;
  futility stopping is non-binding: it never raises the false-verdict rate);
- otherwise it goes on.

A family of primary comparisons shares α by Holm's procedure carried over to
group-sequential designs (Maurer & Bretz 2013): each starts with α/m; when one is
declared better or worse, its α passes in equal shares to those still open, whose
boundaries are computed again at the larger level. Both steps are hand-written (no
maintained Python library computes spending-function boundaries; statsmodels has none);
``tests/runner/test_sequential.py`` checks the family-wise error under no difference and
the power under a real one by simulation with correlated runs.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Sequence

from tactbench.errors import InputError

#: What :func:`look` may decide.
DECISIONS = ("B better", "A better", "equivalent", "futile", "continue")
#: The interval a futility check gives the benefit of the doubt (two-sided 95 %).
FUTILITY_Z = 1.959964


def spent(t: float, alpha: float) -> float:
    """α spent by information fraction ``t`` (O'Brien–Fleming type, Lan & DeMets)."""
    from scipy import stats

    if t <= 0:
        return 0.0
    t = min(1.0, t)
    return float(2 - 2 * stats.norm.cdf(stats.norm.ppf(1 - alpha / 2) / math.sqrt(t)))


def information(runs: int, ratio: float) -> float:
    """The information of a look at ``runs`` runs, per unit of per-run variance."""
    return 1.0 / (1.0 / runs + ratio)


def fractions(looks: Sequence[int], max_runs: int, ratio: float) -> list[float]:
    """The information fractions of looks at these run counts, planned up to ``max_runs``."""
    total = information(max_runs, ratio)
    return [min(1.0, information(j, ratio) / total) for j in looks]


#: Paths simulated to place the boundaries: the α a boundary spends is off by about
#: ``sqrt(α / _PATHS)`` (3.5e-4 at α = 0.025).
_PATHS = 200_000


def boundaries(looks: Sequence[int], max_runs: int, ratio: float, alpha: float
               ) -> list[float]:
    """Two-sided boundaries on the corrected t at looks after ``looks`` runs (increasing,
    each ≥ 2), planned up to ``max_runs``, spending ``alpha`` as :func:`spent` does over
    the information fractions; a look whose information does not grow spends nothing
    (boundary ∞).

    Placed by simulating the statistic itself under "no difference", with the
    correlation between runs the correction assumes (ρ = ratio / (1 + ratio)): at each
    look the boundary is the quantile of |t| among the paths still going that stops the
    spent share of them. (Turning each t into a z and using a normal statistic's
    boundaries overspends α by 10–25 % with a handful of runs, since the variance is
    estimated anew at each look.) Deterministic: a fixed seed; remembered per request.
    """
    looks = tuple(int(j) for j in looks)
    if not looks or looks[0] < 2 or any(b <= a for a, b in zip(looks, looks[1:])) \
            or max_runs < looks[-1]:
        raise InputError(f"looks must be increasing run counts ≥ 2 up to the planned "
                         f"{max_runs}, got {list(looks)}")
    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha!r}")
    return list(_boundaries(looks, int(max_runs), round(float(ratio), 12),
                            round(float(alpha), 12)))


@functools.lru_cache(maxsize=256)
def _boundaries(looks: tuple[int, ...], max_runs: int, ratio: float, alpha: float
                ) -> tuple[float, ...]:
    import numpy as np

    rng = np.random.default_rng(20261125)
    rho = ratio / (1 + ratio)
    # each path: a shared part (the recordings every run draws from) and its runs' own
    # parts, kept as running sums so that memory stays 3 numbers a path however many runs
    shared = rng.standard_normal(_PATHS) * math.sqrt(rho)
    total = np.zeros(_PATHS)
    squares = np.zeros(_PATHS)
    alive = np.ones(_PATHS, dtype=bool)
    out: list[float] = []
    stopped, made = 0, 0
    for j, t in zip(looks, fractions(looks, max_runs, ratio)):
        while made < j:  # the runs up to this look, a block of at most 64 at a time
            block = rng.standard_normal((_PATHS, min(64, j - made))) * math.sqrt(1 - rho)
            total += block.sum(axis=1)
            squares += (block * block).sum(axis=1)
            made += block.shape[1]
        variance = np.maximum(squares - total * total / j, 0.0) / (j - 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            stat = np.abs((shared + total / j) / np.sqrt((1 / j + ratio) * variance))
        stops = int(round(spent(t, alpha) * _PATHS)) - stopped
        if stops <= 0 or not alive.any():
            out.append(math.inf)
            continue
        going = np.sort(stat[alive])[::-1]
        b = float(going[min(stops, len(going)) - 1])
        out.append(b)
        stopped += int(np.sum(alive & (stat >= b)))
        alive &= stat < b
    return tuple(out)


@dataclass(frozen=True)
class Look:
    """One look at one comparison: what the runs so far say, against the boundary."""

    runs: int
    difference: float  # mean B − A (fraction)
    se: float  # corrected standard error
    t: float  # the corrected t
    boundary: float  # |t| needed now
    alpha: float  # the comparison's share of α at this look
    decision: str
    why: str = ""

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.__dict__.items()}


def look(d: Sequence[float], ratio: float, *, looks: Sequence[int], max_runs: int,
         alpha: float, margin: float | None = None) -> Look:
    """The decision at the last of ``looks`` (run counts of every look so far, the last
    being ``len(d)``) for per-run differences ``d``, with looks planned up to
    ``max_runs`` and this comparison's level ``alpha``."""
    import numpy as np

    d = np.asarray(d, dtype=np.float64)
    j = len(d)
    if j < 2 or looks[-1] != j:
        raise InputError(f"a look needs ≥ 2 runs and the last look at {j}, got {list(looks)}")
    planned = [*looks, max_runs] if max_runs > looks[-1] else list(looks)
    bounds = boundaries(planned, max(max_runs, j), ratio, alpha)
    c, c_last = bounds[len(looks) - 1], bounds[-1]
    mean = float(d.mean())
    se = float(math.sqrt((1 / j + ratio) * d.var(ddof=1)))
    z = mean / se if se > 0 else (0.0 if mean == 0 else math.copysign(math.inf, mean))
    if abs(z) >= c:
        return Look(j, mean, se, z, c, alpha, "B better" if z > 0 else "A better")
    if margin and se > 0 and min((mean + margin) / se, (margin - mean) / se) >= c:
        return Look(j, mean, se, z, c, alpha, "equivalent")
    if j >= max_runs:
        return Look(j, mean, se, z, c, alpha, "futile", "the last planned look")
    if se == 0:  # mean 0 too (else |z| is infinite): every run gave exactly no difference
        return Look(j, mean, se, z, c, alpha, "futile",
                    "every run gave the same difference, 0: nothing varies to test (a "
                    "ceiling, where both are right on every recording), and more runs "
                    "like these add nothing")
    # futile: even a difference at the near edge of today's 95 % interval (the most
    # favourable one the runs so far allow) would not cross the last look's boundary
    se_last = float(math.sqrt((1 / max_runs + ratio) * d.var(ddof=1)))
    best, worst = abs(mean) + FUTILITY_Z * se, max(0.0, abs(mean) - FUTILITY_Z * se)
    reach = best >= c_last * se_last
    fits = bool(margin) and worst + c_last * se_last <= margin
    if len(looks) >= 2 and not (reach or fits):
        return Look(j, mean, se, z, c, alpha, "futile",
                    f"at {max_runs} runs the boundary ±{c_last * se_last * 100:.1f} points "
                    f"is beyond the reach of {best * 100:.1f}" + (
                        " and the margin out of reach" if margin else ""))
    return Look(j, mean, se, z, c, alpha, "continue")


@dataclass
class FamilyState:
    """The α shares of a family of primary comparisons (Holm, carried over looks)."""

    alpha: float
    names: list[str]
    shares: dict[str, float] = field(default_factory=dict)
    closed: dict[str, Look] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.shares:
            self.shares = {n: self.alpha / len(self.names) for n in self.names}


def family_look(state: FamilyState, diffs: dict[str, Sequence[float]], ratios: dict[str, float],
                *, looks: Sequence[int], max_runs: int, margin: float | None = None
                ) -> dict[str, Look]:
    """One look at every open comparison of a family; decided ones close, and the α of
    one declared better or worse passes in equal shares to those still open (which are
    looked at again at their new level). Returns the look of each comparison open before."""
    out: dict[str, Look] = {}
    changed = True
    while changed:
        changed = False
        open_now = [n for n in state.names if n not in state.closed]
        for name in open_now:
            res = look(diffs[name], ratios[name], looks=looks, max_runs=max_runs,
                       alpha=state.shares[name], margin=margin)
            out[name] = res
            if res.decision in ("B better", "A better"):
                state.closed[name] = res
                rest = [n for n in open_now if n != name]
                for n in rest:
                    state.shares[n] += state.shares[name] / len(rest)
                changed = bool(rest)
                break
    for name, res in out.items():
        if name not in state.closed and res.decision in ("equivalent", "futile"):
            state.closed[name] = res
    return out
