"""Which test window? The study's first L frames against the contact onset and a vote.

    python benchmarks/which_window.py [--seeds 0-4] [--sim synthetic-forearm:version=2] [--render]
        [--out docs/reports/which-window.md]

On the simulator's version 2 (``synthetic-forearm:version=2``: recordings start before
contact and end after release) and on the real sets in ``../shared/data`` (``TACTBENCH_SHARED_DATA``):
cyskin-fingers (read by the cyskin-text reader, taxel vectors) and icub-grasp (the
``tactbench-icub`` plugin), one grid per test window — ``first`` (the first L frames, the
study's), ``onset`` (L frames from the contact onset) and ``vote`` (every window,
probabilities averaged) — with encoder ``raw`` and classifier ``logreg`` on the study's
random split (``paper``; the real sets have no users), L = 5 (icub-grasp: 4, its trials
are short). Per seed the windows share the split and the training windows' model class,
so onset − first and vote − first are paired by seed; their intervals are Nadeau and
Bengio's corrected resampled t over seeds (``scipy.stats.t``, computed here: see
``benchmarks/people.py``). A real set that is absent is skipped, and the report says so.
Writes the markdown report and a JSON beside it; the report index
(``docs/reports/README.md``) gets its line.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from tactbench.machine import benchmark_meta  # noqa: E402


import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from people import corrected_t_interval  # noqa: E402

SHARED = Path(os.environ.get("TACTBENCH_SHARED_DATA", REPO.parent / "shared" / "data"))
WINDOWS = ("first", "onset", "vote")
TITLE = ("Which test window? first L frames, from the contact onset, or a vote over every "
         "window; simulator and real sets")


def datasets(sim: str) -> list[tuple[str, str, int, str | None]]:
    """(name, spec, L, why skipped)."""
    fingers, icub = SHARED / "cyskin-fingers", SHARED / "icub-grasp"
    out = [("simulator", sim, 5, None)]
    out.append(("cyskin-fingers", str(fingers), 5,
                None if fingers.is_dir() else f"{fingers} is absent"))
    out.append(("icub-grasp", f"icub-grasp:path={icub}", 4,
                None if icub.is_dir() else f"{icub} is absent"))
    return out


def run_window(spec: str, length: int, seeds: list[int], window: str, work: Path) -> list[dict]:
    from tactbench.runner import EncodingCache, Scene, run

    scene = Scene(dataset=spec, encoders=["raw"], classifiers=["logreg"], L=[length],
                  seeds=seeds, split="paper", test_window=window, threads=1,
                  out=str(work / f"{abs(hash(spec)) % 10 ** 8}-{window}"))
    result = run(scene, progress=False, cache=EncodingCache(work / "cache"))
    bad = [r for r in result.rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"{spec} {window}: {len(bad)} cell(s) failed: {bad[0].get('error')}")
    return result.rows


def measure(args: argparse.Namespace, work: Path) -> dict:
    from tactbench.runner import parse_seeds

    seeds = parse_seeds(args.seeds.split(","))
    out: dict = {}
    for name, spec, length, skipped in datasets(args.sim):
        if skipped:
            out[name] = {"skipped": skipped}
            continue
        t0 = time.perf_counter()
        acc, ratio, classes = {}, 0.0, 0
        for window in WINDOWS:
            rows = run_window(spec, length, seeds, window, work)
            acc[window] = {r["seed"]: r["accuracy"] for r in rows}
            ratio = max(ratio, max(r["n_test"] / r["n_train"] for r in rows))
            classes = len(rows[0]["classes"])
        res = {"spec": spec, "L": length, "classes": classes, "chance": 1 / classes,
               "accuracy": {w: float(np.mean(list(a.values()))) for w, a in acc.items()},
               "per_seed": {w: [acc[w][s] for s in seeds] for w in WINDOWS},
               "against_first": {w: corrected_t_interval([acc[w][s] - acc["first"][s]
                                                          for s in seeds], ratio)
                                 for w in WINDOWS[1:]},
               "wall_s": time.perf_counter() - t0}
        out[name] = res
    return out


def markdown(args: argparse.Namespace, res: dict, meta: dict) -> str:
    lines = [f"# {TITLE}", "",
             f"**Regenerate**: `{meta['command']}` — {meta['machine']}, {meta['date']}. "
             "Encoder `raw`, classifier `logreg`, the study's random split (`paper`), seeds "
             f"{args.seeds}; one run per test window (`tactbench run --test-window "
             "first|onset|vote`). Wall time "
             f"{sum(r.get('wall_s', 0) for r in res.values()) / 60:.1f} min (encodings of "
             "the simulator cached by an earlier run; other jobs shared the machine).", "",
             "| data | L | classes (chance) | first | onset | vote | onset − first | "
             "vote − first |", "|---|---|---|---|---|---|---|---|"]
    skipped = []
    for name, r in res.items():
        if "skipped" in r:
            skipped.append(f"- {name}: skipped — {r['skipped']}.")
            continue
        a, d = r["accuracy"], r["against_first"]
        diff = lambda g: (f"{100 * g['mean']:+.1f} [{100 * g['low']:+.1f}, "  # noqa: E731
                          f"{100 * g['high']:+.1f}]")
        lines.append(f"| {name} | {r['L']} | "
                     f"{r['classes']} ({100 * r['chance']:.0f} %) | {100 * a['first']:.1f} % | "
                     f"{100 * a['onset']:.1f} % | {100 * a['vote']:.1f} % | "
                     f"{diff(d['onset'])} | {diff(d['vote'])} |")
    lines += ["", "Accuracy is the mean over seeds; differences in points with their 95 % "
              "interval (Nadeau–Bengio corrected resampled t over seeds, paired by seed, "
              "computed by the script).", ""]
    if skipped:
        lines += ["Not run:", "", *skipped, ""]
    lines += ["## What it shows", ""]
    for name, r in res.items():
        if "skipped" in r:
            continue
        said = []
        for w, g in r["against_first"].items():
            if g["low"] > 0:
                said.append(f"`{w}` beats `first` by {100 * g['mean']:.1f} points")
            elif g["high"] < 0:
                said.append(f"`first` beats `{w}` by {-100 * g['mean']:.1f} points")
            else:
                said.append(f"`{w}` and `first` are not told apart "
                            f"({100 * g['mean']:+.1f} points)")
        lines.append(f"- {name}: " + "; ".join(said) + ".")
    lines += ["", "## What it does not show", "",
              "- `first` assumes recordings start at contact. The simulator's version 2 "
              "starts before contact by design (a lead-in of about 6 frames), so there "
              "`first` at L = 5 sees little touch. Whether a real set's recordings start at "
              "contact depends on how they were cut: a set trimmed to its touches gives "
              "`first` the gesture's start, and the contact onset of a set that starts "
              "with pressure already on may fall late in it.",
              "- One encoder and one classifier (the cheapest), the random split only; the "
              "real sets' test sets are small, so their intervals are wide.",
              f"- Numbers in [{Path(args.out).with_suffix('.json').name}]"
              f"({Path(args.out).with_suffix('.json').name}).", ""]
    return "\n".join(lines)


def add_to_index(report: Path) -> None:
    from tactbench.paths import atomic_write_text

    index = report.parent / "README.md"
    if not index.is_file():
        return
    text = index.read_text()
    line = f"- [{report.stem}]({report.name}): {TITLE}"
    kept = [ln for ln in text.rstrip("\n").splitlines()
            if not ln.startswith(f"- [{report.stem}](")]
    atomic_write_text(index, "\n".join(kept + [line]) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--sim", default="synthetic-forearm:version=2")
    ap.add_argument("--out", default=str(REPO / "docs" / "reports" / "which-window.md"))
    ap.add_argument("--work", help="folder for the runs (default: a temporary one)")
    ap.add_argument("--render", action="store_true",
                    help="only rewrite the markdown from the JSON beside it (no runs)")
    args = ap.parse_args(argv)
    if args.render:
        from tactbench.paths import atomic_write_text

        out = Path(args.out)
        doc = json.loads(out.with_suffix(".json").read_text())
        meta = {k: doc[k] for k in ("command", "machine", "date")}
        args.seeds = doc.get("seeds", args.seeds)
        atomic_write_text(out, markdown(args, doc["results"], meta))
        add_to_index(out)
        return 0
    meta = benchmark_meta("benchmarks/which_window.py",
                          argv if argv is not None else sys.argv[1:])
    if args.work:
        res = measure(args, Path(args.work))
    else:
        with tempfile.TemporaryDirectory(prefix="tactbench-window-") as tmp:
            res = measure(args, Path(tmp))
    from tactbench.paths import atomic_write_text

    out = Path(args.out)
    atomic_write_text(out.with_suffix(".json"), json.dumps({**meta, "seeds": args.seeds,
                                                            "results": res},
                                                           indent=1) + "\n")
    atomic_write_text(out, markdown(args, res, meta))
    add_to_index(out)
    for name, r in res.items():
        if "skipped" in r:
            print(f"{name}: skipped ({r['skipped']})")
        else:
            print(f"{name}: " + ", ".join(f"{w} {100 * a:.1f} %" for w, a in
                                          r["accuracy"].items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
