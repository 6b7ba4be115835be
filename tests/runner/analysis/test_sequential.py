"""tactbench.runner.analysis.sequential: boundaries against a simulation of the canonical joint
distribution, and the whole procedure's family-wise error and power with overlapping runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactbench.errors import InputError
from tactbench.runner.analysis.sequential import (
    FamilyState,
    boundaries,
    family_look,
    fractions,
    look,
    procedure,
    spent,
)

LOOKS = [5, 8, 12, 16, 20]
RATIO = 0.25


def test_boundaries_spend_alpha_as_the_spending_function_says():
    """An independent simulation (another seed) of the corrected t with overlapping runs
    stops at each look the share of paths the spending function gives."""
    b = np.array(boundaries(LOOKS, LOOKS[-1], RATIO, 0.05))
    rng = np.random.default_rng(1)
    n, rho = 200_000, RATIO / (1 + RATIO)
    d = rng.normal(0, math.sqrt(rho), (n, 1)) + rng.normal(0, math.sqrt(1 - rho), (n, 20))
    t = np.stack([d[:, :j].mean(1) / np.sqrt((1 / j + RATIO) * d[:, :j].var(1, ddof=1))
                  for j in LOOKS], axis=1)
    crossed = np.abs(t) >= b
    first = np.where(crossed.any(axis=1), crossed.argmax(axis=1), -1)
    expected = np.diff([0.0, *(spent(f, 0.05) for f in fractions(LOOKS, 20, RATIO))])
    mc = 4 * np.sqrt(expected / n) + 1e-4
    assert np.all(np.abs([(first == k).mean() for k in range(len(LOOKS))] - expected) <= mc)
    assert b[0] > b[-1] > 1.96  # O'Brien–Fleming type: strict early, a t beyond z last


def test_one_look_is_the_fixed_design():
    """One look spends all of α: the corrected t's own two-sided critical value."""
    from scipy import stats

    (b,) = boundaries([10], 10, RATIO, 0.05)
    assert b == pytest.approx(stats.t.ppf(0.975, 9), rel=0.01)
    with pytest.raises(InputError, match="increasing"):
        boundaries([8, 5], 10, RATIO, 0.05)


def _run_family(rng, sims, deltas, sd=0.03, margin=None):
    """The whole procedure on simulated families of overlapping runs: each comparison's
    runs share a component with ρ = ratio / (1 + ratio). Returns the decisions."""
    rho = RATIO / (1 + RATIO)
    out = []
    for _ in range(sims):
        d = {f"c{i}": delta + rng.normal(0, sd * math.sqrt(rho))
             + rng.normal(0, sd * math.sqrt(1 - rho), LOOKS[-1])
             for i, delta in enumerate(deltas)}
        state = FamilyState(0.05, list(d))
        for k, j in enumerate(LOOKS):
            family_look(state, {n: v[:j] for n, v in d.items()}, dict.fromkeys(d, RATIO),
                        looks=LOOKS[:k + 1], max_runs=LOOKS[-1], margin=margin)
            if len(state.closed) == len(d):
                break
        out.append({n: state.closed[n].decision if n in state.closed else "open" for n in d})
    return out


def test_family_wise_error_stays_at_alpha_under_no_difference():
    rng = np.random.default_rng(7)
    sims = 3000
    decisions = _run_family(rng, sims, [0.0, 0.0])
    false = np.mean([any(v in ("A better", "B better") for v in d.values()) for d in decisions])
    assert false <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / sims)


def test_a_five_point_difference_is_found_near_the_fixed_designs_power():
    """+5 points (per-run sd 3): the sequential family finds it about as often as a fixed
    design of the full 20 runs at the same α share would, and the null comparison beside
    it ends futile or open."""
    from tactbench.runner.analysis.power import power

    rng = np.random.default_rng(8)
    decisions = _run_family(rng, 400, [0.05, 0.0])
    found = np.mean([d["c0"] == "B better" for d in decisions])
    fixed = power(0.05, 0.03 * math.sqrt(1 / (1 + RATIO)), RATIO, LOOKS[-1], alpha=0.025)
    assert found >= fixed - 0.08, (found, fixed)
    assert np.mean([d["c1"] in ("futile", "open") for d in decisions]) >= 0.85


