"""Runs added until an answer: a group-sequential design over the corrected variance.

A comparison is looked at after each batch of runs. Looking repeatedly at a growing
sample and stopping at the first p below α would raise the false-verdict rate far above
α; a group-sequential design spends α over the looks instead (Lan & DeMets 1983), with
the O'Brien–Fleming-type spending function ``α(t) = 2 − 2 Φ(z_{1−α/2} / √t)``, which
spends almost nothing early and keeps the last look close to a fixed design's.

The *information* of a look is the inverse of the variance of the mean difference; with
the corrected resampled t (:mod:`tactbench.runner.analysis.statistics`) it is proportional to
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
- ``futile``: neither can happen by the last planned look even where the runs still to
  come land at the favourable edge of their one-sided 80 % predictive interval (the
  Student t at the look's J − 1 degrees of freedom, :func:`futility_reach`) and the
  spread is at its lower 80 % confidence limit (:func:`favourable_sd`), at any look
  the first included (futility stopping is non-binding: it never raises the
  false-verdict rate; its error rates, by simulation, are in docs/statistics.md);
- otherwise it goes on.

A family of primary comparisons shares α by Holm's procedure carried over to
group-sequential designs (Maurer & Bretz 2013): each starts with α/m; when one is
declared better or worse, its α passes in equal shares to every hypothesis not rejected
(those closed futile keep theirs unused: :func:`family_look`), and the open ones'
boundaries are computed again at the larger level. Both steps are hand-written (no
maintained Python library computes spending-function boundaries; statsmodels has none);
``tests/runner/analysis/test_sequential.py`` checks the family-wise error under no difference and
the power under a real one by simulation with correlated runs. :func:`procedure`
forecasts what the whole procedure will do for a true difference (its power, expected
runs, chance of ending futile), by the same rule and boundaries (``tactbench plan``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

from tactbench.errors import InputError
from tactbench.runner.analysis.statistics import (A_BETTER, B_BETTER, EQUIVALENT,
                                                  MIN_DISCORDANT_RECORDINGS, NOT_LEARNED)

#: What :func:`look` may decide, and :data:`NOT_LEARNED` (:func:`family_look`).
#: A look's own words: stop unanswered (no number of runs up to the maximum can decide),
#: or go on to the next look.
FUTILE, CONTINUE = "futile", "continue"
DECISIONS = (B_BETTER, A_BETTER, EQUIVALENT, FUTILE, CONTINUE, NOT_LEARNED)
#: The one-sided level of the predictive interval a futility check gives the benefit of
#: the doubt: the runs still to come land beyond its favourable edge with this chance;
#: and of the lower confidence limit of the per-run spread the last look's boundary is
#: scaled by (the spread of a handful of runs is uncertain: a spread overestimated now
#: would make a question look out of reach that the runs to come would decide). Both
#: 0.2, chosen by simulation (docs/statistics.md, "Futility"): at 0.1 and the sample
#: spread, 1–2.5 % of the paths a later look decides were given up; at 0.2 / 0.2, ≤ 1 %.
FUTILITY_LEVEL = 0.20
SPREAD_LEVEL = 0.20


def favourable_sd(var, j: int, level: float = SPREAD_LEVEL):
    """The one-sided lower ``1 − level`` (:data:`SPREAD_LEVEL`) confidence limit of the per-run spread
    from ``j`` runs' sample variance ``var`` (chi-square on ``j − 1`` degrees of
    freedom): the smallest spread the runs so far plausibly have."""
    import numpy as np
    from scipy import stats

    df = max(1, j - 1)
    return np.sqrt(np.asarray(var, dtype=float) * df / float(stats.chi2.isf(level, df)))


def futility_reach(var, j: int, max_runs: int, level: float = FUTILITY_LEVEL):
    """How far the mean difference can still move by the last planned look, at the
    favourable edge of a one-sided ``1 − level`` (:data:`FUTILITY_LEVEL`) predictive
    interval: the runs
    ``j+1…max_runs`` replace the mean of ``j`` by that of ``max_runs``, which differ by
    ``s · sqrt(1/j − 1/max_runs) · T_{j−1}`` (``s²`` = ``var``, the runs' sample
    variance, estimated on ``j − 1`` degrees of freedom: Student's t, not the normal
    z). The part of the difference every run shares (the data set's) does not move."""
    import numpy as np
    from scipy import stats

    q = float(stats.t.isf(level, max(1, j - 1)))
    return q * np.sqrt(max(0.0, 1 / j - 1 / max_runs) * np.asarray(var, dtype=float))


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

    The first look's is exact: under "no difference", with the correlation between runs
    the correction assumes (ρ = ratio / (1 + ratio)), the corrected t at J runs is
    Student's t with J − 1 degrees of freedom, so the boundary is its quantile at the
    spent α (finite however small that is). The later ones are placed by simulating the
    statistic itself under that model: at each look the boundary is the quantile of |t|
    among the paths still going that stops the spent share of them. (Turning each t into a z and using a normal statistic's
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
    from scipy import stats

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
        if not out:  # the first look: the corrected t is exactly t(J − 1) under the model
            share = spent(t, alpha)
            b = float(stats.t.isf(share / 2, j - 1)) if share > 0 else math.inf
        else:
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
    decision: str  # one of DECISIONS
    why: str = ""

    def __post_init__(self) -> None:
        if self.decision not in DECISIONS:  # a bug, not a user's mistake
            raise ValueError(f"a look cannot decide {self.decision!r} (one of {DECISIONS})")

    def as_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.__dict__.items()}


#: The codes :func:`_decide` gives, by decision (futile has three reasons).
_B, _A, _EQ, _LAST, _FLAT, _REACH, _GO = range(7)


def _bounds(looks: Sequence[int], max_runs: int, ratio: float, alpha: float
            ) -> tuple[float, float]:
    """The boundary of the last of ``looks`` and that of the last planned look."""
    planned = [*looks, max_runs] if max_runs > looks[-1] else list(looks)
    bounds = boundaries(planned, max(max_runs, looks[-1]), ratio, alpha)
    return bounds[len(looks) - 1], bounds[-1]


def out_of_reach(mean, var, j: int, ratio: float, c_last: float, max_runs: int,
                 margin: float | None, levels: tuple[float, float] | None = None):
    """Whether a question can no longer be answered within ``max_runs`` runs — the one
    rule for "cannot be answered within the maximum" that a look stops futile by
    (:func:`_decide`) and ``tactbench plan`` says before the run
    (:func:`unanswerable`). Arrays of means and sample variances of ``j`` runs' per-run
    differences, or scalars: even where the runs to come move the mean to the favourable
    edge of their predictive interval (:func:`futility_reach`) and the spread is at its
    lower confidence limit (:func:`favourable_sd`) the mean would not cross the last
    look's boundary ``c_last``, nor (with a margin) would the interval fit inside the
    margin at its least favourable. ``levels``: (predictive, spread) one-sided levels,
    :data:`FUTILITY_LEVEL` and :data:`SPREAD_LEVEL` unless given (the benchmark's
    trade-off curve varies them)."""
    import numpy as np

    reach_level, spread_level = levels or (FUTILITY_LEVEL, SPREAD_LEVEL)
    mean, var = np.asarray(mean, dtype=float), np.asarray(var, dtype=float)
    se_last = np.sqrt(1 / max_runs + ratio) * favourable_sd(var, j, spread_level)
    move = futility_reach(var, j, max_runs, reach_level)
    best = np.abs(mean) + move
    worst = np.maximum(0.0, np.abs(mean) - move)
    return ~(best >= c_last * se_last) & ~(bool(margin) & (worst + c_last * se_last
                                                         <= (margin or 0)))


def unanswerable(effect: float, sd: float, ratio: float, looks: Sequence[int], *,
                 alpha: float, margin: float | None = None) -> bool:
    """What ``tactbench plan`` says before a run ``--until answered``: whether its first
    look, seeing exactly the planned ``effect`` with the planned spread ``sd``, would
    stop futile — :func:`out_of_reach` at that look, the rule the look itself applies,
    so that plan's "cannot be answered within the maximum" and the look's futile stop
    are one function."""
    looks = [int(x) for x in looks]
    _, c_last = _bounds(looks[:1], looks[-1], ratio, alpha)
    return bool(out_of_reach(effect, sd * sd, looks[0], ratio, c_last, looks[-1], margin))


def _decide(mean, var, j: int, ratio: float, c: float, c_last: float, max_runs: int,
            margin: float | None, futility: bool = True,
            levels: tuple[float, float] | None = None):
    """The decision codes of a look at ``j`` runs (arrays of means and sample variances
    of the per-run differences, or scalars): what :func:`look` says, and what
    :func:`procedure` simulates — one rule for both (``futility`` False: never futile
    before the last look, to measure what futility gives up; ``levels`` as for
    :func:`out_of_reach`)."""
    import numpy as np

    mean, var = np.asarray(mean, dtype=float), np.asarray(var, dtype=float)
    se = np.sqrt((1 / j + ratio) * var)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(se > 0, mean / se, np.where(mean == 0, 0.0, np.sign(mean) * np.inf))
        eq = (se > 0) & (np.minimum((mean + (margin or 0)) / se,
                                    ((margin or 0) - mean) / se) >= c) & bool(margin)
    hopeless = out_of_reach(mean, var, j, ratio, c_last, max_runs, margin, levels) & futility
    return np.select([np.abs(z) >= c, eq, np.full(z.shape, j >= max_runs), se == 0,
                      hopeless], [np.where(z > 0, _B, _A), _EQ, _LAST, _FLAT, _REACH], _GO)


def look(d: Sequence[float], ratio: float, *, looks: Sequence[int], max_runs: int,
         alpha: float, margin: float | None = None, futility: bool = True) -> Look:
    """The decision at the last of ``looks`` (run counts of every look so far, the last
    being ``len(d)``) for per-run differences ``d``, with looks planned up to
    ``max_runs`` and this comparison's level ``alpha``. A question no number of runs up
    to ``max_runs`` can decide (futile) stops at any look, the first included: stopping
    without a verdict spends no α (``futility`` False: only at the last look)."""
    import numpy as np

    d = np.asarray(d, dtype=np.float64)
    j = len(d)
    if j < 2 or looks[-1] != j:
        raise InputError(f"a look needs ≥ 2 runs and the last look at {j}, got {list(looks)}")
    c, c_last = _bounds(looks, max_runs, ratio, alpha)
    mean, var = float(d.mean()), float(d.var(ddof=1))
    se = math.sqrt((1 / j + ratio) * var)
    z = mean / se if se > 0 else (0.0 if mean == 0 else math.copysign(math.inf, mean))
    code = int(_decide(mean, var, j, ratio, c, c_last, max_runs, margin, futility))
    if code == _REACH:
        return Look(j, mean, se, z, c, alpha, FUTILE, _out_of_reach(
            mean, float(futility_reach(var, j, max_runs)),
            math.sqrt(1 / max_runs + ratio) * float(favourable_sd(var, j)) * c_last,
            max_runs, margin))
    decision = {_B: B_BETTER, _A: A_BETTER, _EQ: EQUIVALENT, _GO: CONTINUE}
    why = {_LAST: "the last planned look",
           _FLAT: "every run gave the same difference, 0: nothing varies to test (a "
                  "ceiling, where both are right on every recording), and more runs like "
                  "these add nothing"}
    return Look(j, mean, se, z, c, alpha, decision.get(code, FUTILE), why.get(code, ""))


def _out_of_reach(mean: float, move: float, needed: float, max_runs: int,
                  margin: float | None) -> str:
    """Why a look is futile before the last, and what data would change that. The
    per-run spread of a difference is mostly test sampling, which shrinks as
    1/√recordings: with ``k`` times the recordings (people, where they are the unit) the
    boundary ``needed`` and the runs' reach ``move`` both shrink by √k while the
    difference stays, so a difference is within reach once ``|mean| + move/√k ≥
    needed/√k`` and equivalence once ``max(0, |mean| − move/√k) + needed/√k ≤ margin``
    (:func:`recordings_to_reach`)."""
    best = abs(mean) + move
    k = recordings_to_reach(mean, move, needed, margin)
    more = (f"; more data would, not more runs: about {k:.1f}× the test recordings "
            f"(people, where they are the unit)" if k is not None else "")
    return (f"no number of runs up to {max_runs} can decide it: at {max_runs} runs the "
            f"boundary ±{needed * 100:.1f} points is beyond the reach of {best * 100:.1f}"
            + (" and the margin out of reach" if margin else "") + more)


def recordings_to_reach(mean: float, move: float, needed: float, margin: float | None
                        ) -> float | None:
    """The fewest multiples ``k`` of the test recordings at which a look like this one
    would not be futile (see :func:`_out_of_reach`; the smaller of a difference's and,
    with a margin, equivalence's), None where none up to 10 000 is."""
    options = []
    if abs(mean) > 0:
        options.append(max(1.0, ((needed - move) / abs(mean)) ** 2))
    if margin:
        low, high = 1.0, 1e4
        fits = lambda k: max(0.0, abs(mean) - move / math.sqrt(k)) + needed / math.sqrt(k) \
            <= margin  # noqa: E731
        if fits(high):
            for _ in range(60):  # fits(k) is monotone in k while |mean| < margin
                mid = math.sqrt(low * high)
                low, high = (low, mid) if fits(mid) else (mid, high)
            options.append(high)
    best = min(options, default=None)
    return best if best is not None and best <= 1e4 else None


#: Paths :func:`procedure` simulates: its shares are off by at most ``0.5/√paths``
#: (one standard error; 0.0035 at 20 000).
FORECAST_PATHS = 20_000


@dataclass(frozen=True)
class Procedure:
    """What a run ``--until answered`` will do for one comparison, simulated: the share
    of runs ending in each decision, the expected and largest number of runs, and the
    simulation's standard error on a share (``mc_error``)."""

    power: float  # the true difference found (better, on its side)
    futile: float  # no verdict: stopped_futile + undecided_at_max
    equivalent: float
    wrong_side: float  # declared better on the other side
    expected_runs: float
    max_runs: int
    paths: int
    mc_error: float
    stopped_futile: float = 0.0  # stopped early, no number of runs up to the max could decide
    undecided_at_max: float = 0.0  # reached the maximum runs undecided (or the last look)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def procedure(effect: float, sd: float, ratio: float, looks: Sequence[int], *,
              alpha: float, margin: float | None = None, paths: int = FORECAST_PATHS,
              seed: int = 37, futility: bool = True) -> Procedure:
    """The whole sequential procedure for a true difference ``effect`` (per-run sd
    ``sd`` within a data set, both as fractions), looks after ``looks`` runs (the last the
    maximum), this comparison's level ``alpha`` (a family's: its Holm share at the first
    look) and ``margin``: each simulated path draws its runs with the overlap the
    correction assumes (a shared part of variance ``ratio · sd²``, each run its own of
    ``sd²``, so the fixed-design :func:`tactbench.runner.analysis.power.power` is this at one
    look) and meets the boundaries of :func:`boundaries` and the rule of :func:`look`.
    Deterministic (a fixed seed). ``futility`` False: never stopped futile before the
    last look (the same paths: what futility gives up is the difference)."""
    import numpy as np

    looks = [int(j) for j in looks]
    max_runs = looks[-1]
    code, stop = simulate_paths(effect, sd, ratio, looks, alpha=alpha, margin=margin,
                                paths=paths, seed=seed, futility=futility)
    right = _B if effect >= 0 else _A
    futile = np.isin(code, (_LAST, _FLAT, _REACH, _GO))
    early = np.isin(code, (_FLAT, _REACH)) & (stop < max_runs)
    return Procedure(power=float(np.mean(code == right)), futile=float(futile.mean()),
                     stopped_futile=float(early.mean()),
                     undecided_at_max=float(np.mean(futile & ~early)),
                     equivalent=float(np.mean(code == _EQ)),
                     wrong_side=float(np.mean(code == (_A if right == _B else _B))),
                     expected_runs=float(stop.mean()), max_runs=max_runs, paths=paths,
                     mc_error=0.5 / math.sqrt(paths))


