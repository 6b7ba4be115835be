"""tactbench.runner.statistics against independent computations, simulations and degenerate
inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactbench.errors import InputError
from tactbench.runner.statistics import (
    paired_difference,
    pairs_differing_in_one_factor,
    seed_summary,
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


# ------------------------------------------------------------------- paired_difference


def _rows(outcomes: list[tuple[bool, bool]], seed_of_row=None):
    """y_true, pred_a, pred_b, groups from (A right, B right) per row (3 classes)."""
    y = np.arange(len(outcomes)) % 3
    a = np.where([o[0] for o in outcomes], y, (y + 1) % 3)
    b = np.where([o[1] for o in outcomes], y, (y + 2) % 3)
    g = np.zeros(len(outcomes), int) if seed_of_row is None else np.asarray(seed_of_row)
    return y, a, b, g


def test_mcnemar_p_is_the_exact_binomial_enumerated_by_hand():
    # 2 rows only A got right, 8 only B, 5 both, 3 neither.
    outcomes = [(True, False)] * 2 + [(False, True)] * 8 + [(True, True)] * 5 \
        + [(False, False)] * 3
    r = paired_difference(*_rows(outcomes), n_resamples=200)
    # two-sided: 2 · P(X ≤ 2), X ~ Binomial(10, 1/2)
    expected = 2 * sum(math.comb(10, k) for k in range(3)) / 2 ** 10
    assert (r.a_only, r.b_only) == (2, 8)
    assert r.mcnemar_p == pytest.approx(expected)  # 0.109375
    balanced = paired_difference(*_rows([(True, False)] * 3 + [(False, True)] * 3),
                                 n_resamples=200)
    assert balanced.mcnemar_p == pytest.approx(1.0)


def test_difference_is_averaged_over_seeds_and_signs_are_counted():
    # seed 7: 4 rows, B +2 over A; seed 3: 2 rows, A +1; seed 9: 3 rows, tie.
    outcomes = ([(False, True)] * 2 + [(True, True)] * 2 + [(True, False), (False, False)]
                + [(True, True), (False, False), (True, True)])
    seeds = [7] * 4 + [3] * 2 + [9] * 3
    r = paired_difference(*_rows(outcomes, seeds), n_resamples=500)
    per_seed = {"7": 2 / 4, "3": -1 / 2, "9": 0.0}
    assert r.per_seed == pytest.approx(per_seed)
    assert r.difference == pytest.approx(np.mean(list(per_seed.values())))
    assert r.accuracy_a == pytest.approx(np.mean([2 / 4, 1 / 2, 2 / 3]))
    assert r.accuracy_b == pytest.approx(np.mean([4 / 4, 0 / 2, 2 / 3]))
    assert (r.b_better_seeds, r.a_better_seeds, r.tied_seeds) == (1, 1, 1)
    assert r.seeds == 3 and r.sequences == 9 and r.resampling == "within each seed"
    assert r.low <= r.difference <= r.high


def test_the_bootstrap_is_deterministic_given_its_seed():
    rng = np.random.default_rng(1)
    outcomes = [tuple(x) for x in rng.random((60, 2)) < [0.6, 0.7]]
    args = _rows(outcomes, np.repeat([0, 1, 2], 20))
    first = paired_difference(*args, seed=4, n_resamples=500)
    assert paired_difference(*args, seed=4, n_resamples=500) == first
    other = paired_difference(*args, seed=5, n_resamples=500)
    assert (other.low, other.high) != (first.low, first.high)


def test_a_clear_win_is_a_verdict_and_either_way_round():
    outcomes = [(False, True)] * 30 + [(True, True)] * 30
    args = _rows(outcomes, np.repeat([0, 1, 2], 20))
    r = paired_difference(*args, n_resamples=500)
    assert r.verdict == "B better" and r.low > 0 and r.mcnemar_p < 1e-6
    y, a, b, g = args
    swapped = paired_difference(y, b, a, g, n_resamples=500)
    assert swapped.verdict == "A better" and swapped.high < 0
    assert swapped.difference == pytest.approx(-r.difference)


def test_an_interval_spanning_zero_is_unresolved():
    outcomes = [(True, False)] * 3 + [(False, True)] * 4 + [(True, True)] * 13
    r = paired_difference(*_rows(outcomes, np.repeat([0, 1], 10)), n_resamples=1000)
    assert r.low < 0 < r.high and r.verdict == "unresolved"


def _coverage(simulate, true_difference, runs=200, **kw):
    hits = 0
    for k in range(runs):
        y, a, b, g, ids = simulate(np.random.default_rng(1000 + k))
        r = paired_difference(y, a, b, g, sequence_ids=ids, n_resamples=400, seed=k, **kw)
        hits += r.low <= true_difference <= r.high
    return hits / runs


def test_the_interval_covers_the_true_difference_at_about_the_nominal_rate():
    """200 datasets of 3 seeds × 50 fresh test sequences, A right with p = 0.70 and B
    with p = 0.78 independently: the 95 % interval covers 0.08 in ~95 % of them."""
    def simulate(rng):
        n = 150
        y = np.zeros(n, int)
        a = np.where(rng.random(n) < 0.70, 0, 1)
        b = np.where(rng.random(n) < 0.78, 0, 1)
        return y, a, b, np.repeat([0, 1, 2], 50), None

    coverage = _coverage(simulate, 0.08)
    assert 0.89 <= coverage <= 0.99, coverage


def test_shared_test_sequences_are_resampled_jointly_and_still_cover():
    """The same 40 sequences under 3 seeds, each sequence with its own difficulty (so a
    sequence's results agree across seeds): resampling sequences jointly covers the true
    difference at about the nominal rate; resampling each seed alone would not."""
    def simulate(rng):
        m = 40
        hard = rng.random(m) < 0.5  # shared by every seed
        p_a = np.where(hard, 0.1, 0.95)
        p_b = np.where(hard, 0.9, 0.95)
        a = np.concatenate([np.where(rng.random(m) < p_a, 0, 1) for _ in range(3)])
        b = np.concatenate([np.where(rng.random(m) < p_b, 0, 1) for _ in range(3)])
        ids = np.tile(np.arange(m), 3)
        return np.zeros(3 * m, int), a, b, np.repeat([0, 1, 2], m), ids

    # true difference: P(hard) · (0.9 − 0.1) = 0.4
    joint = _coverage(simulate, 0.4)
    r = paired_difference(*simulate(np.random.default_rng(0))[:4],
                          sequence_ids=simulate(np.random.default_rng(0))[4])
    assert r.resampling == "sequences jointly across seeds"
    assert 0.89 <= joint <= 0.99, joint
    alone = _coverage(lambda rng: (*simulate(rng)[:4], None), 0.4)
    assert alone < 0.9 < joint  # each seed alone: ~0.83 in theory


def test_a_handful_of_sequences_gives_an_interval_but_no_verdict():
    outcomes = [(False, True)] * 9  # B right on all 9, A on none: the interval is [1, 1]
    few = paired_difference(*_rows(outcomes), n_resamples=200)
    assert few.low == few.high == 1.0 and few.verdict == "unresolved"
    assert "9 test sequences: no verdict" in few.note
    ten = paired_difference(*_rows(outcomes + [(False, True)]), n_resamples=200)
    assert ten.verdict == "B better" and ten.note == ""


def test_all_predictions_agreeing_give_a_zero_difference_and_p_1():
    y = np.arange(12) % 3
    r = paired_difference(y, y, y, np.repeat([0, 1], 6))
    assert (r.difference, r.low, r.high, r.mcnemar_p) == (0, 0, 0, 1.0)
    assert r.verdict == "unresolved" and r.tied_seeds == 2
    wrong = (y + 1) % 3  # both always wrong: still no discordant pair
    assert paired_difference(y, wrong, wrong, np.zeros(12)).mcnemar_p == 1.0


def test_one_seed_and_a_seed_with_one_sequence_work():
    rng = np.random.default_rng(3)
    outcomes = [tuple(x) for x in rng.random((30, 2)) < [0.5, 0.8]]
    one = paired_difference(*_rows(outcomes), n_resamples=300)
    assert one.seeds == 1 and one.low <= one.difference <= one.high
    seeds = [0] * 29 + [1]  # seed 1 tested a single sequence
    mixed = paired_difference(*_rows(outcomes, seeds), n_resamples=300)
    assert mixed.seeds == 2 and mixed.low <= mixed.difference <= mixed.high
    singles = paired_difference(*_rows(outcomes[:5], range(5)), n_resamples=300)
    assert singles.seeds == 5 and singles.low < singles.high  # resampled over the seeds


def test_one_sequence_gives_no_interval():
    r = paired_difference([0], [1], [0], [0])
    assert (r.difference, r.low, r.high, r.verdict) == (1.0, -1.0, 1.0, "unresolved")
    assert "one test sequence" in r.note


def test_labels_may_be_text():
    y = np.array(["tap", "pull", "tap", "grasp"] * 5)
    a = np.array(["tap", "tap", "tap", "grasp"] * 5)
    r = paired_difference(y, a, y, np.zeros(20), n_resamples=200)
    assert r.difference == pytest.approx(0.25) and r.b_only == 5


@pytest.mark.parametrize("args, match", [
    (([0, 1], [0], [0, 1], [0, 0]), "pred_a has 1 rows"),
    (([[0, 1]], [[0, 1]], [[0, 1]], [[0, 0]]), "1-D"),
    (([], [], [], []), "at least one"),
])
def test_bad_inputs_are_one_line(args, match):
    with pytest.raises(InputError, match=match):
        paired_difference(*args)


def test_too_few_resamples_are_refused():
    with pytest.raises(InputError, match="n_resamples"):
        paired_difference([0, 1], [0, 1], [1, 1], [0, 0], n_resamples=10)


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