def test_equivalence_is_declared_within_a_margin():
    rng = np.random.default_rng(9)
    decisions = _run_family(rng, 200, [0.0], sd=0.01, margin=0.03)
    assert np.mean([d["c0"] == "equivalent" for d in decisions]) >= 0.8


def test_a_look_says_why_it_stops():
    d = np.array([0.01, -0.02, 0.015, 0.0, -0.01, 0.02, -0.015, 0.005])
    res = look(d, RATIO, looks=[5, 8], max_runs=8, alpha=0.05)
    assert res.decision == "futile" and "last planned look" in res.why
    strong = look(np.full(6, 0.1) + np.arange(6) * 1e-3, RATIO, looks=[6], max_runs=20,
                  alpha=0.05)
    assert strong.decision == "B better" and strong.t > strong.boundary
    with pytest.raises(InputError, match="last look"):
        look(d, RATIO, looks=[5], max_runs=8, alpha=0.05)


def test_a_ceiling_stops_at_its_first_look_instead_of_running_to_the_budget():
    # both models right on every recording of every run: the difference is 0 in each run,
    # nothing varies, and more runs cannot decide it (stopping without a verdict spends no α)
    res = look(np.zeros(5), RATIO, looks=[5], max_runs=20, alpha=0.05, margin=0.02)
    assert res.decision == "futile" and "ceiling" in res.why
    state = FamilyState(0.05, ["ceiling", "open"])
    seen = family_look(state, {"ceiling": np.zeros(5),
                               "open": np.array([0.03, 0.01, 0.05, 0.02, 0.04])},
                       {"ceiling": RATIO, "open": RATIO}, looks=[5], max_runs=20)
    assert seen["ceiling"].decision == "futile" and "ceiling" in state.closed
    assert seen["open"].decision == "continue" and "open" not in state.closed


def test_the_first_looks_boundary_is_the_t_quantile_of_its_spent_alpha():
    """Under no difference the corrected t at the first look is exactly t(J − 1), so its
    boundary is that quantile — finite at an α a simulation cannot place (it gave ∞)."""
    from scipy import stats

    for alpha in (0.05, 0.0125, 1e-4):
        b = boundaries([5, 10], 10, RATIO, alpha)
        share = spent(fractions([5, 10], 10, RATIO)[0], alpha)
        assert b[0] == pytest.approx(float(stats.t.isf(share / 2, 4)), rel=1e-12)
        assert math.isfinite(b[0]) and b[0] > b[1]


def test_procedure_at_one_look_is_the_fixed_designs_exact_power():
    from tactbench.runner.analysis.power import detectable_effect, power

    sd = 0.03
    effect = detectable_effect(sd, RATIO, 10, alpha=0.025)
    one = procedure(effect, sd, RATIO, [10], alpha=0.025)
    assert one.power == pytest.approx(power(effect, sd, RATIO, 10, alpha=0.025),
                                      abs=4 * one.mc_error)
    assert one.expected_runs == 10 and one.futile == pytest.approx(1 - one.power, abs=1e-3)


def test_procedure_says_what_looking_costs_and_keeps_its_level():
    """At the effect a fixed design of all the runs finds with 80 % power, the sequential
    procedure finds it less often and stops earlier on average; under no difference it
    declares a difference in at most α of its paths (plus simulation error)."""
    from tactbench.runner.analysis.power import detectable_effect

    sd = 0.03
    effect = detectable_effect(sd, RATIO, 20, alpha=0.025)
    seq = procedure(effect, sd, RATIO, LOOKS, alpha=0.025)
    assert 0.6 < seq.power < 0.8 + 4 * seq.mc_error
    assert seq.expected_runs < 20 and seq.max_runs == 20
    null = procedure(0.0, sd, RATIO, LOOKS, alpha=0.025)
    assert null.power + null.wrong_side <= 0.025 + 4 * math.sqrt(0.025 / null.paths)
    inside = procedure(0.005, 0.01, RATIO, LOOKS, alpha=0.05, margin=0.02)
    assert inside.equivalent > inside.power


def test_a_question_no_number_of_runs_can_decide_stops_at_its_first_look():
    """A difference far below what 10 runs could resolve, on a wide spread: futile at the
    first look (no α spent), saying what data would help, where it used to run on."""
    d = np.array([0.004, -0.05, 0.06, -0.03, 0.025])
    res = look(d, 1.0, looks=[5], max_runs=10, alpha=0.025)
    assert res.decision == "futile"
    assert "no number of runs up to 10" in res.why and "recordings" in res.why


