"""The runner's goals, measured: the study's comparison on the quick profile, twice.

    python benchmarks/runner.py [--out docs/results/study-quick] [--workers-too]
                                [--repeats N] [--extra ARGS...]

1. From an empty cache: `tactbench run` with its defaults — the study's comparison
   (raw vs farneback, small-cnn-lstm, L = 5, seeds 0 1 2, paper split, test window
   vote, quick profile, the built-in synthetic-forearm dataset: version 2 since
   2026-11-24, whose recordings are about twice version 1's length). Goal: ≤ 180 s on 2 CPU cores (issue 21; it was
   ≤ 10 minutes before).
2. The identical command again. Goal: ≤ 5 % of the first (nothing is recomputed).
3. With ``--workers-too``: the same grid into two fresh output folders on the now warm
   encoding cache, one cell at a time with 2 torch threads (the default) and two cells at
   once with 1 thread each (``--workers 2``): which serves a grid better on this machine
   (``--repeats N``: N interleaved pairs, so that the machine's drift hits both alike).

The run's reports (report.md, results.csv/json, plots) land in --out; the timings go to
OUT/timing.json. Extra arguments are passed to `tactbench run` (e.g. `-L 1-6`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GOAL_FIRST_S = 180.0
GOAL_SECOND_FRACTION = 0.05


def timed(argv: list[str], env: dict[str, str]) -> tuple[float, str]:
    start = time.perf_counter()
    proc = subprocess.run(argv, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"tactbench run failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return elapsed, proc.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/results/study-quick")
    parser.add_argument("--workers-too", action="store_true",
                        help="also time the cells alone: 1 worker x 2 threads and 2 x 1")
    parser.add_argument("--repeats", type=int, default=1,
                        help="with --workers-too: interleaved repeats of the two")
    parser.add_argument("extra", nargs="*", help="more arguments for tactbench run")
    args = parser.parse_args()

    out = Path(args.out)
    if out.exists():
        shutil.rmtree(out)
    cache = Path(tempfile.mkdtemp(prefix="tactbench-bench-cache-"))
    env = {**os.environ, "TACTBENCH_CACHE": str(cache)}
    argv = [sys.executable, "-m", "tactbench", "run", "--out", str(out), *args.extra]
    # The simulator's own cache is part of the first run's cost, as on a fresh install.
    first_s, first_out = timed(argv, env)
    second_s, _ = timed(argv, env)
    grid: dict[str, list[float]] = {}
    if args.workers_too:  # encodings cached now: what is left is the cells
        for _ in range(args.repeats):  # interleaved: the VM's drift hits both alike
            for label, flags in (("1 worker x 2 threads", ["--workers", "1", "--threads", "2"]),
                                 ("2 workers x 1 thread", ["--workers", "2", "--threads", "1"])):
                scratch = Path(tempfile.mkdtemp(prefix="tactbench-bench-grid-"))
                seconds, _ = timed([sys.executable, "-m", "tactbench", "run", "--out",
                                    str(scratch / "out"), *flags, *args.extra], env)
                grid.setdefault(label, []).append(seconds)
                shutil.rmtree(scratch, ignore_errors=True)
                print(f"{label}: {seconds:.1f} s (encodings cached)", flush=True)
    shutil.rmtree(cache, ignore_errors=True)

    doc = {
        "benchmark": "runner",
        "command": "tactbench run " + " ".join(["--out", str(out), *args.extra]),
        "first_run_s": first_s, "second_run_s": second_s,
        "second_over_first": second_s / first_s,
        "goal_first_s": GOAL_FIRST_S, "goal_second_fraction": GOAL_SECOND_FRACTION,
        "first_ok": first_s <= GOAL_FIRST_S,
        "second_ok": second_s / first_s <= GOAL_SECOND_FRACTION,
        **({"grid_cached_encodings_s": grid} if grid else {}),
        "machine": platform.platform(), "cpus": os.cpu_count(),
        "python": sys.version.split()[0], "date": time.strftime("%Y-%m-%d"),
    }
    (out / "timing.json").write_text(json.dumps(doc, indent=2))
    print(first_out)
    print(f"first run  {first_s:7.1f} s  (goal ≤ {GOAL_FIRST_S:.0f} s: "
          f"{'ok' if doc['first_ok'] else 'MISSED'})")
    print(f"second run {second_s:7.1f} s  = {100 * doc['second_over_first']:.1f} % of the "
          f"first (goal ≤ {100 * GOAL_SECOND_FRACTION:.0f} %: "
          f"{'ok' if doc['second_ok'] else 'MISSED'})")


if __name__ == "__main__":
    main()
