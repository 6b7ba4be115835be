"""Error rates of tactbench's verdict rules, by simulation (issue 48).

    python benchmarks/statistics_checks.py [--part learned] [--reps 4000]
        [--out docs/benchmarks/statistics-checks.json]

Each part simulates the rule the package applies (its own functions, not a copy) and
writes its rates with their Monte Carlo standard errors into the JSON file (other parts'
entries are kept), with the command, the machine and the date:

- ``futility``: the sequential looks' futility rule
  (:func:`tactbench.runner.analysis.sequential.simulate_paths`, the paths ``tactbench
  plan`` forecasts with), each scene's paths run with futility on and off: how often it
  stops at the first look, and how often it gives up on a path that, continued, a later
  look would have decided (better, worse or equivalent).
- ``alpha``: the family-wise error of a family of 3 or 4 primaries when α passes on
  after a rejection (Holm over what remains, futility on and off), with 0 to m − 1 of
  them carrying a real difference.
- ``family``: a primary family's chance of every comparison being answered, the run's
  own procedure path by path (cells drawn, differences taken, ``family_look`` or the
  fixed design's Holm) against ``tactbench plan``'s forecast
  (:func:`tactbench.runner.analysis.family_paths.family_forecast`) and the product of
  independent comparisons it printed before.
- ``futility-curve``: the futility rule's trade-off curve, its predictive and spread
  levels against the share of powerless paths stopped at the first look and the
  largest share of decidable paths given up.
- ``disagreement``: the per-run disagreement of the stored reports' primary
  comparisons (no simulation), beside the no-pilot assumption of ``tactbench plan``.
- ``learned``: "not learned" (:func:`tactbench.runner.execution.learning.cell_learning`'s
  pooled test over a cell's runs) against the rule before it (any one run within noise of
  chance). A cell of J runs (5, 10, 20), 150 or 400 balanced test recordings of 5 classes
  per run (guessing 20 %); each run's true accuracy is chance + the effect + a normal
  training spread (1 point: with it one run of a model 10 points above chance fails the
  one-run test in about 12 % of runs, as the issue measured), its right answers a
  binomial draw. Rates: the share of cells marked not learned.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "docs" / "benchmarks" / "statistics-checks.json"
#: The training spread of a run's accuracy (fraction) in the "learned" part.
LEARN_SPREAD = 0.01


def _rate(hits: np.ndarray) -> dict[str, float]:
    p = float(np.mean(hits))
    return {"rate": round(p, 4), "mc_se": round(float(np.sqrt(p * (1 - p) / hits.size)), 4)}


def learned_part(reps: int, seed: int = 0) -> dict:
    """Marked-not-learned rates of the pooled rule and the one-run rule it replaces."""
    from tactbench.runner import pooled_p, within_noise

    rng = np.random.default_rng(seed)
    chance, out = 0.2, []
    for n in (150, 400):
        for effect in (0.0, 0.08, 0.10, 0.15):
            for runs in (1, 5, 10, 20):
                acc = np.clip(chance + effect + (LEARN_SPREAD if effect else 0.0)
                              * rng.standard_normal((reps, runs)), 0, 1)
                right = rng.binomial(n, acc)
                pooled = np.array([pooled_p([(n, int(r), chance) for r in line]) > 0.05
                                   for line in right])
                one_run = np.array([any(within_noise(r / n, chance, n) for r in line)
                                    for line in right])
                out.append({"test_recordings": n, "effect_points": round(100 * effect),
                            "runs": runs, "pooled_rule": _rate(pooled),
                            "any_run_rule": _rate(one_run)})
    return {"what": "share of cells marked not learned (5 classes, guessing 20 %); "
                    f"training spread {100 * LEARN_SPREAD:.1f} points for a model above chance",
            "reps": reps, "results": out}


#: Looks of the futility part (runs), a spread of the per-run difference (fraction).
LOOKS, SD = (5, 10, 15, 20), 0.03


def _futility_scene(effect: float, ratio: float, alpha: float, margin: float | None,
                    paths: int) -> dict:
    """One scene's rates: the same simulated paths with futility on and off."""
    from tactbench.runner import DECIDED_CODES, OUTCOMES_FUTILE, power, simulate_paths

    on = simulate_paths(effect, SD, ratio, LOOKS, alpha=alpha, margin=margin, paths=paths,
                        seed=11)
    off = simulate_paths(effect, SD, ratio, LOOKS, alpha=alpha, margin=margin, paths=paths,
                         seed=11, futility=False)
    futile_early = np.isin(on[0], OUTCOMES_FUTILE) & (on[1] < LOOKS[-1])
    decided_off = np.isin(off[0], DECIDED_CODES)
    given_up = futile_early & decided_off
    return {"effect_points": round(100 * effect, 3), "ratio": ratio, "alpha": round(alpha, 5),
            "margin_points": None if margin is None else 100 * margin,
            "fixed_power_20": round(power(effect, SD, ratio, LOOKS[-1], alpha=alpha), 4),
            "futile_at_first_look": _rate(futile_early & (on[1] == LOOKS[0])),
            "futile_early": _rate(futile_early),
            "gave_up_on_decided": _rate(given_up),
            "gave_up_share_of_decided": round(float(given_up.sum() / max(1, decided_off.sum())), 4),
            "decided_without_futility": _rate(decided_off),
            "expected_runs": round(float(on[1].mean()), 2)}


