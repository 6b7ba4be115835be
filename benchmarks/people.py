"""Do simulated people differ like real ones? Two measurements on the simulator.

    python benchmarks/people.py [--dataset synthetic-forearm] [--encoders raw farneback]
        [--classifier logreg] [-L 5] [--seeds 0-4] [--test-window onset]
        [--json docs/people.json] [--md docs/people.md] [--work DIR]

1. **Leaving people out costs accuracy.** Two K-fold designs test every recording once
   per seed: ``users:folds=5`` (each fold's people are unseen in training) and
   ``group:repetition:folds=5`` (each fold holds out one repetition of every person,
   gesture and position: the test people are seen, with their other repetitions, as in a
   random split). Per seed and users fold, the difference users − seen is taken on the
   *same* test recordings (that fold's people; under the seen design they were predicted
   by the repetition folds' models), so which people happen to be tested cancels out of
   it. The ``K · r`` fold differences of ``r`` seeds go into Bouckaert and Frank's
   corrected repeated K-fold t (PAKDD 2004): variance ``(1/(K r) + 1/(K − 1)) · S²``, t
   with ``K r − 1`` degrees of freedom (``scipy.stats.t``). An earlier design compared the
   ``paper`` split (150 random test recordings) with ``users`` (a fifth of the people);
   its two test sets differ, and the correction's floor ``n_test/n_train · S²`` on those
   noisy differences kept gaps of 5–10 points unresolved however many seeds ran.
2. **Accuracy differs between people beyond binomial noise.** The ``users:folds=5`` run
   at the first seed (every person tested once, by a model that never saw them); per
   person, ``k`` of ``n`` test recordings right. The between-person variance of accuracy
   is the method-of-moments variance component ``Var(p̂_i) − mean(p̂_i (1 − p̂_i)/(n_i − 1))``
   (what the spread of per-person accuracy adds to what binomial noise alone would give),
   with a percentile bootstrap interval over people (2000 resamples), and the χ² test of
   homogeneity of the ``k_i / n_i`` (``scipy.stats.chi2_contingency``).

The cells run through :func:`tactbench.runner.run` (the same code as ``tactbench run``;
the equivalent commands are printed in the markdown). The test window is ``onset`` by
default: version 2's recordings start before contact, so the study's ``first`` window of 5
frames mostly sees no touch at all (``--test-window first`` measures that). Nothing here is
tuned: the simulator's distributions are set in ``tactbench/datasets/people.py`` from the
sources in ``docs/simulator.md``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from tactbench.machine import benchmark_meta  # noqa: E402
from tactbench.runner import corrected_t, parse_seeds  # noqa: E402

from typing import Sequence  # noqa: E402

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
CONFIDENCE = 0.95
BOOTSTRAP = 2000


# ------------------------------------------------------------------- statistics


def corrected_t_interval(differences: Sequence[float], test_train_ratio: float,
                         confidence: float = CONFIDENCE) -> dict:
    """Nadeau–Bengio corrected resampled t over ``J`` paired run-level differences:
    mean, interval and two-sided p. ``test_train_ratio`` is ``n_test / n_train``."""
    j = len(differences)
    if j < 2:
        raise ValueError("a corrected t interval needs ≥ 2 runs")
    res = corrected_t(np.asarray(differences, dtype=float), float(test_train_ratio),
                      confidence=confidence)  # the package's test, one definition
    return {"mean": float(res["mean"]), "low": float(res["low"]), "high": float(res["high"]),
            "p": float(res["p"]), "runs": j, "test_train_ratio": float(test_train_ratio),
            "confidence": confidence}


def corrected_kfold_interval(differences: Sequence[float], folds: int,
                             confidence: float = CONFIDENCE) -> dict:
    """Bouckaert–Frank corrected repeated K-fold t over ``K · r`` fold differences: the
    corrected resampled t with ``n_test/n_train = 1/(K − 1)``."""
    out = corrected_t_interval(differences, 1.0 / (folds - 1), confidence)
    out["folds"] = int(folds)
    return out


def paired_fold_differences(users_pred: dict, seen_pred: dict, folds: list) -> list[float]:
    """Per users fold: accuracy under the users design − under the seen design, both on
    that fold's test recordings. ``*_pred`` are a cell's ``test_predictions``."""
    def correct(pred: dict) -> dict[int, bool]:
        return {int(i): bool(t == p) for i, t, p in
                zip(pred["indices"], pred["labels"], pred["predictions"])}

    u, s = correct(users_pred), correct(seen_pred)
    if set(u) != set(s):
        raise SystemExit("the two K-fold designs did not test the same recordings")
    return [float(np.mean([u[int(i)] for i in f.test]) - np.mean([s[int(i)] for i in f.test]))
            for f in folds]


def _variance_component(k: np.ndarray, n: np.ndarray) -> float:
    p = k / n
    return float(p.var(ddof=1) - np.mean(p * (1 - p) / np.maximum(n - 1, 1)))


def between_person_variance(correct: Sequence[bool], people: Sequence[str], *,
                            seed: int = 0, confidence: float = CONFIDENCE,
                            resamples: int = BOOTSTRAP) -> dict:
    """How much accuracy varies between people beyond binomial noise: the variance
    component (method of moments), its bootstrap interval over people, its square root in
    accuracy points, the observed spread, and the χ² homogeneity test's p."""
    from scipy.stats import chi2_contingency

    correct = np.asarray(correct, dtype=bool)
    people = np.asarray([str(p) for p in people])
    names = np.unique(people)
    k = np.array([correct[people == u].sum() for u in names], dtype=float)
    n = np.array([(people == u).sum() for u in names], dtype=float)
    estimate = _variance_component(k, n)
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, len(names), (resamples, len(names)))
    boot = np.array([_variance_component(k[i], n[i]) for i in draws])
    lo, hi = np.quantile(boot, [(1 - confidence) / 2, (1 + confidence) / 2])
    table = np.column_stack([k, n - k])
    table = table[:, table.sum(0) > 0]
    p_chi2 = float(chi2_contingency(table)[1]) if table.shape[1] == 2 else 1.0
    acc = k / n
    return {"people": int(len(names)), "tests_per_person": float(n.mean()),
            "accuracy": float(k.sum() / n.sum()),
            "per_person_sd": float(acc.std(ddof=1)),
            "binomial_sd": float(np.sqrt(np.mean(acc * (1 - acc) / np.maximum(n - 1, 1)))),
            "variance": estimate, "low": float(lo), "high": float(hi),
            "sd_points": 100 * math.sqrt(max(estimate, 0.0)),
            "sd_points_low": 100 * math.sqrt(max(float(lo), 0.0)),
            "sd_points_high": 100 * math.sqrt(max(float(hi), 0.0)),
            "chi2_p": p_chi2, "confidence": confidence,
            "per_person": {str(u): [int(a), int(b)] for u, a, b in zip(names, k, n)}}


