"""tactbench.runner.analysis.statistics against independent computations (scipy), simulations with
a per-run model effect and test-set noise, and degenerate inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactbench.errors import InputError
from tactbench.runner.analysis.statistics import (
    MIN_DISCORDANT_RECORDINGS,
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

# ------------------------------------------------------------------------ seed_summary


def test_seed_summary_is_the_t_interval_of_the_mean():
    s = seed_summary([0.80, 0.90, 0.85])
    assert s.n == 3 and s.mean == pytest.approx(0.85) and s.std == pytest.approx(0.05)
    t_975_2 = 4.302652729911275  # Student's t, 2 degrees of freedom, from tables
    half = t_975_2 * 0.05 / math.sqrt(3)
    assert (s.low, s.high) == (pytest.approx(0.85 - half), pytest.approx(0.85 + half))
    assert s.as_dict()["confidence"] == 0.95


def test_seed_summary_of_one_seed_has_no_interval_and_says_so():
    s = seed_summary([0.7])
    assert (s.mean, s.std, s.low, s.high, s.n) == (0.7, None, None, None, 1)
    assert "one seed" in s.note


def test_seed_summary_of_equal_accuracies_is_the_point():
    s = seed_summary(np.full(4, 0.5))
    assert (s.low, s.high, s.std) == (0.5, 0.5, 0.0)


@pytest.mark.parametrize("bad", [[], [0.5, float("nan")]])
def test_seed_summary_refuses_no_or_non_finite_accuracies(bad):
    with pytest.raises(InputError):
        seed_summary(bad)


def test_seed_summary_refuses_a_confidence_outside_0_1():
    with pytest.raises(InputError, match="confidence"):
        seed_summary([0.5, 0.6], confidence=95)


# ------------------------------------------------------------- tests over runs


def test_corrected_t_is_nadeau_bengio_and_without_correction_scipys_t_test():
    from scipy import stats

    d = np.array([0.10, 0.14, 0.08, 0.12, 0.16])
    plain = corrected_t(d, 0.0)
    ref = stats.ttest_1samp(d, 0.0)
    assert float(plain["p"]) == pytest.approx(ref.pvalue)
    ci = ref.confidence_interval(0.95)
    assert (float(plain["low"]), float(plain["high"])) == (pytest.approx(ci.low),
                                                           pytest.approx(ci.high))
    ratio = 400 / 1500
    c = corrected_t(d, ratio)
    se = math.sqrt((1 / 5 + ratio) * d.var(ddof=1))  # Nadeau & Bengio (2003)
    assert float(c["se"]) == pytest.approx(se) and int(c["df"]) == 4
    assert float(c["p"]) == pytest.approx(2 * stats.t.sf(d.mean() / se, 4))
    assert float(c["high"] - c["low"]) > float(plain["high"] - plain["low"])


def test_the_issues_example_users_split_l5_is_reproduced():
    """Issue 18: users split, L = 5, raw → farneback: per-seed differences of the stored
    report; the corrected t gives p ≈ 0.003 and about [+7.7, +18.9]."""
    d = np.array([0.175, 0.1425, 0.11, 0.10, 0.1375])
    c = corrected_t(d, 400 / 1500)
    assert float(c["p"]) == pytest.approx(0.0027, abs=2e-4)
    assert 100 * float(c["low"]) == pytest.approx(7.7, abs=0.05)
    assert 100 * float(c["high"]) == pytest.approx(18.9, abs=0.05)


def test_sign_flip_is_scipys_exact_permutation_test_and_has_a_floor():
    from scipy import stats

    rng = np.random.default_rng(1)
    for j in (3, 5, 8):
        d = rng.normal(0.02, 0.05, size=j)
        ref = stats.permutation_test((d,), np.mean, permutation_type="samples",
                                     n_resamples=np.inf).pvalue
        assert float(sign_flip_p(d)) == pytest.approx(ref)
    assert float(sign_flip_p(np.full(5, 0.1))) == pytest.approx(2 / 2 ** 5)
    assert float(sign_flip_p(np.zeros(4))) == 1.0
    many = rng.normal(0.0, 1.0, size=(7, 6))  # vectorised over leading axes
    assert np.allclose(sign_flip_p(many), [sign_flip_p(r) for r in many])


def test_holm_matches_the_step_down_rule_by_hand_and_leaves_nan_out():
    p = [0.01, 0.04, 0.03, 0.005]
    # sorted 0.005, 0.01, 0.03, 0.04 × 4, 3, 2, 1 → 0.02, 0.03, 0.06, 0.06 (monotone)
    assert holm(p).tolist() == pytest.approx([0.03, 0.06, 0.06, 0.02])
    got = holm([0.01, math.nan, 0.04])
    assert math.isnan(got[1]) and got[[0, 2]].tolist() == pytest.approx([0.02, 0.04])
    assert holm([0.9, 0.8]).max() <= 1.0


def test_tost_shows_equivalence_only_for_a_tight_difference_near_zero():
    tight = np.array([0.002, -0.003, 0.001, 0.0, -0.001, 0.002])
    assert float(tost_p(tight, 0.0, 0.02)) < 0.05
    assert float(tost_p(tight + 0.05, 0.0, 0.02)) > 0.5  # far outside the margin
    wide = np.array([0.08, -0.07, 0.05, -0.06, 0.02, 0.0])
    assert float(tost_p(wide, 0.0, 0.02)) > 0.05  # centred, but too uncertain
    with pytest.raises(InputError, match="margin"):
        tost_p(tight, 0.0, -1)


def test_runs_needed_meets_the_width_and_says_when_no_number_of_runs_does():
    from scipy import stats

    sd = 0.03
    j = runs_needed(sd, 0.0, 0.02)
    width = lambda n: stats.t.ppf(0.975, n - 1) * math.sqrt(1 / n) * sd  # noqa: E731
    assert width(j) <= 0.02 < width(j - 1)
    # the correction keeps ratio · sd² however many runs: 0.27 · 0.03² is too wide for ±2
    assert runs_needed(sd, 400 / 1500, 0.02) is None
    assert runs_needed(0.0, 0.2, 0.02) == 3 and runs_needed(None, 0.2, 0.02) is None


def test_verdict_rules():
    assert verdict(0.05, 0.1, 0.001, 2)[0] == "too few runs"
    assert verdict(0.05, 0.1, 0.001, 5)[0] == "B better"
    assert verdict(-0.1, -0.05, 0.001, 5)[0] == "A better"
    # an interval whose end is 0 plus floating-point noise touches 0
    assert verdict(1.7e-18, 0.1, 0.001, 5)[0] == "unresolved"
    assert verdict(0.05, 0.1, 0.2, 5)[0] == "unresolved"  # adjusted p governs
    assert verdict(-0.01, 0.01, 0.5, 5, equivalence_p_adjusted=0.01)[0] == "equivalent"
    few = verdict(0.05, 0.1, 0.001, 5, discordant_recordings=MIN_DISCORDANT_RECORDINGS - 1)
    assert few[0] == "unresolved" and "recording" in few[1]


def test_mcnemar_per_seed_is_the_exact_binomial():
    from scipy import stats

    a = np.array([True] * 10 + [False] * 6 + [True] * 2)
    b = np.array([True] * 10 + [True] * 6 + [False] * 2)
    assert mcnemar_p(a, b) == pytest.approx(stats.binomtest(6, 8, 0.5).pvalue)
    assert mcnemar_p(a, a) == 1.0


def test_variance_components_recover_simulated_split_and_init_variance():
    rng = np.random.default_rng(3)
    n_split, n_init, sims = 6, 4, 400
    sd_split, sd_init, sd_test = 0.03, 0.02, 0.015
    got = []
    for _ in range(sims):
        v = (0.7 + rng.normal(0, np.hypot(sd_split, sd_test), (n_split, 1))
             + rng.normal(0, sd_init, (n_split, n_init)))
        c = variance_components(v, sd_test ** 2)
        got.append((c["split"], c["init"]))
    split, init = np.mean(got, axis=0)
    assert split == pytest.approx(sd_split ** 2, rel=0.25)
    assert init == pytest.approx(sd_init ** 2, rel=0.1)
    with pytest.raises(InputError, match="2 split seeds"):
        variance_components(np.ones((1, 3)), 0.0)


# ------------------------------------------------------------- checked by simulation


def _simulate(rng, sims, runs, n_test, delta, sd_run, discord=0.2):
    """Per-row differences of B − A (−1, 0, +1) counted per run: each run draws a model
    effect u ~ N(0, sd_run) (training variability) and then its test rows (test-set
    noise). Returns counts (sims, runs, 3) of (−1, 0, +1) rows and the run means."""
    u = rng.normal(0.0, sd_run, size=(sims, runs))
    eff = np.clip(delta + u, -discord + 1e-3, discord - 1e-3)
    probs = np.stack([(discord - eff) / 2, 1 - discord + 0 * eff, (discord + eff) / 2], -1)
    counts = rng.multinomial(n_test, probs)
    return counts, (counts[..., 2] - counts[..., 0]) / n_test


def _old_sequence_bootstrap(rng, counts, n_test, n_resamples=400, conf=0.95):
    """The old interval: test rows resampled within each seed, the models held fixed."""
    props = counts / n_test  # (sims, runs, 3)
    draws = rng.multinomial(n_test, props[:, :, None, :].repeat(n_resamples, axis=2))
    means = ((draws[..., 2] - draws[..., 0]) / n_test).mean(axis=1)  # (sims, resamples)
    return (np.quantile(means, (1 - conf) / 2, axis=-1),
            np.quantile(means, (1 + conf) / 2, axis=-1))


def test_the_run_level_interval_covers_where_the_sequence_bootstrap_falls_short():
    rng = np.random.default_rng(18)
    sims, runs, n_test, delta = 1500, 5, 400, 0.05
    counts, d = _simulate(rng, sims, runs, n_test, delta, sd_run=0.03)
    for ratio in (0.0, n_test / 1500):  # the plain t over runs, and Nadeau–Bengio's
        c = corrected_t(d, ratio)
        covered = np.mean((c["low"] <= delta) & (delta <= c["high"]))
        assert covered >= 0.93, (ratio, covered)
    low, high = _old_sequence_bootstrap(rng, counts[:500], n_test)
    old = np.mean((low <= delta) & (delta <= high))
    assert old < 0.85, old  # it sees the test set's noise only


def test_false_verdicts_under_no_difference_stay_within_5_percent_per_family():
    rng = np.random.default_rng(20)
    families, m, runs, n_test = 1000, 8, 8, 400
    _, d = _simulate(rng, families * m, runs, n_test, 0.0, sd_run=0.03)
    d = d.reshape(families, m, runs)
    c = corrected_t(d, n_test / 1500)
    p = np.maximum(c["p"], sign_flip_p(d))  # the stricter governs
    adjusted = holm(p)
    false = (adjusted < 0.05) & ((c["low"] > 0) | (c["high"] < 0))
    assert false.any(axis=1).mean() <= 0.05
    # the same families judged by a plain t over runs, unadjusted: many false verdicts
    # (so the simulation can show them, and the check above is not empty)
    assert (corrected_t(d, 0.0)["p"] < 0.05).any(axis=1).mean() > 0.2


# -------------------------------------------------------- pairs_differing_in_one_factor


def test_pairs_differing_in_one_factor():
    cells = [
        {"encoder": "raw", "classifier": "logreg", "L": 5},        # 0
        {"encoder": "farneback", "classifier": "logreg", "L": 5},  # 1
        {"encoder": "raw", "classifier": "sklearn", "L": 5},       # 2
        {"encoder": "farneback", "classifier": "sklearn", "L": 4},  # 3: two factors from 2
        {"encoder": "raw", "classifier": "logreg", "L": 4},        # 4
    ]
    got = [(p.a, p.b, p.factor, p.value_a, p.value_b)
           for p in pairs_differing_in_one_factor(cells)]
    assert got == [
        (0, 1, "encoder", "raw", "farneback"),
        (0, 2, "classifier", "logreg", "sklearn"),
        (0, 4, "L", 5, 4),
    ]
    backwards = [(p.a, p.b, p.factor) for p in pairs_differing_in_one_factor(cells[::-1])]
    assert backwards == [(3, 4, "encoder"), (2, 4, "classifier"), (0, 4, "L")]
    assert pairs_differing_in_one_factor([cells[0], dict(cells[0])]) == []
    assert pairs_differing_in_one_factor([]) == []


def test_pairs_need_the_same_factors():
    with pytest.raises(InputError, match="same factors"):
        pairs_differing_in_one_factor([{"encoder": "raw"}, {"encoder": "raw", "L": 5}])