#: What a simulated path of :func:`simulate_paths` ended with, by its code; the codes
#: of a stop without a verdict before the last look, and of a verdict.
OUTCOMES = {_B: B_BETTER, _A: A_BETTER, _EQ: EQUIVALENT, _LAST: "last look",
            _FLAT: "no variation", _REACH: FUTILE, _GO: CONTINUE}
OUTCOMES_FUTILE, DECIDED_CODES = (_FLAT, _REACH), (_B, _A, _EQ)


def simulate_paths(effect: float, sd: float, ratio: float, looks: Sequence[int], *,
                   alpha: float, margin: float | None = None, paths: int = FORECAST_PATHS,
                   seed: int = 37, futility: bool = True,
                   levels: tuple[float, float] | None = None):
    """Each simulated path of :func:`procedure`: its outcome code (:data:`OUTCOMES`) and
    the runs at which it stopped, as two arrays; the paths depend on ``seed`` only.
    ``levels``: the futility rule's (predictive, spread) levels (:func:`out_of_reach`),
    the package's unless given."""
    import numpy as np

    looks = [int(j) for j in looks]
    max_runs = looks[-1]
    rng = np.random.default_rng(seed)
    shared = effect + rng.standard_normal(paths) * sd * math.sqrt(ratio)
    total, squares = np.zeros(paths), np.zeros(paths)
    code = np.full(paths, _GO)
    stop = np.full(paths, max_runs)
    made = 0
    for k, j in enumerate(looks):
        own = rng.standard_normal((paths, j - made)) * sd
        total += own.sum(axis=1)
        squares += (own * own).sum(axis=1)
        made = j
        mean = shared + total / j
        var = np.maximum(squares - total * total / j, 0.0) / (j - 1)
        c, c_last = _bounds(looks[:k + 1], max_runs, ratio, alpha)
        going = code == _GO
        now = _decide(mean, var, j, ratio, c, c_last, max_runs, margin, futility, levels)
        code = np.where(going, now, code)
        stop = np.where(going & (now != _GO), j, stop)
        if not (code == _GO).any():
            break
    return code, stop


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