def futility_part(reps: int) -> dict:
    """Futility's error rates over scenes: overlap ratios 0.1–0.8, a comparison's level
    (α, α/3, α/4 of 0.05), true differences from none to 95 % fixed-design power."""
    from tactbench.runner import detectable_effect

    out = []
    for ratio in (0.1, 0.25, 0.5, 0.8):
        for alpha in (0.05, 0.05 / 3, 0.05 / 4):
            effects = list(dict.fromkeys(  # at α = 0.05, 5 % power is no difference
                [0.0] + [detectable_effect(SD, ratio, LOOKS[-1], alpha=alpha, target=t)
                         for t in (0.05, 0.2, 0.5, 0.8, 0.95)]))
            for effect in effects:
                out.append(_futility_scene(effect, ratio, alpha, None, reps))
            for effect in (0.0, 0.01):
                out.append(_futility_scene(effect, ratio, alpha, 0.02, reps))
    return {"what": f"futility of the sequential looks {list(LOOKS)}, per-run sd "
                    f"{100 * SD:.0f} points; rates over {reps} simulated paths a scene "
                    "(futility on and off on the same paths)",
            "paths": reps, "scenes": out}


def _family_error(m: int, real: int, families: int, futility: bool, seed: int) -> dict:
    """One family of ``m`` primaries, the first ``real`` with a difference found at 95 %
    power by a fixed design of 20 runs at α/m, the others none: the share of families
    declaring any of the others better or worse (the family-wise error), through the
    package's own looks (:func:`~tactbench.runner.analysis.sequential.family_look`)."""
    from tactbench.runner import A_BETTER, B_BETTER, FamilyState, detectable_effect, family_look

    rng, ratio, alpha = np.random.default_rng(seed), 0.25, 0.05
    effect = detectable_effect(SD, ratio, LOOKS[-1], alpha=alpha / m, target=0.95)
    names = [f"q{i}" for i in range(m)]
    wrong = np.zeros(families, dtype=bool)
    for f in range(families):
        shared = rng.standard_normal(m) * SD * np.sqrt(ratio)
        runs = rng.standard_normal((m, LOOKS[-1])) * SD
        d = {n: (effect if i < real else 0.0) + shared[i] + runs[i] for i, n in enumerate(names)}
        state = FamilyState(alpha, list(names))
        for k, j in enumerate(LOOKS):
            family_look(state, {n: d[n][:j] for n in names}, dict.fromkeys(names, ratio),
                        looks=LOOKS[:k + 1], max_runs=LOOKS[-1], futility=futility)
            if len(state.closed) == m:
                break
        wrong[f] = any(state.closed.get(n) is not None and state.closed[n].decision in
                       (B_BETTER, A_BETTER) for n in names[real:])
    return {"primaries": m, "with_difference": real, "futility": futility,
            "effect_points": round(100 * effect, 2), "family_wise_error": _rate(wrong)}


def alpha_part(reps: int) -> dict:
    """The family-wise error of α passed on after a rejection (Holm over what remains),
    with 3 and 4 primaries, futility on and off on the same draws."""
    out = []
    for m in (3, 4):
        for real in range(m):
            for futility in (True, False):
                out.append(_family_error(m, real, reps, futility, seed=100 * m + real))
    return {"what": f"family-wise error under partial nulls, looks {list(LOOKS)}, per-run sd "
                    f"{100 * SD:.0f} points, overlap 0.25, α 0.05; {reps} families each",
            "families": reps, "results": out}


def disagreement_part(reps: int) -> dict:
    """The share of test recordings the two models of each stored primary comparison
    disagree on, per run (``(a_only + b_only) / (runs · n_test)``, ``n_test`` the runs'
    largest test set, as ``tactbench plan`` reads a pilot's): what the no-pilot
    assumption of 30 % is compared with. ``reps`` is unused (no simulation)."""
    shares = []
    for path in sorted((REPO / "docs" / "reports").glob("*/*/results.json")):
        doc = json.loads(path.read_text())
        n_test = max((r["n_test"] for r in doc["rows"] if r.get("status") == "ok"), default=0)
        for c in doc["comparisons"]:
            if c.get("family") == "primary" and n_test and c["runs"]:
                shares.append({"results": path.relative_to(REPO).as_posix(),
                               "comparison": f"{c['a']} → {c['b']}",
                               "share": round((c["a_only"] + c["b_only"])
                                              / (c["runs"] * n_test), 4)})
    values = [x["share"] for x in shares]
    return {"what": "per-run disagreement of the stored primary comparisons",
            "min": min(values), "max": max(values), "comparisons": shares}


