"""Loading the public touch-gesture corpora at their real size: first load, cached load,
peak memory, beside the CoST reader of before (issue 49).

    python benchmarks/corpora.py [--json docs/benchmarks/corpora.json] [--before REV]
                                 [--skip-before | --before-from JSON] [--skip-plan]
                                 [--keep DIR]

Generates, in a temporary folder, a CoST-format CSV of the corpus's real size (31
subjects × 14 gestures × 3 variants × 6 repetitions = 7 812 captures of 40–160 frames,
random 10-bit readings: about 780 000 rows, 206 MB) and HAART's two challenge files (578
+ 251 captures of 432 frames), then loads each in a fresh process, timing the load call
and reading the process's peak resident memory (``wait4``'s ``ru_maxrss``):

- ``cost first``: ``CoST(path).load()`` with an empty cache (read with pyarrow, checked,
  segmented, converted into the store);
- ``cost cached``: the same again (the file's SHA-256, then the store, verified);
- ``cost before``: the reader of ``--before`` (default: the commit before issue 49's
  rewrite), run once, as it was (a Python list per row); ``--skip-before`` leaves it out,
  ``--before-from JSON`` takes its row from an earlier run's JSON (said so in the JSON:
  it is slow, and it does not change);
- ``haart first`` and ``haart cached``: ``HAART(folder).load()``, the same way.

Then ``tactbench plan`` of the study's flow question (``encoder=raw..encoder=farneback``,
the main job's grid) on each corpus with people left out, and HAART's own division,
without a pilot (the spread is the plan's documented assumption); each plan's lines
(its per-cell lines left out) go into the JSON beside the loads. ``--skip-plan`` leaves
them out.

Goals (issue 49): CoST first load ≤ 20 s and ≤ 1.5 GiB peak, cached ≤ 2 s, on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BEFORE = "d867a8c"  # the commit before issue 49 rewrote tactbench/datasets/cost.py
GOALS = {"cost_first_s": 20.0, "cost_first_peak_gib": 1.5, "cost_cached_s": 2.0}
#: The plans made on the generated files: (corpus, the plan's options).
PLANS = [("cost", "--split users"),
         ("cost", "--split users --until answered --max-runs 10"),
         ("cost", "--split users:folds=5 --until answered --max-runs 10"),
         ("haart", "--split users --until answered --max-runs 10"),
         ("haart", "--split users:folds=5 --until answered --max-runs 10"),
         ("haart", "--split group:set:test=test"),
         ("haart", "--split group:set:test=test --until answered --max-runs 10")]

LOAD = """
import json, sys, time
sys.path.insert(0, {extra!r})
t0 = time.perf_counter()
{imports}
t1 = time.perf_counter()
ds = {call}
t2 = time.perf_counter()
print(json.dumps({{"import_s": t1 - t0, "load_s": t2 - t1, "captures": len(ds),
                  "users": len(set(ds.users)), "classes": len(ds.classes),
                  "frames": int(ds.lengths().sum())}}))
"""


def write_cost(path: Path, seed: int = 0) -> dict:
    """A CoST-format CSV of the real corpus's size (module docstring)."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    from tactbench.datasets.cost import GESTURES

    rng = np.random.default_rng(seed)
    keys = [(s, v, g) for s in range(1, 32) for v in ("gentle", "normal", "rough")
            for g in GESTURES for _ in range(6)]
    lengths = rng.integers(40, 161, size=len(keys))
    n = int(lengths.sum())
    rep = np.repeat(np.arange(len(keys)), lengths)
    frame = np.arange(n) - np.repeat(np.cumsum(lengths) - lengths, lengths) + 1
    cols = {"subject": pa.array(np.array([k[0] for k in keys])[rep]),
            "variant": pa.array(np.array([k[1] for k in keys])[rep]),
            "gesture": pa.array(np.array([k[2] for k in keys])[rep]),
            "frame": pa.array(frame)}
    values = rng.integers(0, 1024, size=(n, 64), dtype=np.int16)
    for k in range(64):
        cols[f"ch{k + 1}"] = pa.array(values[:, k])
    pacsv.write_csv(pa.table(cols), path, pacsv.WriteOptions(quoting_style="needed"))
    return {"captures": len(keys), "rows": n, "bytes": path.stat().st_size}


def write_haart(folder: Path, seed: int = 1) -> dict:
    """HAART's two challenge files at the real size: 7 training participants (578
    captures), 3 test participants (251), 432 frames each."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    from tactbench.datasets.haart import GESTURES

    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    conditions = [(s, c, g) for s in ("flat", "foam", "curved")
                  for c in ("none", "short", "long", "fur") for g in GESTURES]
    out = {}
    for name, people, keep in (("training.csv", range(1, 8), 578),
                               ("testWITHLABELS.csv", range(8, 11), 251)):
        keys = [(p, *c) for p in people for c in conditions]
        keys = [keys[i] for i in sorted(rng.choice(len(keys), size=keep, replace=False))]
        rep = np.repeat(np.arange(len(keys)), 432)
        cols = {title: pa.array(np.array([str(k[i]) for k in keys])[rep])
                for i, title in enumerate(("ParticipantID", "Substrate", "Cover", "Gesture"))}
        values = rng.integers(0, 1024, size=(rep.size, 64), dtype=np.int16)
        for k in range(64):
            cols[f"ch{k + 1}"] = pa.array(values[:, k])
        pacsv.write_csv(pa.table(cols), folder / name, pacsv.WriteOptions(quoting_style="needed"))
        out[name] = {"captures": len(keys), "rows": int(rep.size),
                     "bytes": (folder / name).stat().st_size}
    return out


def measure(label: str, imports: str, call: str, env: dict, extra: str = "") -> dict:
    """One load in a fresh interpreter: its times and the process's peak memory."""
    code = LOAD.format(extra=extra or str(REPO), imports=imports, call=call)
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    out, err = proc.stdout.read(), proc.stderr.read()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{label} failed:\n{err[-2000:]}")
    row = {"what": label, **json.loads(out.strip().splitlines()[-1]),
           "process_s": wall, "peak_rss_mib": usage.ru_maxrss / 1024.0,
           "said": [line for line in err.splitlines() if line.strip()]}
    print(f"{label:<14} load {row['load_s']:7.2f} s (process {wall:6.2f} s), peak "
          f"{row['peak_rss_mib']:7.0f} MiB, {row['captures']} captures", flush=True)
    return row