def _look_distinct(d: Sequence[float], ratio: float, looks: Sequence[int], max_runs: int,
                   alpha: float, margin: float | None, futility: bool) -> Look:
    """:func:`look` at ``looks``, where ``d`` holds one difference per **distinct** split:
    fewer than the look's runs when seeds repeated a split (few sessions or people allow
    few). Then no more runs can add evidence: the look is the last, at the distinct
    splits there are, and says so."""
    j = len(d)
    if j >= looks[-1]:
        return look(d, ratio, looks=looks, max_runs=max_runs, alpha=alpha, margin=margin,
                    futility=futility)
    why = (f"the data allow only {j} distinct split(s) for {looks[-1]} runs: more runs "
           f"repeat splits already drawn and add no evidence")
    if j < 2:
        return Look(j, float(d[0]) if j else 0.0, math.nan, math.nan, math.inf, alpha,
                    FUTILE, why)
    res = look(d, ratio, looks=[x for x in looks[:-1] if x < j] + [j], max_runs=j,
               alpha=alpha, margin=margin, futility=futility)
    return res if res.decision not in (FUTILE, CONTINUE) else replace(
        res, decision=FUTILE, why=why + (f"; {res.why}" if res.why else ""))


def _minimum(res: Look, discordant: int | None, max_runs: int) -> Look:
    """``res`` with a verdict taken back where the cells disagree on fewer distinct test
    recordings than a verdict needs (None: not known, as before): it goes on, or at the
    last look stops without one."""
    if discordant is None or discordant >= MIN_DISCORDANT_RECORDINGS or \
            res.decision not in (B_BETTER, A_BETTER, EQUIVALENT):
        return res
    why = (f"the cells disagree on {discordant} distinct test recording(s): no verdict "
           f"below {MIN_DISCORDANT_RECORDINGS}")
    return replace(res, decision=FUTILE if res.runs >= max_runs else CONTINUE, why=why)