#: The family part's scenes: (name, comparisons as (A, B) cells, the true effect of each
#: (points), a margin, looks or None for a fixed design of FAMILY_FIXED_RUNS runs).
FAMILY_FIXED_RUNS = 10
FAMILY_SCENES = (
    ("raw→frame-diff over 3 classifiers, --until", (("raw1", "fd1"), ("raw2", "fd2"),
                                                  ("raw3", "fd3")), (6.0, 6.0, 6.0), None, LOOKS),
    ("3 encoders against raw, --until", (("raw", "fd"), ("raw", "flow"), ("raw", "far")),
     (6.0, 6.0, 6.0), None, LOOKS),
    ("3 encoders against raw, --until, ±2 margin, one at 0", (("raw", "fd"), ("raw", "flow"),
                                                              ("raw", "far")),
     (0.0, 6.0, 7.0), 2.0, LOOKS),
    ("3 encoders against raw, fixed 10 runs", (("raw", "fd"), ("raw", "flow"),
                                              ("raw", "far")), (7.0, 7.0, 7.0), None, None),
    ("2 encoders against raw, fixed 10 runs, ±2 margin", (("raw", "fd"), ("raw", "flow")),
     (0.0, 7.0), 2.0, None),
)


def _family_scene(name: str, pairs, effects, margin, looks, paths: int, seed: int) -> dict:
    """One family scene through the run's own code, path by path: every *cell*'s
    accuracy drawn (a part every run shares, of variance ``ratio · sd²/2``, and each
    run's own, ``sd²/2``: a difference of two cells has the per-run sd ``SD``), the
    differences taken, and the looks made by ``family_look`` (``--until``) or the
    fixed design's corrected t with Holm and TOST (``comparisons``' rule, via
    ``statistics.verdict``) — a construction of its own, not ``draw_family``; beside it,
    the plan's forecast (``family_paths.family_forecast``, its default paths) and the
    product of the comparisons' own forecasts the plan printed before."""
    from tactbench.runner import (A_BETTER, B_BETTER, EQUIVALENT, FamilyState, corrected_t,
                                  family_forecast, family_look, holm, power, procedure,
                                  tost_p, verdict)

    ratio, alpha, m = 0.25, 0.05, len(pairs)
    cells = sorted({c for pair in pairs for c in pair})
    mu = {c: 0.0 for c in cells}
    for (a, b), e in zip(pairs, effects):
        mu[b] = mu[a] + e / 100
    runs = looks[-1] if looks else FAMILY_FIXED_RUNS
    rng = np.random.default_rng(seed)
    cell_sd = SD / np.sqrt(2)
    answered = np.zeros(paths, dtype=bool)
    names = [f"c{i}" for i in range(m)]
    marg = None if margin is None else margin / 100
    for p in range(paths):
        acc = {c: mu[c] + cell_sd * (np.sqrt(ratio) * rng.standard_normal()
                                     + rng.standard_normal(runs)) for c in cells}
        d = {n: acc[b] - acc[a] for n, (a, b) in zip(names, pairs)}
        if looks:
            state = FamilyState(alpha, names)
            for k, j in enumerate(looks):
                family_look(state, {n: d[n][:j] for n in names}, dict.fromkeys(names, ratio),
                            looks=looks[:k + 1], max_runs=looks[-1], margin=marg)
                if len(state.closed) == m:
                    break
            said = [state.closed[n].decision if n in state.closed else "" for n in names]
        else:
            t = [corrected_t(d[n], ratio) for n in names]
            p_holm = holm([float(x["p"]) for x in t])
            eq = holm([float(tost_p(d[n], ratio, marg)) for n in names]) if marg else [None] * m
            said = [verdict(float(x["low"]), float(x["high"]), float(ph), runs,
                            equivalence_p_adjusted=None if e is None else float(e))[0]
                    for x, ph, e in zip(t, p_holm, eq)]
        answered[p] = all(v in (B_BETTER, A_BETTER, EQUIVALENT) for v in said)
    plan = family_forecast([e / 100 for e in effects], [SD] * m, [ratio] * m, pairs,
                           runs=runs, looks=looks, alpha=alpha, margin=marg)
    product = 1.0
    for e in effects:
        if looks:
            s = procedure(e / 100, SD, ratio, looks, alpha=alpha / m, margin=marg)
            product *= s.power + s.wrong_side + s.equivalent
        else:
            product *= power(e / 100, SD, ratio, runs, alpha=alpha / m)
    return {"scene": name, "pairs": [list(x) for x in pairs], "effects_points": list(effects),
            "margin_points": margin, "looks": list(looks) if looks else None, "runs": runs,
            "sd_points": 100 * SD, "ratio": ratio, "alpha": alpha,
            "answered": _rate(answered), "plan_answered": round(plan.answered, 4),
            "plan_paths": plan.paths, "product_of_each": round(product, 4)}


