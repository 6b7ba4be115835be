"""A primary family's chance of being answered, simulated through the run's own procedure.

``tactbench plan`` says, beside each primary comparison's forecast, the chance that
every comparison of the family is answered (better either way, or equivalent). The
comparisons are not independent (two encoders against one raw baseline share its runs)
and the run does not test each at a fixed α/m (Holm passes the α of a rejection on,
:func:`tactbench.runner.analysis.sequential.family_look`), so the product of each one's
chance is not it. :func:`family_forecast` draws the family's per-run differences
(:func:`draw_family`, correlated by the cells the comparisons share,
:func:`arm_correlation`) and judges them as the run does: the sequential looks
(:func:`family_codes`, path by path the decisions of ``family_look``, its boundaries
and rule) or one fixed test with Holm and TOST (:func:`fixed_family_codes`).
``benchmarks/statistics_checks.py --part family`` checks it against the run's own code
over drawn cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from tactbench.runner.analysis.sequential import (_A, _B, _EQ, _GO, _LAST, DECIDED_CODES,
                                                  _bounds, _decide)
from tactbench.runner.analysis.statistics import MIN_RUNS, corrected_t, holm, tost_p


#: Paths :func:`family_forecast` simulates in ``tactbench plan``: few enough to stay well
#: under a second with three primaries and four looks (on a 2-core VM: 0.05 s once
#: the boundaries are placed, 0.56 s where Holm's later levels α/2 and α place theirs
#: for the first time), one standard error on the family's share at most
#: ``0.5/√paths`` (0.011).
FAMILY_PATHS = 2000


def arm_correlation(pairs: Sequence[tuple]) -> list[list[float]]:
    """The correlation of the per-run differences of comparisons ``pairs`` (each ``(A,
    B)``, cells by any hashable name), from the cells they share: with every cell's
    accuracy varying on its own by the same amount, ``B − A`` and ``B′ − A′`` covary by
    one cell's variance for each cell in the same role (``A = A′`` or ``B = B′``) and by
    minus it for each in opposite roles, so two comparisons against one baseline
    (``raw → frame-diff``, ``raw → farneback``) correlate by 0.5; comparisons with no
    cell in common are taken as independent (what their shared splits add is not
    known before the runs)."""
    out = []
    for a, b in pairs:
        row = []
        for a2, b2 in pairs:
            same = (a == a2) + (b == b2) - (a == b2) - (b == a2)
            row.append(same / 2)
        out.append(row)
    return out


def draw_family(effects: Sequence[float], sds: Sequence[float], ratios: Sequence[float],
                corr: Sequence[Sequence[float]], max_runs: int, *, paths: int, seed: int):
    """Per-run differences of a family, ``(paths, m, max_runs)``: comparison ``i`` as in
    :func:`simulate_paths` (a part every run shares, of variance ``ratio_i · sd_i²``, and
    each run's own, of ``sd_i²``), the comparisons correlated by ``corr`` in both parts
    (:func:`arm_correlation`). Depends on ``seed`` only."""
    import numpy as np

    effects, sds, ratios = (np.asarray(x, dtype=float) for x in (effects, sds, ratios))
    w, v = np.linalg.eigh(np.asarray(corr, dtype=float))
    root = v * np.sqrt(np.clip(w, 0.0, None))  # root @ root.T == corr (singular allowed)
    rng = np.random.default_rng(seed)
    m = len(effects)
    shared = rng.standard_normal((paths, m)) @ root.T * sds * np.sqrt(ratios)
    own = np.einsum("pjk,ik->pij", rng.standard_normal((paths, max_runs, m)), root)
    return effects[None, :, None] + shared[:, :, None] + own * sds[None, :, None]


def family_codes(diffs, ratios: Sequence[float], looks: Sequence[int], *, alpha: float,
                 margin: float | None = None, futility: bool = True):
    """What the run's looks (:func:`family_look`: Holm carried over the looks, α of a
    rejection passed to every hypothesis not rejected) end with on each path of
    ``diffs`` (``(paths, m, ≥ looks[-1])``), vectorised over the paths: the decision
    codes ``(paths, m)`` (:data:`~tactbench.runner.analysis.sequential.OUTCOMES`) and the runs each path stopped at. After r
    rejections of m every hypothesis not rejected holds α/(m − r), so a look repeats at
    the larger level until no more is rejected, as :func:`family_look` does; its
    boundaries are the same calls (:func:`_bounds`). The minimum of discordant
    recordings and "not learned" are not simulated (learners, enough disagreement)."""
    import numpy as np

    diffs = np.asarray(diffs, dtype=float)
    paths, m, _ = diffs.shape
    looks = [int(j) for j in looks]
    max_runs = looks[-1]
    code = np.full((paths, m), _GO)
    stop = np.full(paths, max_runs)
    for k, j in enumerate(looks):
        mean, var = diffs[:, :, :j].mean(axis=2), diffs[:, :, :j].var(axis=2, ddof=1)
        was_open = code == _GO
        now = code.copy()
        while True:
            rejected = np.isin(now, (_B, _A)).sum(axis=1)
            fresh = now.copy()
            for i in range(m):
                todo = was_open[:, i] & ~np.isin(now[:, i], (_B, _A))  # rejected stays
                for r in np.unique(rejected[todo]):
                    rows = todo & (rejected == r)
                    c, c_last = _bounds(looks[:k + 1], max_runs, ratios[i], alpha / (m - r))
                    fresh[rows, i] = _decide(mean[rows, i], var[rows, i], j, ratios[i], c,
                                             c_last, max_runs, margin, futility)
            # only a rejection raises the others' level: keep rejections, redo the rest
            grew = np.isin(fresh, (_B, _A)).sum(axis=1) > rejected
            now = np.where(was_open, fresh, code)
            if not grew.any():
                break
            # the paths that rejected more look again; the others are settled
            keep = ~grew[:, None] | np.isin(now, (_B, _A))
            now = np.where(was_open & ~keep, _GO, now)
        stop = np.where(was_open.any(axis=1) & ~(now == _GO).any(axis=1)
                        & (stop == max_runs), j, stop)
        code = now
        if not (code == _GO).any():
            break
    return code, stop


def fixed_family_codes(diffs, ratios: Sequence[float], *, alpha: float,
                       margin: float | None = None):
    """What a fixed design's verdicts are on each path of ``diffs`` (``(paths, m, J)``):
    each comparison's corrected t, Holm over the family, TOST with Holm where there is a
    margin (:func:`~tactbench.runner.analysis.statistics.verdict`'s rule, learners with
    enough disagreement assumed), as decision codes ``(paths, m)``: better either way,
    equivalent, or :data:`_LAST` (unresolved)."""
    import numpy as np

    diffs = np.asarray(diffs, dtype=float)
    paths, m, j = diffs.shape
    t = [corrected_t(diffs[:, i], ratios[i]) for i in range(m)]
    p_holm = holm(np.stack([x["p"] for x in t], axis=1))
    low, high = (np.stack([x[k] for x in t], axis=1) for k in ("low", "high"))
    eq = (holm(np.stack([tost_p(diffs[:, i], ratios[i], margin) for i in range(m)], axis=1))
          < alpha) if margin else np.zeros((paths, m), dtype=bool)
    if j < MIN_RUNS:
        return np.full((paths, m), _LAST)
    return np.select([(p_holm < alpha) & (low > 1e-9), (p_holm < alpha) & (high < -1e-9), eq],
                     [_B, _A, _EQ], _LAST)


@dataclass(frozen=True)
class FamilyForecast:
    """A primary family's chance of being answered, simulated through the run's own
    procedure: ``answered`` every comparison (better either way, or equivalent),
    ``each`` the share per comparison, over ``paths`` paths (``mc_error``: one standard
    error at most, ``0.5/√paths``), the comparisons correlated by ``corr``."""

    answered: float
    each: list[float]
    paths: int
    mc_error: float
    corr: list[list[float]]

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def family_forecast(effects: Sequence[float], sds: Sequence[float], ratios: Sequence[float],
                    pairs: Sequence[tuple], *, runs: int, looks: Sequence[int] | None,
                    alpha: float, margin: float | None = None, paths: int = FAMILY_PATHS,
                    seed: int = 41) -> FamilyForecast:
    """The chance that every comparison of a primary family is answered: paths drawn by
    :func:`draw_family` (correlated by the cells the comparisons share,
    :func:`arm_correlation`) and judged as the run judges them — with ``looks`` (a run
    ``--until answered``, the last the maximum) by :func:`family_codes`, the looks'
    own Holm carried over; without, a fixed design of ``runs`` by
    :func:`fixed_family_codes`. Deterministic (a fixed seed)."""
    import numpy as np

    corr = arm_correlation(pairs)
    diffs = draw_family(effects, sds, ratios, corr, looks[-1] if looks else runs,
                        paths=paths, seed=seed)
    if looks:
        code, _ = family_codes(diffs, ratios, looks, alpha=alpha, margin=margin)
    else:
        code = fixed_family_codes(diffs, ratios, alpha=alpha, margin=margin)
    done = np.isin(code, DECIDED_CODES)
    return FamilyForecast(answered=float(done.all(axis=1).mean()),
                          each=[float(x) for x in done.mean(axis=0)], paths=paths,
                          mc_error=0.5 / math.sqrt(paths), corr=corr)