# ------------------------------------------------------------------ futility (issue 48)


def test_futility_uses_the_t_at_the_looks_degrees_of_freedom():
    """The runs to come move the mean by s·sqrt(1/J − 1/J_max)·T_{J−1} (not z = 1.96,
    an 88 % interval at 4 degrees of freedom), and the boundary at the last look is
    scaled by the spread's lower chi-square limit on J − 1 degrees of freedom."""
    from scipy import stats

    from tactbench.runner.analysis.sequential import (FUTILITY_LEVEL, SPREAD_LEVEL,
                                                      favourable_sd, futility_reach)

    assert float(futility_reach(4.0, 5, 20)) == pytest.approx(
        2 * stats.t.isf(FUTILITY_LEVEL, 4) * math.sqrt(1 / 5 - 1 / 20), rel=1e-12)
    assert float(futility_reach(4.0, 20, 20)) == 0.0  # nothing left to come
    assert float(favourable_sd(4.0, 5)) == pytest.approx(
        2 * math.sqrt(4 / stats.chi2.isf(SPREAD_LEVEL, 4)), rel=1e-12)


def test_the_recordings_a_futile_look_names_are_where_it_would_go_on():
    """Under the rule's own model (spread ∝ 1/√recordings), the multiple of the test
    recordings the note gives is where the same look stops being futile."""
    from tactbench.runner.analysis.sequential import recordings_to_reach

    d = np.array([0.004, -0.05, 0.06, -0.03, 0.025])
    res = look(d, 1.0, looks=[5], max_runs=10, alpha=0.025)
    assert res.decision == "futile"
    said = float(res.why.split("about ")[1].split("×")[0])
    k = recordings_to_reach(d.mean(), *_reach_and_needed(d, 1.0, 10, 0.025), None)
    assert said == pytest.approx(k, abs=0.05)
    for factor, decision in ((0.98, "futile"), (1.02, "continue")):
        scaled = d.mean() + (d - d.mean()) / math.sqrt(k * factor)
        assert look(scaled, 1.0, looks=[5], max_runs=10, alpha=0.025).decision == decision


def _reach_and_needed(d, ratio, max_runs, alpha):
    from tactbench.runner.analysis.sequential import _bounds, favourable_sd, futility_reach

    var = float(np.var(d, ddof=1))
    _, c_last = _bounds([len(d)], max_runs, ratio, alpha)
    return (float(futility_reach(var, len(d), max_runs)),
            math.sqrt(1 / max_runs + ratio) * float(favourable_sd(var, len(d))) * c_last)


def test_futility_stops_a_powerless_design_early_and_rarely_gives_up_an_answer():
    """Same paths with futility on and off (1500 each, looks 5 and 20, overlap 0.8 as on
    a small real data set, a family's α/3): with no difference most paths stop at the
    first look; with a difference a fixed design of 20 runs finds 80 % of the time, at
    most 1 % of paths (+3 Monte Carlo standard errors) stop futile where a later look
    would have decided. The benchmark measures both over many scenes."""
    from tactbench.runner.analysis.power import detectable_effect
    from tactbench.runner.analysis.sequential import (DECIDED_CODES, OUTCOMES_FUTILE,
                                                      simulate_paths)

    looks, sd, ratio, alpha, n = [5, 20], 0.03, 0.8, 0.05 / 3, 1500
    code, stop = simulate_paths(0.0, sd, ratio, looks, alpha=alpha, paths=n, seed=3)
    assert np.mean(np.isin(code, OUTCOMES_FUTILE) & (stop == 5)) >= 0.75
    effect = detectable_effect(sd, ratio, 20, alpha=alpha)
    on = simulate_paths(effect, sd, ratio, looks, alpha=alpha, paths=n, seed=3)
    off = simulate_paths(effect, sd, ratio, looks, alpha=alpha, paths=n, seed=3,
                         futility=False)
    given_up = np.isin(on[0], OUTCOMES_FUTILE) & (on[1] < 20) & np.isin(off[0], DECIDED_CODES)
    assert given_up.mean() <= 0.01 + 3 * math.sqrt(0.01 * 0.99 / n)