def family_part(reps: int) -> dict:
    """A primary family's chance of every comparison being answered: the run's own
    procedure path by path (``reps`` paths a scene) against ``tactbench plan``'s
    vectorised forecast of it and the product it printed before (issue 48)."""
    out = [_family_scene(*scene, paths=reps, seed=500 + i)
           for i, scene in enumerate(FAMILY_SCENES)]
    return {"what": f"family answered: run's own looks / fixed Holm, per-run sd "
                    f"{100 * SD:.0f} points, overlap 0.25, α 0.05; {reps} paths a scene",
            "paths": reps, "results": out}


#: The futility rule's parameters the trade-off curve tries: its predictive level (the
#: runs to come land beyond the favourable edge with this chance) and its spread level
#: (the one-sided lower confidence limit of the spread; 0.5 is about the sample spread).
CURVE_REACH = (0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5)
CURVE_SPREAD = (0.2, 0.5)


def futility_curve_part(reps: int) -> dict:
    """The futility rule's trade-off: for each (predictive level, spread level), the
    share of powerless paths (a fixed design of 20 runs has power 2 % or 5 % at the
    comparison's level) stopped futile at the first look (the goal: ≥ 90 %), and the
    largest share over powered scenes (power 20–95 %) of paths given up that a later
    look would have decided (the goal: ≤ 1 %), over overlap ratios 0.1, 0.25, 0.8 and
    levels α and α/3 — the same paths for every parameter, futility off once."""
    from tactbench.runner import DECIDED_CODES, OUTCOMES_FUTILE, detectable_effect, simulate_paths

    scenes = []
    for ratio in (0.1, 0.25, 0.8):
        for alpha in (0.05, 0.05 / 3):
            for target in (0.02, 0.05, 0.2, 0.5, 0.8, 0.95):
                effect = detectable_effect(SD, ratio, LOOKS[-1], alpha=alpha, target=target) \
                    if target > alpha else 0.0
                off = simulate_paths(effect, SD, ratio, LOOKS, alpha=alpha, paths=reps,
                                     seed=11, futility=False)
                scenes.append((ratio, alpha, target, effect, np.isin(off[0], DECIDED_CODES)))
    out = []
    for reach in CURVE_REACH:
        for spread in CURVE_SPREAD:
            first, given = [], []
            for ratio, alpha, target, effect, decided_off in scenes:
                code, stop = simulate_paths(effect, SD, ratio, LOOKS, alpha=alpha,
                                            paths=reps, seed=11, levels=(reach, spread))
                early = np.isin(code, OUTCOMES_FUTILE) & (stop < LOOKS[-1])
                if target <= 0.05:
                    first.append(float(np.mean(early & (stop == LOOKS[0]))))
                else:
                    given.append(float(np.mean(early & decided_off)))
            out.append({"reach_level": reach, "spread_level": spread,
                        "powerless_first_look_min": round(min(first), 4),
                        "powerless_first_look_max": round(max(first), 4),
                        "given_up_max": round(max(given), 4),
                        "meets_both": min(first) >= 0.9 and max(given) <= 0.01})
    return {"what": f"futility trade-off: looks {list(LOOKS)}, per-run sd {100 * SD:.0f} "
                    f"points, ratios 0.1/0.25/0.8, levels α and α/3; {reps} paths a scene",
            "paths": reps, "results": out}


PARTS = {"learned": learned_part, "futility": futility_part, "alpha": alpha_part,
         "disagreement": disagreement_part, "family": family_part,
         "futility-curve": futility_curve_part}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=sorted(PARTS), action="append")
    ap.add_argument("--reps", type=int, default=4000)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    doc = json.loads(args.out.read_text()) if args.out.exists() else {}
    for part in args.part or sorted(PARTS):
        start = time.perf_counter()
        res = PARTS[part](args.reps)
        res.update(command=f"python benchmarks/statistics_checks.py --part {part} "
                           f"--reps {args.reps}",
                   machine=f"{platform.machine()} {platform.processor() or ''}".strip(),
                   date=datetime.now(timezone.utc).strftime("%Y-%m-%d"),
                   seconds=round(time.perf_counter() - start, 1))
        doc[part] = res
        print(json.dumps(res, indent=1))
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