# --------------------------------------------------------------------- running


def run_grid(dataset: str, encoders: list[str], classifier: str, length: int,
             seeds: list[int], split: str, test_window: str, work: Path,
             workers: int = 1) -> list[dict]:
    from tactbench.runner import EncodingCache, Scene, run

    scene = Scene(dataset=dataset, encoders=encoders, classifiers=[classifier],
                  L=[length], seeds=seeds, split=split, test_window=test_window,
                  threads=1, workers=workers,
                  out=str(work / split.replace(":", "-").replace("=", "")))
    result = run(scene, progress=False, cache=EncodingCache(work / "cache"))
    bad = [r for r in result.rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"{len(bad)} cell(s) failed: {bad[0].get('error')}")
    return result.rows


def command(dataset: str, encoders: list[str], classifier: str, length: int, seeds: str,
            split: str, test_window: str) -> str:
    enc = " ".join(f"--encoder {e}" for e in encoders)
    return (f"tactbench run --dataset {dataset} {enc} --classifier {classifier} -L {length} "
            f"--seed {seeds} --split {split} --test-window {test_window} --threads 1")


#: The two K-fold designs of the gap: people unseen, people seen (one repetition out).
FOLDS = 5
UNSEEN, SEEN = f"users:folds={FOLDS}", f"group:repetition:folds={FOLDS}"


def measure(args: argparse.Namespace, work: Path) -> dict:
    from tactbench.data.splits import user_folds
    from tactbench.datasets.loading import load_dataset

    seeds = parse_seeds(args.seeds.split(","))  # "0-4", "0,2,5" or "0-2,5"
    t0 = time.perf_counter()
    ds = load_dataset(args.dataset)
    users = np.asarray(ds.users)
    labels = np.asarray(ds.labels)
    rows = {split: run_grid(args.dataset, args.encoders, args.classifier, args.length,
                            seeds, split, args.test_window, work, args.workers)
            for split in (UNSEEN, SEEN)}
    out = {"gap": {}, "people": {}, "accuracy": {}}
    for enc in args.encoders:
        cell = {split: {r["seed"]: r for r in rows[split] if r["encoder"] == enc}
                for split in (UNSEEN, SEEN)}
        diffs, per_seed = [], []
        for s in seeds:
            split_seed = int(cell[UNSEEN][s].get("split_seed", s))
            folds = user_folds(users, labels, seed=split_seed, folds=FOLDS)
            d = paired_fold_differences(cell[UNSEEN][s]["test_predictions"],
                                        cell[SEEN][s]["test_predictions"], folds)
            diffs += d
            per_seed.append(cell[UNSEEN][s]["accuracy"] - cell[SEEN][s]["accuracy"])
        gap = corrected_kfold_interval(diffs, FOLDS)
        gap["per_fold"] = diffs
        gap["per_seed"] = per_seed  # every recording, users − seen
        gap["folds_lower"] = int(sum(d < 0 for d in diffs))
        gap["folds_higher"] = int(sum(d > 0 for d in diffs))
        out["gap"][enc] = gap
        out["accuracy"][enc] = {split: float(np.mean([r["accuracy"]
                                                      for r in cell[split].values()]))
                                for split in cell}
        pred = cell[UNSEEN][seeds[0]]["test_predictions"]
        idx = np.asarray(pred["indices"])
        correct = np.asarray(pred["labels"]) == np.asarray(pred["predictions"])
        out["people"][enc] = between_person_variance(correct, users[idx], seed=seeds[0])
    out["wall_s"] = time.perf_counter() - t0
    return out