def test_alpha_passes_to_every_hypothesis_not_rejected_holm_over_what_remains():
    """Three primaries: one closed futile at the first look, one declared better at the
    second: its α/3 passes half to the open one and half to the futile one (kept
    unused), so the open one tests at α/2 — Holm's level with one of three rejected —
    not at 2α/3."""
    from tactbench.runner.analysis.sequential import Look

    state = FamilyState(0.05, ["better", "futile", "open"])
    state.closed["futile"] = Look(5, 0.0, 0.01, 0.0, 4.0, 0.05 / 3, "futile")
    rng = np.random.default_rng(0)
    diffs = {"better": 0.10 + 0.01 * rng.standard_normal(10),
             "futile": np.zeros(10),
             "open": 0.005 + 0.03 * rng.standard_normal(10)}
    seen = family_look(state, diffs, dict.fromkeys(diffs, RATIO), looks=[5, 10],
                       max_runs=20)
    assert seen["better"].decision == "B better" and "futile" not in seen
    assert state.shares["open"] == pytest.approx(0.05 / 2)
    assert state.shares["futile"] == pytest.approx(0.05 / 2)  # kept, never used
    assert seen["open"].alpha == pytest.approx(0.05 / 2)  # looked at again at α/2


def test_the_minimum_of_evidence_holds_at_every_look_as_in_a_fixed_design():
    """A difference every run agrees on, on 3 discordant recordings: a fixed design gives
    no verdict below 10 (statistics.verdict), and neither does a look — it goes on, and
    at the last look stops without one, saying why."""
    from tactbench.runner.analysis.statistics import MIN_DISCORDANT_RECORDINGS, verdict

    d = np.array([0.02, 0.021, 0.019, 0.02, 0.02, 0.022, 0.018, 0.02, 0.021, 0.019])
    assert verdict(0.01, 0.03, 0.001, 10, discordant_recordings=3)[0] == "unresolved"
    for looks, said in (([5, 10], "continue"), ([5, 10, 20], "futile")):
        state = FamilyState(0.05, ["q"])
        runs = np.resize(d, looks[-1])
        free = family_look(FamilyState(0.05, ["q"]), {"q": runs}, {"q": RATIO},
                           looks=looks, max_runs=20)
        assert free["q"].decision == "B better"  # without the minimum: decided
        seen = family_look(state, {"q": runs}, {"q": RATIO}, looks=looks, max_runs=20,
                           discordant={"q": 3})
        assert seen["q"].decision == said and "disagree on 3 distinct" in seen["q"].why
        assert f"no verdict below {MIN_DISCORDANT_RECORDINGS}" in seen["q"].why
    ok = family_look(FamilyState(0.05, ["q"]), {"q": d}, {"q": RATIO}, looks=[5, 10],
                     max_runs=20, discordant={"q": MIN_DISCORDANT_RECORDINGS})
    assert ok["q"].decision == "B better"


def test_plans_cannot_be_answered_is_the_looks_futile_stop():
    """plan's "cannot be answered within the maximum" (unanswerable) and the look's
    futile stop are one rule (out_of_reach): a first look that sees exactly the planned
    difference and spread stops futile exactly where plan says so — on both sides of
    the edge, with and without a margin."""
    import numpy as np

    from tactbench.runner.analysis.forecast import _primary
    from tactbench.runner.analysis.sequential import FUTILE, look, unanswerable

    z = np.array([-1.2, -0.4, 0.1, 0.5, 1.0])
    z = (z - z.mean()) / z.std(ddof=1)  # mean 0, sample variance 1 exactly
    seen = set()
    for effect in np.linspace(0.0, 0.05, 26):
        for margin in (None, 0.02):
            said = unanswerable(effect, 0.03, 0.25, [5, 10, 15, 20], alpha=0.05 / 3,
                                margin=margin)
            got = look(effect + 0.03 * z, 0.25, looks=[5], max_runs=20, alpha=0.05 / 3,
                       margin=margin).decision
            assert said == (got == FUTILE), (effect, margin, got)
            seen.add(said)
    assert seen == {True, False}
    f = _primary("q", None, 20, 0.01, 0.25, 400, 0.05 / 3, 1600, looks=[5, 10, 15, 20],
                 n_train=1200)
    assert f.unanswerable and any("cannot be answered within 20 runs" in w
                                  for w in f.warnings)
