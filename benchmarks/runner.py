"""The README's main job, measured and committed: the study's question, answered.

    python benchmarks/runner.py [--out docs/results/study-quick] [--readme] [--workers-too]
                                [--repeats N] [ARGS...]

1. From an empty cache: ``tactbench run --until answered --max-runs 10`` (or ARGS) — the
   study's comparison (raw vs farneback, small-cnn-lstm, L = 5, paper split, test window
   vote, quick profile, the built-in synthetic-forearm dataset), runs added until its
   primary question is answered, cells side by side at one thread each, kernels pinned.
2. The identical command again. Goal: ≤ 5 % of the first (nothing is recomputed).
3. With ``--workers-too``: the same grid into two fresh output folders on the now warm
   encoding cache, one cell at a time with 2 torch threads and two cells at once with 1
   thread each (``--repeats N``: N interleaved pairs, so that the machine's drift hits
   both alike). The two give other numbers (the thread count is in a cell's identity).

The run's reports (report.md, results.csv/json, plots) land in --out; the timings go to
OUT/timing.json; ``--readme`` rewrites the README's paragraph on the main job from them
(:func:`write_main_job`). The comparison with the code before is benchmarks/first_run.py.
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

#: The README's main job: the study's question, runs added until it is answered.
MAIN_JOB = ["--until", "answered", "--max-runs", "10"]
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
    parser.add_argument("--readme", action="store_true",
                        help="rewrite the README's main-job paragraph from this run")
    parser.add_argument("extra", nargs="*", default=MAIN_JOB,
                        help="the arguments of tactbench run (default: the README's main "
                             "job, " + " ".join(MAIN_JOB) + ")")
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
        "goal_second_fraction": GOAL_SECOND_FRACTION,
        "second_ok": second_s / first_s <= GOAL_SECOND_FRACTION,
        **({"grid_cached_encodings_s": grid} if grid else {}),
        "machine": platform.platform(), "cpus": os.cpu_count(),
        "python": sys.version.split()[0], "date": time.strftime("%Y-%m-%d"),
    }
    (out / "timing.json").write_text(json.dumps(doc, indent=2))
    if args.readme:
        write_main_job(out)
    print(first_out)
    print(f"first run  {first_s:7.1f} s  (against the code before: benchmarks/first_run.py)")
    print(f"second run {second_s:7.1f} s  = {100 * doc['second_over_first']:.1f} % of the "
          f"first (goal ≤ {100 * GOAL_SECOND_FRACTION:.0f} %: "
          f"{'ok' if doc['second_ok'] else 'MISSED'})")


#: The README's paragraph on the main job's committed run lies between these markers and
#: is written by :func:`write_main_job` (tests/test_readme.py checks it is current).
MAIN_START = "<!-- main job: written by benchmarks/runner.py from docs/results/study-quick -->"
MAIN_END = "<!-- /main job -->"


def main_job_text(folder: Path) -> str:
    """The README's sentences on the committed main job in ``folder``: its primary
    answer first (the package's own words), the runs it took, each encoding's accuracy,
    the wall time, machine and date."""
    from tactbench.runner import answer_text, render_folder

    report = render_folder(folder, write=False, plots=False)
    [primary] = [c for c in report.comparisons if c.family == "primary"]
    accuracy = {s["encoder"]: s for s in report.summaries}
    timing = json.loads((folder / "timing.json").read_text())
    runs = len({r["seed"] for r in report.ok})
    looks = (report.looks or {}).get("looks") or []
    facts = report.ok[0].get("machine") or {}
    rel = Path(os.path.relpath(folder.resolve(), Path(__file__).resolve().parents[1]))
    return (f"On the committed run ([{rel.as_posix()}]({rel.as_posix()}/report.md)): "
            + answer_text(primary).replace("**", "") + " "
            + f"It stopped after {runs} runs" + (f" at look {len(looks)}" if looks else "")
            + "; " + ", ".join(f"`{e}` {100 * s['accuracy_mean']:.1f} ± {100 * s['accuracy_std']:.1f} %"
                               for e, s in sorted(accuracy.items()))
            + f". Wall time {timing['first_run_s']:.0f} s from an empty cache on "
            + f"{facts.get('cpu', 'an unknown CPU')}, {timing['cpus']} cores, "
            + f"{timing['date']}; CPU kernels pinned to "
            + f"{(facts.get('pinned') or {}).get('TACTBENCH_CPU_KERNELS', 'nothing')}, "
            + f"{report.ok[0]['threads']} torch thread per cell.")


def write_main_job(folder: Path, readme: Path = Path(__file__).resolve().parents[1]
                   / "README.md") -> None:
    """Rewrite the README's main-job paragraph from the committed run in ``folder``."""
    import textwrap

    text = readme.read_text()
    head, rest = text.split(MAIN_START, 1)
    _, tail = rest.split(MAIN_END, 1)
    body = textwrap.fill(main_job_text(folder), width=90)
    readme.write_text(f"{head}{MAIN_START}\n{body}\n{MAIN_END}{tail}")


if __name__ == "__main__":
    main()
