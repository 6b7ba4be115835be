"""tactbench.runner.analysis.power against independent computations: simulation and baycomp."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactbench.errors import InputError
from tactbench.runner.analysis.power import (
    bayes_correlated_t,
    detectable_effect,
    effect_floor,
    power,
    recordings_for,
    runs_for_power,
    sampling_sd,
    seed_mean_ratio,
    t_power,
)
from tactbench.runner.analysis.statistics import corrected_t, sign_flip_p


def _correlated_runs(rng, sims, runs, delta, sd, ratio):
    """Per-run differences of repeated splits of one data set: runs share a component
    (the recordings they all draw from) with correlation ρ = ratio / (1 + ratio), the
    correlation the Nadeau–Bengio correction assumes."""
    rho = ratio / (1 + ratio)
    shared = rng.normal(0, sd * math.sqrt(rho), size=(sims, 1))
    own = rng.normal(0, sd * math.sqrt(1 - rho), size=(sims, runs))
    return delta + shared + own


def test_power_matches_a_simulation_of_the_corrected_t():
    rng = np.random.default_rng(5)
    ratio, sd, runs, delta = 0.25, 0.04, 8, 0.05
    d = _correlated_runs(rng, 20000, runs, delta, sd, ratio)
    # the per-run sd the formula takes is the spread within a family (what s estimates)
    within = sd * math.sqrt(1 / (1 + ratio))
    simulated = float((corrected_t(d, ratio)["p"] < 0.05).mean())
    assert power(delta, within, ratio, runs) == pytest.approx(simulated, abs=0.03)


#: Power of the corrected t at J = 3 runs (df 2), sd 0.0369, ratio 0.2667, α 0.0125,
#: computed independently (docs/statistics.md, "Reference values"; scipy's nct gave
#: 0.9490 / 0.9964 / 1.0000 for the last three).
REFERENCE_POWER = [(0.25, 0.6182), (0.30, 0.7487), (0.33, 0.8114), (0.40, 0.9133)]


@pytest.mark.parametrize("effect, expected", REFERENCE_POWER)
def test_power_at_two_degrees_of_freedom_is_the_reference_value(effect, expected):
    assert power(effect, 0.0369, 0.2667, 3, alpha=0.0125) == pytest.approx(expected, abs=1e-4)


@pytest.mark.parametrize("df, nc, alpha", [(1, 5.0, 0.05), (2, 3.0, 0.05), (2, 6.0, 0.0125),
                                           (4, 2.5, 0.01), (9, 4.0, 1e-3)])
def test_t_power_matches_a_large_simulation_at_few_degrees_of_freedom(df, nc, alpha):
    """A million noncentral t's drawn from their definition (Z + λ) / sqrt(V/df),
    fixed seed; the simulated share beyond ±c is within 4 of its standard errors."""
    from scipy import stats

    rng = np.random.default_rng(37)
    n = 1_000_000
    c = float(stats.t.isf(alpha / 2, df))
    t = (rng.standard_normal(n) + nc) / np.sqrt(rng.chisquare(df, n) / df)
    share = float((np.abs(t) > c).mean())
    assert t_power(nc, c, df) == pytest.approx(share, abs=4 * math.sqrt(share * (1 - share) / n))


@pytest.mark.parametrize("df", [1, 2, 3, 10, 200])
def test_t_power_under_no_difference_is_alpha(df):
    from scipy import stats

    for alpha in (0.05, 0.0125, 1e-6):
        assert t_power(0.0, float(stats.t.isf(alpha / 2, df)), df) == \
            pytest.approx(alpha, rel=1e-6)


def test_runs_for_power_at_three_runs_is_what_a_simulation_of_the_corrected_t_says():
    """An effect whose exact power at 2 runs is far below 80 % and at 3 runs above it:
    runs_for_power says 3, and a simulation of the corrected t agrees with both powers."""
    rng = np.random.default_rng(8)
    sd, ratio, alpha = 0.02, 0.25, 0.025
    effect = detectable_effect(sd, ratio, 3, alpha=alpha)
    assert runs_for_power(effect * 1.001, sd, ratio, alpha=alpha) == 3
    for runs in (2, 3):
        d = _correlated_runs(rng, 200_000, runs, effect, sd * math.sqrt(1 + ratio), ratio)
        share = float((corrected_t(d, ratio)["p"] < alpha).mean())
        assert power(effect, sd, ratio, runs, alpha=alpha) == \
            pytest.approx(share, abs=4 * math.sqrt(share * (1 - share) / 200_000))


def test_detectable_effect_inverts_power_and_approaches_the_floor():
    sd, ratio = 0.03, 0.25
    e = detectable_effect(sd, ratio, 10)
    assert power(e, sd, ratio, 10) == pytest.approx(0.8, abs=1e-6)
    floor = effect_floor(sd, ratio)
    assert floor < detectable_effect(sd, ratio, 1000) < floor * 1.05
    assert detectable_effect(sd, ratio, 5) > detectable_effect(sd, ratio, 50) > floor


def test_runs_for_power_is_the_first_run_count_that_reaches_it_or_none_below_the_floor():
    sd, ratio = 0.03, 0.25
    floor = effect_floor(sd, ratio)
    j = runs_for_power(floor * 1.5, sd, ratio)
    assert j is not None and power(floor * 1.5, sd, ratio, j) >= 0.8
    assert j == 2 or power(floor * 1.5, sd, ratio, j - 1) < 0.8
    assert runs_for_power(floor * 0.99, sd, ratio) is None
    assert runs_for_power(0.0, sd, ratio) is None


def test_seed_means_of_k_folds_need_the_factor_k_over_k_minus_1():
    """Fold differences correlated 1/K (Bouckaert & Frank): the corrected t over seed
    means keeps its level with K/(K − 1), and exceeds it with 1/(K − 1)."""
    rng = np.random.default_rng(11)
    k, r, sims = 5, 5, 20000
    rho = 1 / k
    shared = rng.normal(0, math.sqrt(rho), size=(sims, 1, 1))
    folds = shared + rng.normal(0, math.sqrt(1 - rho), size=(sims, r, k))
    seed_means = folds.mean(axis=2)
    right = float((corrected_t(seed_means, seed_mean_ratio(k))["p"] < 0.05).mean())
    wrong = float((corrected_t(seed_means, 1 / (k - 1))["p"] < 0.05).mean())
    mc = 3 * math.sqrt(0.05 * 0.95 / sims)
    assert right <= 0.05 + mc
    assert wrong > 0.05 + mc


def test_the_corrected_t_keeps_its_level_where_the_plain_t_and_the_sign_flip_do_not():
    """Runs that overlap (ρ = r/(1 + r)): the false-verdict rate of the corrected t stays
    at α, the plain t's and the sign-flip's do not — the sign-flip is no check on the
    correction."""
    rng = np.random.default_rng(3)
    sims, runs, ratio = 20000, 10, 0.25
    d = _correlated_runs(rng, sims, runs, 0.0, 0.03, ratio)
    mc = 3 * math.sqrt(0.05 * 0.95 / sims)
    corrected = float((corrected_t(d, ratio)["p"] < 0.05).mean())
    plain = float((corrected_t(d, 0.0)["p"] < 0.05).mean())
    flip = float((sign_flip_p(d[:4000]) < 0.05).mean())
    assert corrected <= 0.05 + mc
    assert plain > 0.10 and flip > 0.10


def test_sampling_sd_is_the_spread_of_a_paired_difference_on_n_recordings():
    rng = np.random.default_rng(2)
    n, pi, delta = 150, 0.3, 0.1
    probs = [(pi - delta) / 2, 1 - pi, (pi + delta) / 2]
    counts = rng.multinomial(n, probs, size=50000)
    d = (counts[:, 2] - counts[:, 0]) / n
    assert sampling_sd(n, pi, delta) == pytest.approx(d.std(), rel=0.02)
    with pytest.raises(InputError, match="disagree"):
        sampling_sd(n, 0.01, 0.2)


def test_recordings_for_scales_with_the_square_of_the_floor():
    assert recordings_for(0.02, 0.04, 750) == 3000
    assert recordings_for(0.05, 0.04, 750) == 750


def test_bayes_correlated_t_sums_to_one_and_follows_the_evidence():
    d = np.array([0.05, 0.07, 0.04, 0.06, 0.08, 0.05])
    p = bayes_correlated_t(d, 0.25, 0.01)
    assert sum(p.values()) == pytest.approx(1.0)
    assert p["p_b_better"] > 0.9 > p["p_a_better"]
    q = bayes_correlated_t(-d, 0.25, 0.01)
    assert q["p_a_better"] == pytest.approx(p["p_b_better"])
    tight = bayes_correlated_t(np.array([0.001, -0.002, 0.0, 0.001, -0.001]), 0.0, 0.02)
    assert tight["p_equivalent"] > 0.99


def test_bayes_correlated_t_agrees_with_baycomp_where_its_correlation_applies():
    """baycomp fixes ρ = runs/len(x) (repeated K-fold); with ratio = ρ/(1 − ρ) the two
    are the same posterior."""
    baycomp = pytest.importorskip("baycomp", reason="baycomp is not installed")
    rng = np.random.default_rng(0)
    x = rng.normal(0.8, 0.02, 10)
    y = x + rng.normal(0.01, 0.02, 10)
    # baycomp: 10 differences, runs=2 → 5 folds, ρ = 1/5, ratio = 0.25
    left, rope, right = baycomp.two_on_single(x, y, rope=0.01, runs=2)
    mine = bayes_correlated_t(y - x, 0.25, 0.01)
    assert mine["p_a_better"] == pytest.approx(left, abs=1e-6)
    assert mine["p_equivalent"] == pytest.approx(rope, abs=1e-6)
    assert mine["p_b_better"] == pytest.approx(right, abs=1e-6)


def test_bad_input_is_one_clear_error():
    with pytest.raises(InputError, match="runs"):
        power(0.05, 0.03, 0.25, 1)
    with pytest.raises(InputError, match="sd"):
        detectable_effect(float("nan"), 0.25, 5)
    with pytest.raises(InputError, match="folds"):
        seed_mean_ratio(1)
    with pytest.raises(InputError, match="2 finite"):
        bayes_correlated_t([0.1], 0.25, 0.01)
