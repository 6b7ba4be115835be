"""Planning numbers for a paired comparison of two training procedures, before and after.

Pure functions (numbers in, numbers out; scipy imported inside them), with the training
run as the unit as everywhere in :mod:`tactbench.runner.analysis.statistics`. The per-run
differences ``d_1 … d_J`` of repeated random splits of one data set are correlated (they
share recordings): the corrected resampled t of Nadeau & Bengio (2003) takes
``var(mean d) = (1/J + ratio) · s²`` with ``ratio = n_test / n_train`` (``K/(K − 1)`` for
seed means of K folds, see :func:`seed_mean_ratio`). Everything here follows from that one
variance:

- :func:`power`: the power of the two-sided corrected t at J runs for a true difference
  ``effect`` (noncentral t with J − 1 degrees of freedom, :func:`t_power`: one integral
  over the normal, exact at every number of runs where scipy's ``nct`` is not);
- :func:`detectable_effect`: the smallest difference found at a given power;
- :func:`runs_for_power`: the fewest runs reaching a power, or None;
- :func:`persistent_sd`: the part of the per-run spread more runs cannot remove,
  ``sd · sqrt(ratio)`` (the corrected standard error's limit as J → ∞);
- :func:`effect_floor`: the limit of :func:`detectable_effect` as J → ∞ — no number of
  runs of *these* recordings resolves less, because ``ratio · s²`` stays;
- :func:`recordings_for`: how many recordings (same proportions) would lower that floor
  to a target;
- :func:`sampling_sd`: the per-run standard deviation that test sampling alone
  gives, ``sqrt((π − δ²)/n_test)`` (π: the share of test recordings on which the two
  models disagree) — the planning value when no pilot run exists;
- :func:`bayes_correlated_t`: the Bayesian correlated t of Corani & Benavoli (2015):
  the posterior probabilities that A is better by more than a margin, that the two are
  equivalent within it, and that B is better by more than it.

Hand-written rather than taken from a library: statsmodels' ``TTestPower`` and baycomp's
``CorrelatedTTest`` both assume another variance (the plain t, and a correlation fixed at
``1/K`` by K folds); the corrected variance with ``ratio = n_test/n_train`` needs only the
noncentral t (computed here, :func:`t_power`) and the Student t of scipy. ``tests/runner/analysis/test_power.py`` checks each
against an independent computation (a simulation, or baycomp where it applies).
"""

from __future__ import annotations

import math

from tactbench.errors import InputError

#: The power a plan aims at when none is given.
TARGET_POWER = 0.8
#: Runs beyond this are not searched (the answer is "more than this").
MAX_RUNS = 1000
#: More recordings than this are no plan a data set can follow: :func:`recordings_for`
#: says none (a vanishing effect needs ever more, without bound).
MAX_RECORDINGS = 10 ** 9


