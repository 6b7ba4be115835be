"""The README's main job against the code before, on this machine, in one run (issue 36).

    python benchmarks/first_run.py [--baseline 1eb4afe] [--out docs/benchmarks/first-run.json]
                                   [--skip baseline,grid,load,warm]

Every step starts from an empty cache (the simulator's data set, the images and the
encodings are made again, as on a fresh install) unless it says warm, one after another,
with nothing else running:

1. ``baseline``: the main job of the code at ``--baseline`` (``tactbench run``, 3 runs, one
   cell at a time on the machine's cores), from a git worktree of that commit on this
   interpreter's packages;
2. ``grid``: today's ``tactbench run`` (the same 3-run grid, cells side by side);
3. ``main``: today's main job, ``tactbench run --until answered --max-runs 10``, with
   ``tactbench plan`` of the same command just before it (its forecast, cold);
4. ``load``: the main job again, from an empty cache, beside one busy process (a Python
   loop on one core for the whole run);
5. ``warm``: plan, then the main job, into a new out folder on the warm cache of step 3.

It records each wall time, the ratios the issue sets as goals (main ≤ 1.0 × baseline,
grid ≤ 0.6 ×, load ≤ 2 × main, plan within ±25 %), the machine and the date.
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

REPO = Path(__file__).resolve().parents[1]
MAIN_JOB = ["--until", "answered", "--max-runs", "10"]
#: Variables of the kernel pin: the baseline ran without them, as it did then.
PIN_VARIABLES = ("TACTBENCH_CPU_KERNELS", "ATEN_CPU_CAPABILITY", "ONEDNN_MAX_CPU_ISA",
                 "MKL_CBWR", "NPY_DISABLE_CPU_FEATURES", "OPENCV_CPU_DISABLE")
GOALS = {"main_over_baseline": 1.0, "grid_over_baseline": 0.6, "load_over_main": 2.0,
         "plan_error": 0.25}


def timed(argv: list[str], env: dict[str, str], log: Path, cwd: Path = REPO) -> float:
    """Seconds ``argv`` took (in ``cwd``, whose ``tactbench`` ``python -m`` runs); its
    output goes to ``log``; exits when it fails."""
    start = time.perf_counter()
    with log.open("w") as out:
        proc = subprocess.run(argv, env=env, stdout=out, stderr=subprocess.STDOUT, cwd=cwd)
    seconds = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"{' '.join(argv)} failed ({proc.returncode}); see {log}")
    print(f"{seconds:8.1f} s  {' '.join(argv[2:])}", flush=True)
    return seconds


def fresh_env(scratch: Path, name: str, **extra: str) -> dict[str, str]:
    cache = scratch / f"cache-{name}"
    cache.mkdir()
    return {**os.environ, "TACTBENCH_CACHE": str(cache), **extra}


def tactbench(*args: str) -> list[str]:
    return [sys.executable, "-m", "tactbench", *args]


def planned(argv: list[str], env: dict[str, str], log: Path) -> float:
    """The wall time ``tactbench plan`` forecasts for ``argv`` (a run's arguments)."""
    proc = subprocess.run(tactbench("plan", *argv, "--json"), env=env, capture_output=True,
                          text=True, cwd=REPO)
    log.write_text(proc.stdout + proc.stderr)
    if proc.returncode != 0:
        sys.exit(f"tactbench plan failed; see {log}")
    return float(json.loads(proc.stdout)["wall_s"][0])


def baseline(rev: str, scratch: Path) -> float:
    """The main job of commit ``rev``, from a worktree, unpinned as it ran then."""
    tree = scratch / "baseline"
    subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(tree), rev],
                   check=True, capture_output=True)
    try:
        env = {k: v for k, v in fresh_env(scratch, "baseline").items()
               if k not in PIN_VARIABLES}
        return timed(tactbench("run", "--out", str(scratch / "out-baseline")), env,
                     scratch / "baseline.log", cwd=tree)  # python -m: the tree's package
    finally:
        subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree)],
                       capture_output=True)


def under_load(argv: list[str], env: dict[str, str], log: Path) -> float:
    """``argv``'s seconds beside one busy process (a Python loop) the whole time."""
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        return timed(argv, env, log)
    finally:
        busy.kill()
        busy.wait()


def measure(args: argparse.Namespace, scratch: Path) -> dict:
    skip = set(args.skip.split(",")) if args.skip else set()
    out: dict = {}
    if "baseline" not in skip:
        out["baseline_s"] = baseline(args.baseline, scratch)
    if "grid" not in skip:
        out["grid_s"] = timed(tactbench("run", "--out", str(scratch / "out-grid")),
                              fresh_env(scratch, "grid"), scratch / "grid.log")
    env = fresh_env(scratch, "main")
    main = ["--out", str(scratch / "out-main"), *MAIN_JOB]
    out["plan_cold_s"] = planned(main, env, scratch / "plan-cold.log")
    out["main_s"] = timed(tactbench("run", *main), env, scratch / "main.log")
    out["main_report"] = json.loads((scratch / "out-main" / "results.json").read_text()
                                    ).get("looks")
    if "load" not in skip:
        out["load_s"] = under_load(tactbench("run", "--out", str(scratch / "out-load"),
                                             *MAIN_JOB),
                                   fresh_env(scratch, "load"), scratch / "load.log")
    if "warm" not in skip:
        warm = ["--out", str(scratch / "out-warm"), *MAIN_JOB]
        out["plan_warm_s"] = planned(warm, env, scratch / "plan-warm.log")
        out["warm_s"] = timed(tactbench("run", *warm), env, scratch / "warm.log")
    return out


def ratios(m: dict) -> dict:
    """The goals' ratios that the measured steps allow."""
    r = {}
    if "baseline_s" in m:
        r["main_over_baseline"] = m["main_s"] / m["baseline_s"]
        if "grid_s" in m:
            r["grid_over_baseline"] = m["grid_s"] / m["baseline_s"]
    if "load_s" in m:
        r["load_over_main"] = m["load_s"] / m["main_s"]
    r["plan_error_cold"] = m["plan_cold_s"] / m["main_s"] - 1
    if "warm_s" in m:
        r["plan_error_warm"] = m["plan_warm_s"] / m["warm_s"] - 1
    return r


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default="1eb4afe")
    parser.add_argument("--out", default="docs/benchmarks/first-run.json")
    parser.add_argument("--skip", default="", help="steps to leave out: baseline,grid,load,warm")
    parser.add_argument("--keep", help="keep the run folders and logs here")
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="tactbench-first-run-"))
    try:
        measured = measure(args, scratch)
    finally:
        if args.keep:
            shutil.copytree(scratch, args.keep, dirs_exist_ok=True,
                            ignore=shutil.ignore_patterns("cache-*"))
        shutil.rmtree(scratch, ignore_errors=True)
    r = ratios(measured)
    doc = {"benchmark": "first-run", "command": "python " + " ".join(sys.argv),
           "main_job": "tactbench run " + " ".join(MAIN_JOB), **measured, "ratios": r,
           "goals": GOALS, "cpu": _cpu(), "cores": os.cpu_count(),
           "machine": platform.platform(), "python": sys.version.split()[0],
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(doc, indent=2) + "\n")
    for name, value in r.items():
        print(f"{name:20s} {value:+.3f}" if "error" in name else f"{name:20s} {value:.3f}")


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


if __name__ == "__main__":
    main()