def markdown(args: argparse.Namespace, res: dict, meta: dict) -> str:
    pct = lambda x: f"{100 * x:+.1f}"  # noqa: E731
    lines = [
        "# Do simulated people differ? (generated)",
        "",
        f"`{meta['command']}` — {meta['machine']}, {meta['date']}, "
        f"{res['wall_s'] / 60:.1f} min wall.",
        "",
        f"Dataset `{args.dataset}`; classifier `{args.classifier}`, L = {args.length}, "
        f"seeds {args.seeds}, test window `{args.test_window}`. The same cells as:",
        "",
        "```bash",
        *(command(args.dataset, args.encoders, args.classifier, args.length, args.seeds, s,
                  args.test_window) for s in (UNSEEN, SEEN)),
        "```",
        "",
        "## Leaving people out (people unseen − seen, paired on the same recordings)",
        "",
        f"`{UNSEEN}` leaves each fold's people out of training; `{SEEN}` leaves one "
        "repetition of every person out, so the test people are seen (as in a random "
        "split). Both test every recording once per seed. Per seed and users fold, the "
        "difference is taken on that fold's recordings under both designs; the interval is "
        "Bouckaert–Frank's corrected repeated K-fold t over the K · seeds fold differences "
        "(n_test/n_train = 1/(K − 1)), computed by this script (`scipy.stats.t`).",
        "",
        "| encoder | people seen | people unseen | unseen − seen (points) | "
        f"{int(100 * CONFIDENCE)} % interval | p | folds lower / higher | "
        "per seed (all recordings) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for enc, g in res["gap"].items():
        a = res["accuracy"][enc]
        lines.append(f"| {enc} | {100 * a[SEEN]:.1f} % | {100 * a[UNSEEN]:.1f} % | "
                     f"{pct(g['mean'])} | [{pct(g['low'])}, {pct(g['high'])}] | "
                     f"{g['p']:.2g} | {g['folds_lower']} / {g['folds_higher']} | "
                     + ", ".join(pct(d) for d in g["per_seed"]) + " |")
    lines += [
        "",
        f"## Accuracy per person ({UNSEEN}, first seed)",
        "",
        "Variance component between people (method of moments, beyond binomial noise) with "
        "a percentile bootstrap interval over people; χ² test of homogeneity.",
        "",
        "| encoder | people | tests each | accuracy | sd of per-person accuracy | of which "
        "binomial noise | between-person sd (points) | interval | χ² p |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for enc, v in res["people"].items():
        lines.append(f"| {enc} | {v['people']} | {v['tests_per_person']:.0f} | "
                     f"{100 * v['accuracy']:.1f} % | {100 * v['per_person_sd']:.1f} | "
                     f"{100 * v['binomial_sd']:.1f} | {v['sd_points']:.1f} | "
                     f"[{v['sd_points_low']:.1f}, {v['sd_points_high']:.1f}] | "
                     f"{v['chi2_p']:.2g} |")
    lines += ["", "Regenerate with the command above; numbers in "
              f"[{Path(args.json).name}]({Path(args.json).name}).", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", default="synthetic-forearm:version=2")
    ap.add_argument("--encoders", nargs="+", default=["raw", "farneback"])
    ap.add_argument("--classifier", default="logreg")
    ap.add_argument("-L", "--length", type=int, default=5)
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--test-window", default="onset", choices=["first", "onset", "vote"])
    ap.add_argument("--json", default=str(REPO / "docs" / "people.json"))
    ap.add_argument("--md", default=str(REPO / "docs" / "people.md"))
    ap.add_argument("--workers", type=int, default=1,
                    help="cells in parallel, one torch thread each (the runner's --workers)")
    ap.add_argument("--work", help="folder for the runs (default: a temporary one)")
    args = ap.parse_args(argv)
    meta = benchmark_meta("benchmarks/people.py", argv if argv is not None else sys.argv[1:])
    if args.work:
        res = measure(args, Path(args.work))
    else:
        with tempfile.TemporaryDirectory(prefix="tactbench-people-") as tmp:
            res = measure(args, Path(tmp))
    from tactbench.paths import atomic_write_text

    doc = {**meta, "options": vars(args) | {"json": None, "md": None, "work": None}, **res}
    atomic_write_text(Path(args.json), json.dumps(doc, indent=1) + "\n")
    atomic_write_text(Path(args.md), markdown(args, res, meta))
    for enc, g in res["gap"].items():
        print(f"{enc}: people unseen − seen {100 * g['mean']:+.1f} points "
              f"[{100 * g['low']:+.1f}, {100 * g['high']:+.1f}]")
        v = res["people"].get(enc)
        if v:
            print(f"  between-person sd {v['sd_points']:.1f} points [{v['sd_points_low']:.1f}, "
                  f"{v['sd_points_high']:.1f}], χ² p {v['chi2_p']:.2g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