def _check(value: float, name: str, *, low: float = 0.0, high: float = math.inf,
           open_low: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value < low or value > high \
            or (open_low and value == low):
        side = ">" if open_low else "≥"
        raise InputError(f"{name} must be a finite number {side} {low}"
                         f"{'' if high == math.inf else f' and ≤ {high}'}, got {value!r}")
    return float(value)


def seed_mean_ratio(folds: int) -> float:
    """The correction factor for *seed means* of a K-fold design: each run's difference
    is the mean of its K fold differences, and ``var(mean) / E[s²] − 1/r`` is
    ``K/(K − 1)`` (derived from Bouckaert & Frank's correlation ``1/K`` between fold
    differences). Per-fold differences use ``1/(K − 1)`` instead."""
    if isinstance(folds, bool) or not isinstance(folds, int) or folds < 2:
        raise InputError(f"folds must be an integer ≥ 2, got {folds!r}")
    return folds / (folds - 1)


def se_factor(runs: int, ratio: float) -> float:
    """``sqrt(1/J + ratio)``: the standard error of the mean difference per unit of the
    per-run standard deviation."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 2:
        raise InputError(f"runs must be an integer ≥ 2, got {runs!r}")
    return math.sqrt(1.0 / runs + _check(ratio, "ratio"))


def power(effect: float, sd: float, ratio: float, runs: int, *, alpha: float = 0.05
          ) -> float:
    """The power of the two-sided corrected t at level ``alpha`` with ``runs`` runs for a
    true mean difference ``effect`` (same unit as ``sd``, the per-run standard deviation):
    :func:`t_power` at noncentrality ``effect / (sd · sqrt(1/J + ratio))``, J − 1 degrees
    of freedom. Exact at every number of runs (to about 1e-10)."""
    from scipy import stats

    alpha = _check(alpha, "alpha", high=1.0, open_low=True)
    sd = _check(sd, "sd")
    effect = abs(_check(effect, "effect", low=-math.inf))
    se = sd * se_factor(runs, ratio)
    if se == 0:
        return 1.0 if effect > 0 else alpha
    df = runs - 1
    return t_power(effect / se, float(stats.t.isf(alpha / 2, df)), df)


def t_power(noncentrality: float, critical: float, df: int) -> float:
    """``P(|T| > critical)`` for a noncentral t with ``df`` degrees of freedom: with
    ``T = (Z + λ) / sqrt(V/df)``, ``Z`` standard normal and ``V ~ χ²(df)``,
    ``|T| > c`` exactly when ``V < (Z + λ)² · df / c²``, so the power is
    ``E_Z[F_χ²(df)((Z + λ)² · df / c²)]``, one integral over the normal (scipy's
    ``quad``, split where the integrand's kink and peak lie).

    scipy's ``nct.sf`` is wrong at 1–2 degrees of freedom for a large noncentrality (at
    df 2 it gives 0.949 where the power is 0.749: docs/statistics.md), which is why this
    is computed here; ``tests/runner/analysis/test_power.py`` checks it against a simulation."""
    from scipy import integrate, special

    nc = abs(float(noncentrality))
    c = df / (float(critical) ** 2)
    edge = 40.0  # the normal's mass beyond ±40 is below 1e-300

    def integrand(z: float) -> float:
        return float(special.chdtr(df, (z + nc) ** 2 * c)) * math.exp(-0.5 * z * z)

    cuts = sorted({-edge, edge, 0.0, max(-edge, -nc)})
    total = sum(integrate.quad(integrand, a, b, epsabs=1e-15, epsrel=1e-12, limit=200)[0]
                for a, b in zip(cuts, cuts[1:]))
    return min(1.0, max(0.0, total / math.sqrt(2 * math.pi)))


def detectable_effect(sd: float, ratio: float, runs: int, *, alpha: float = 0.05,
                      target: float = TARGET_POWER) -> float:
    """The smallest true difference the corrected t finds with power ``target`` at
    ``runs`` runs (same unit as ``sd``)."""
    from scipy import optimize

    target = _check(target, "power", high=1.0, open_low=True)
    se = _check(sd, "sd") * se_factor(runs, ratio)
    if se == 0:
        return 0.0
    if power(0.0, sd, ratio, runs, alpha=alpha) >= target:
        return 0.0
    high = se
    while power(high, sd, ratio, runs, alpha=alpha) < target:
        high *= 2
    return float(optimize.brentq(
        lambda e: power(e, sd, ratio, runs, alpha=alpha) - target, 0.0, high, xtol=1e-12))


def persistent_sd(sd: float, ratio: float) -> float:
    """The part of the per-run spread ``sd`` that more runs of the same recordings cannot
    remove: ``sd · sqrt(ratio)``, the limit of the corrected standard error
    ``sd · sqrt(1/J + ratio)`` as J grows (Nadeau & Bengio 2003; ``ratio =
    n_test/n_train``, ``K/(K − 1)`` for seed means of K folds). On the CySkin pilot, sd
    3.40 points over splits of 165 test and 208 training recordings: 3.40 · √(165/208) =
    3.03 points. (Not ``sd · sqrt(1 − n_test/n)``, 2.54 there: that is a run's own share
    under an overlap model the correction does not use.)"""
    return _check(sd, "sd") * math.sqrt(_check(ratio, "ratio"))


def effect_floor(sd: float, ratio: float, *, alpha: float = 0.05,
                 target: float = TARGET_POWER) -> float:
    """The limit of :func:`detectable_effect` as the runs grow without bound:
    ``(z_{1−α/2} + z_power) · persistent_sd(sd, ratio)``
    (:func:`persistent_sd`, ``sd · sqrt(ratio)``). More runs of the same recordings
    cannot detect a smaller difference; only more recordings (or independent data) can."""
    from scipy import stats

    alpha = _check(alpha, "alpha", high=1.0, open_low=True)
    target = _check(target, "power", high=1.0, open_low=True)
    z = stats.norm.ppf(1 - alpha / 2) + stats.norm.ppf(target)
    return float(z * persistent_sd(sd, ratio))


def runs_for_power(effect: float, sd: float, ratio: float, *, alpha: float = 0.05,
                   target: float = TARGET_POWER, max_runs: int = MAX_RUNS) -> int | None:
    """The fewest runs (≥ 2) at which the corrected t finds ``effect`` with power
    ``target``; None when no number of runs up to ``max_runs`` does (at or below the
    floor, :func:`effect_floor`, none ever does)."""
    effect = abs(_check(effect, "effect", low=-math.inf))
    if effect == 0:
        return None
    if effect <= effect_floor(sd, ratio, alpha=alpha, target=target) * (1 - 1e-12):
        return None
    low, high = 2, 2
    while power(effect, sd, ratio, high, alpha=alpha) < target:
        if high >= max_runs:
            return None
        low, high = high, min(max_runs, high * 2)
    while low < high:  # power grows with the runs: bisect for the first that reaches it
        mid = (low + high) // 2
        if power(effect, sd, ratio, mid, alpha=alpha) >= target:
            high = mid
        else:
            low = mid + 1
    return high


def sampling_sd(n_test: int, discordance: float, effect: float = 0.0) -> float:
    """The per-run standard deviation of a paired difference of accuracies from test
    sampling alone: ``sqrt((π − δ²) / n_test)``, ``π`` the share of test recordings on
    which the two models disagree and ``δ`` the true difference (fractions). With the
    true ``π`` it is below the real per-run spread (training noise adds to it); with an
    assumed ``π`` it is only as good as the assumption (a plan without a pilot says it
    as one: :mod:`tactbench.runner.analysis.forecast`)."""
    if isinstance(n_test, bool) or not isinstance(n_test, int) or n_test < 1:
        raise InputError(f"n_test must be an integer ≥ 1, got {n_test!r}")
    pi = _check(discordance, "discordance", high=1.0)
    delta = _check(effect, "effect", low=-1.0, high=1.0)
    if delta * delta > pi:
        raise InputError(f"a difference of {delta:+.3g} needs the models to disagree on at "
                         f"least {delta * delta:.3g} of the recordings, not {pi:.3g}")
    return math.sqrt((pi - delta * delta) / n_test)


def recordings_for(target_floor: float, floor: float, recordings: int) -> int | None:
    """How many recordings, split in the same proportions, bring the floor from ``floor``
    (at ``recordings``) down to ``target_floor``: the floor scales as
    ``1/sqrt(recordings)`` when the per-run spread is test sampling. None when the target
    is not above 0, or when more than :data:`MAX_RECORDINGS` would be needed (a tiny
    target: the ratio may overflow a float)."""
    target_floor = _check(target_floor, "target floor")
    floor = _check(floor, "floor")
    if target_floor <= 0:
        return None
    if floor <= target_floor:
        return int(recordings)
    scale = 2 * (math.log(floor) - math.log(target_floor))  # in logs: 1e-300 overflows
    if math.log(recordings) + scale > math.log(MAX_RECORDINGS):
        return None
    return int(math.ceil(recordings * (floor / target_floor) ** 2))


def bayes_correlated_t(d, ratio: float, margin: float) -> dict[str, float]:
    """The Bayesian correlated t (Corani & Benavoli 2015) over per-run differences ``d``
    (B − A; J ≥ 2): the posterior of the mean difference is Student t with J − 1 degrees
    of freedom, location ``mean(d)`` and scale ``sqrt((1/J + ratio) · s²)``.

    Returns ``p_a_better`` = P(δ < −margin), ``p_equivalent`` = P(|δ| ≤ margin),
    ``p_b_better`` = P(δ > margin) (they sum to 1); ``margin`` 0 gives the one-sided
    posterior probabilities with no region of practical equivalence.
    """
    import numpy as np
    from scipy import stats

    margin = _check(margin, "margin")
    d = np.asarray(d, dtype=np.float64)
    if d.ndim != 1 or len(d) < 2 or not np.all(np.isfinite(d)):
        raise InputError("a Bayesian correlated t needs ≥ 2 finite per-run differences")
    j = len(d)
    mean, var = float(d.mean()), float(d.var(ddof=1))
    scale = math.sqrt(se_factor(j, ratio) ** 2 * var)
    if scale == 0:
        below, above = float(mean < -margin), float(mean > margin)
    else:
        below = float(stats.t.cdf(-margin, j - 1, loc=mean, scale=scale))
        above = float(stats.t.sf(margin, j - 1, loc=mean, scale=scale))
    return {"p_a_better": below, "p_equivalent": max(0.0, 1.0 - below - above),
            "p_b_better": above}
