"""The README's main job against the code before, on this machine, in one run (issue 36).

    python benchmarks/first_run.py [--baseline 1eb4afe] [--out docs/benchmarks/first-run.json]
                                   [--skip baseline,pinned,floor,grid,main,load,warm]

Every step starts from an empty cache (the simulator's data set, the images and the
encodings are made again, as on a fresh install) unless it says warm, one after another,
with nothing else running:

1. ``baseline``: the main job of the code at ``--baseline`` (``tactbench run``, 3 runs, one
   cell at a time on the machine's cores), from a git worktree of that commit on this
   interpreter's packages;
2. ``pinned``: the same, on the CPU kernels today's cells are pinned to (AVX2), as the
   code before would run on a machine with AVX2 only;
3. ``floor``: the least time today's main job and 3-run grid could take on this machine,
   from bare loops of their two dominant stages measured right after the baseline
   (:func:`floor`): every cell's optimiser steps at the speed of a bare torch loop, two
   at once as the cells run, plus a bare ``cv2.calcOpticalFlowFarneback`` loop (no
   padding) over every frame of the data set on both cores; nothing else (no data set,
   imaging, loading, prediction or report) is counted;
4. ``grid``: today's ``tactbench run`` (the same 3-run grid, cells side by side);
5. ``main``: today's main job, ``tactbench run --until answered --max-runs 10``, with
   ``tactbench plan`` of the same command just before it (its forecast, cold);
6. ``load``: the main job again, from an empty cache, beside one busy process (a Python
   loop on one core for the whole run);
7. ``warm``: plan, then the main job, into a new out folder on the warm cache of step 5.

It records each wall time, the ratios the issue sets as goals (main ≤ 1.0 × baseline,
grid ≤ 0.6 ×, load ≤ 2 × main, plan within ±25 %), the floor's against the same goals
(a floor above a goal: no implementation of today's model meets it here), the machine
and the date. ``--skip grid,main,load,warm`` measures both baselines and the floor alone
(about 12 minutes).
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
#: The committed run of the README's main job: its cells give the model, the steps a cell
#: takes and how many cells the first look trains.
COMMITTED = REPO / "docs/results/study-quick/cells"
#: Runs of the 3-run grid (the code before's main job, and ``tactbench run``'s default).
GRID_RUNS = 3
MAIN_JOB = ["--until", "answered", "--max-runs", "10"]
#: Variables of the kernel pin: the baseline ran without them, as it did then.
PIN_VARIABLES = ("TACTBENCH_CPU_KERNELS", "ATEN_CPU_CAPABILITY", "ONEDNN_MAX_CPU_ISA",
                 "MKL_CBWR", "NPY_DISABLE_CPU_FEATURES", "OPENCV_CPU_DISABLE")
GOALS = {"main_over_baseline": 1.0, "grid_over_baseline": 0.6, "load_over_main": 2.0,
         "plan_error": 0.25, "floor_main_over_baseline": 1.0, "floor_grid_over_baseline": 0.6}


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


def baseline(rev: str, scratch: Path, *, pinned: bool = False) -> float:
    """The main job of commit ``rev``, from a worktree, unpinned as it ran then; with
    ``pinned``, on the kernels today's cells use (AVX2: the libraries' own variables, which
    that code did not set itself), as it would run on a machine with AVX2 only."""
    from tactbench.kernels import pin_cpu_kernels

    name = "baseline-pinned" if pinned else "baseline"
    tree = scratch / name
    subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(tree), rev],
                   check=True, capture_output=True)
    try:
        env = {k: v for k, v in fresh_env(scratch, name).items() if k not in PIN_VARIABLES}
        if pinned:
            env["TACTBENCH_CPU_KERNELS"] = "avx2"
            pin_cpu_kernels(env)  # writes ATEN_CPU_CAPABILITY, ONEDNN_MAX_CPU_ISA, …
        return timed(tactbench("run", "--out", str(scratch / f"out-{name}")), env,
                     scratch / f"{name}.log", cwd=tree)  # python -m: the tree's package
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


def floor() -> dict:
    """The main job's and the 3-run grid's least wall time here with today's model.

    Per cell: its optimiser steps (the committed cells' ``fit.steps``) at the ms a step of
    a bare torch loop of the same network takes while another runs beside it (one per
    core, raw's and farneback's inputs at once, as the cells run; median of two rounds).
    The data set's flow: its frame count × the ms a frame of a bare cv2 Farnebäck loop
    takes (unpadded, so below the encoder's own cost). Both spread perfectly over the
    cores; every other stage costs nothing. A lower bound, not a forecast."""
    import multiprocessing
    import statistics
    from concurrent.futures import ProcessPoolExecutor

    import bare_loops  # this folder's: the same bare loops as docs/benchmarks/bare-loops.json

    from tactbench.datasets.loading import load_dataset
    from tactbench.plugins import load_registry

    rows = [json.loads(p.read_text()) for p in sorted(COMMITTED.glob("*.json"))]
    rows = [r for r in rows if r.get("status") == "ok"]
    encoders = sorted({r["encoder"] for r in rows})  # raw, farneback
    runs = len({r["seed"] for r in rows})
    steps = {e: int(statistics.median(r["fit"]["steps"] for r in rows if r["encoder"] == e))
             for e in encoders}
    channels = {"raw": 1, "farneback": 3}
    ms: dict[str, list[float]] = {e: [] for e in encoders}
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(bare_loops._bare_steps, [1, 3], [5, 5]))  # start both workers
        for _ in range(2):
            for e, t in zip(encoders, pool.map(bare_loops._bare_steps,
                                                [channels[e] for e in encoders], [200, 200])):
                ms[e].append(t)
    flow = bare_loops.farneback(20)
    frames = int(sum(load_dataset("synthetic-forearm", registry=load_registry()).lengths()))
    cores = 2
    step_s = {e: statistics.median(ms[e]) / 1e3 for e in encoders}
    train = {n: sum(n * steps[e] * step_s[e] for e in encoders) / cores
             for n in (runs, GRID_RUNS)}
    flow_s = frames * flow["bare_cv2_ms_per_frame"] / 1e3 / cores
    return {"cells": {"main_first_look": runs * len(encoders),
                      "grid": GRID_RUNS * len(encoders)},
            "steps_per_cell": steps, "bare_ms_per_step_side_by_side": ms,
            "frames": frames, "bare_cv2_ms_per_frame": flow["bare_cv2_ms_per_frame"],
            "encoder_ms_per_frame": flow["encoder_ms_per_frame"], "cores": cores,
            "train_s": {"main": train[runs], "grid": train[GRID_RUNS]},
            "flow_s": flow_s,
            "main_s": train[runs] + flow_s, "grid_s": train[GRID_RUNS] + flow_s}


def measure(args: argparse.Namespace, scratch: Path) -> dict:
    skip = set(args.skip.split(",")) if args.skip else set()
    out: dict = {}
    if "baseline" not in skip:
        out["baseline_s"] = baseline(args.baseline, scratch)
    if "pinned" not in skip:
        out["baseline_pinned_s"] = baseline(args.baseline, scratch, pinned=True)
    if "floor" not in skip:
        out["floor"] = floor()
        print(f"{out['floor']['main_s']:8.1f} s  floor of the main job "
              f"({out['floor']['grid_s']:.1f} s of the grid)", flush=True)
    if "grid" not in skip:
        out["grid_s"] = timed(tactbench("run", "--out", str(scratch / "out-grid")),
                              fresh_env(scratch, "grid"), scratch / "grid.log")
    if "main" in skip:
        return out
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
        if "main_s" in m:
            r["main_over_baseline"] = m["main_s"] / m["baseline_s"]
        if "grid_s" in m:
            r["grid_over_baseline"] = m["grid_s"] / m["baseline_s"]
        if "floor" in m:
            r["floor_main_over_baseline"] = m["floor"]["main_s"] / m["baseline_s"]
            r["floor_grid_over_baseline"] = m["floor"]["grid_s"] / m["baseline_s"]
    if "baseline_pinned_s" in m:
        r["pinned_over_baseline"] = m["baseline_pinned_s"] / m.get("baseline_s", float("nan"))
        if "floor" in m:
            r["floor_main_over_pinned"] = m["floor"]["main_s"] / m["baseline_pinned_s"]
            r["floor_grid_over_pinned"] = m["floor"]["grid_s"] / m["baseline_pinned_s"]
    if "main_s" not in m:
        return r
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
    parser.add_argument("--skip", default="",
                        help="steps to leave out: baseline,pinned,floor,grid,main,load,warm "
                             "(pinned: the code before on today's AVX2 kernels)")
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
