"""Error rates of tactbench's verdict rules, by simulation (issue 48).

    python benchmarks/statistics_checks.py [--part learned] [--reps 4000]
        [--out docs/benchmarks/statistics-checks.json]

Each part simulates the rule the package applies (its own functions, not a copy) and
writes its rates with their Monte Carlo standard errors into the JSON file (other parts'
entries are kept), with the command, the machine and the date:

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
    from tactbench.runner.execution.learning import pooled_p, within_noise

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


PARTS = {"learned": learned_part}


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