def _rejected(state: FamilyState, name: str) -> bool:
    """Whether the family has declared ``name`` better or worse (its hypothesis rejected)."""
    closed = state.closed.get(name)
    return closed is not None and closed.decision in (B_BETTER, A_BETTER)


def family_look(state: FamilyState, diffs: dict[str, Sequence[float]], ratios: dict[str, float],
                *, looks: Sequence[int], max_runs: int, margin: float | None = None,
                not_learned: Mapping[str, str] | None = None, futility: bool = True,
                discordant: Mapping[str, int] | None = None) -> dict[str, Look]:
    """One look at every open comparison of a family; decided ones close, and the α of
    one declared better or worse passes in equal shares to **every hypothesis not
    rejected** — those still open (looked at again at their new level) and those closed
    without a verdict (futile, equivalent, not learned), whose share is kept unused.
    This is Holm over what remains: after r rejections of m, each hypothesis not
    rejected holds α/(m − r), whether or not it is still being tested. It is the
    graphical procedure of Bretz et al. (2009) with the Holm graph (equal weights to
    every other node), whose family-wise error is proven for any dependence given a
    valid level-share test per hypothesis (here the group-sequential boundaries,
    Maurer & Bretz 2013); stopping a hypothesis for futility is non-binding — it
    rejects nothing the full procedure would not — so the bound holds with futility on.
    (Passing the share to open comparisons only, as before issue 48, gave the last
    open one α/3 + α/3 where Holm gives α/2.) Returns the look of each comparison open
    before.

    ``not_learned`` (name → why): comparisons one of whose cells did not learn; they
    close as :data:`NOT_LEARNED`, a stop without a verdict, whatever their t: no α passes
    from them, so the family's error stays bounded as for a futile stop.

    ``discordant`` (name → the distinct test recordings the cells disagree on so far):
    the one minimum of evidence a fixed design applies
    (:data:`~tactbench.runner.analysis.statistics.MIN_DISCORDANT_RECORDINGS`,
    :func:`~tactbench.runner.analysis.statistics.verdict`) applies at every look too:
    below it a boundary crossed decides nothing — the look goes on, and at the last it
    stops without a verdict, saying why."""
    out: dict[str, Look] = {}
    not_learned = not_learned or {}
    changed = True
    while changed:
        changed = False
        open_now = [n for n in state.names if n not in state.closed]
        for name in open_now:
            res = _look_distinct(diffs[name], ratios[name], looks, max_runs,
                                 state.shares[name], margin, futility)
            if name in not_learned:
                res = replace(res, decision=NOT_LEARNED, why=not_learned[name])
            res = _minimum(res, (discordant or {}).get(name), max_runs)
            out[name] = res
            if res.decision in (B_BETTER, A_BETTER):
                state.closed[name] = res
                rest = [n for n in state.names if n != name and not _rejected(state, n)]
                for n in rest:
                    state.shares[n] += state.shares[name] / len(rest)
                changed = any(n not in state.closed for n in rest)
                break
    for name, res in out.items():
        if name not in state.closed and res.decision in (EQUIVALENT, FUTILE, NOT_LEARNED):
            state.closed[name] = res
    return out