def plan(dataset: str, options: str, env: dict, out: Path) -> dict:
    """``tactbench plan`` of the main job's grid on ``dataset``: its lines, the per-cell
    ones left out."""
    argv = ["--dataset", dataset, *options.split(), "--out", str(out)]
    proc = subprocess.run([sys.executable, "-m", "tactbench", "plan", *argv], env=env,
                          capture_output=True, text=True, check=True)
    lines = [line for line in proc.stdout.splitlines() if not line.startswith("cell ")]
    command = "tactbench plan " + " ".join(argv[:-2]).replace(f"{out.parent}/", "")
    print(f"{command}\n  " + "\n  ".join(lines), flush=True)
    return {"command": command, "lines": lines}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", dest="json_out")
    parser.add_argument("--before", default=BEFORE)
    parser.add_argument("--skip-before", action="store_true")
    parser.add_argument("--skip-plan", action="store_true")
    parser.add_argument("--before-from", help="take the reader before's row from this JSON")
    parser.add_argument("--keep", help="write the generated files here and keep them")
    args = parser.parse_args()

    load_before = os.getloadavg()  # other jobs on the machine: said beside the numbers
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(args.keep or tmp_name)
        tmp.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "TACTBENCH_CACHE": str(tmp / "cache")}
        t0 = time.perf_counter()
        cost = write_cost(tmp / "CoST.csv")
        haart = write_haart(tmp / "haart")
        print(f"generated CoST {cost['bytes'] / 1e6:.0f} MB ({cost['rows']} rows, "
              f"{cost['captures']} captures) and HAART in {time.perf_counter() - t0:.0f} s",
              flush=True)
        rows = []
        new = "from tactbench.datasets.cost import CoST"
        rows.append(measure("cost first", new, f"CoST({str(tmp / 'CoST.csv')!r}).load()", env))
        rows.append(measure("cost cached", new, f"CoST({str(tmp / 'CoST.csv')!r}).load()", env))
        new = "from tactbench.datasets.haart import HAART"
        rows.append(measure("haart first", new, f"HAART({str(tmp / 'haart')!r}).load()", env))
        rows.append(measure("haart cached", new, f"HAART({str(tmp / 'haart')!r}).load()", env))
        specs = {"cost": f"cost:path={tmp / 'CoST.csv'}", "haart": f"haart:path={tmp / 'haart'}"}
        plans = [] if args.skip_plan else [plan(specs[c], o, env, tmp / "plan-out")
                                           for c, o in PLANS]
        if args.before_from:
            earlier = json.loads(Path(args.before_from).read_text())
            rows += [{**r, "from": f"{args.before_from} of {earlier['date']}"}
                     for r in earlier["rows"] if r["what"] == "cost before"]
        elif not args.skip_before:
            old = subprocess.run(["git", "show", f"{args.before}:tactbench/datasets/cost.py"],
                                 cwd=REPO, capture_output=True, text=True, check=True).stdout
            (tmp / "before").mkdir(exist_ok=True)
            (tmp / "before" / "cost_before.py").write_text(old)
            rows.append(measure("cost before", "from cost_before import read_cost_csv",
                                f"read_cost_csv({str(tmp / 'CoST.csv')!r})", env,
                                extra=str(tmp / "before")))
    by = {r["what"]: r for r in rows}
    first, cached = by["cost first"], by["cost cached"]
    verdict = {"cost_first_s": first["load_s"] <= GOALS["cost_first_s"],
               "cost_first_peak_gib": first["peak_rss_mib"] / 1024 <= GOALS["cost_first_peak_gib"],
               "cost_cached_s": cached["load_s"] <= GOALS["cost_cached_s"]}
    print(f"load average (1, 5, 15 min) at the start {load_before}, at the end "
          f"{os.getloadavg()}")
    print("goals: " + ", ".join(f"{k} {'met' if ok else 'MISSED'}" for k, ok in verdict.items()))
    doc = {"benchmark": "corpora", "command": "python benchmarks/corpora.py --json "
           "docs/benchmarks/corpora.json", "machine": platform.platform(),
           "processor": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
           "python": sys.version.split()[0], "date": time.strftime("%Y-%m-%d"),
           "load_average_1_5_15_min": {"start": load_before, "end": os.getloadavg()},
           "before": None if args.skip_before else args.before,
           "before_from": args.before_from,
           "files": {"cost": cost, "haart": haart}, "goals": GOALS, "met": verdict,
           "rows": rows, "plans": plans, "self_peak_rss_mib":
           resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
