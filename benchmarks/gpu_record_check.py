"""GPU check of a run's record and of the device in a cell's identity (issue 50).

On a machine with CUDA: the same tiny cell trained with ``--device cpu``, ``cuda`` and
``auto``; each run's record (``OUT/run-record.json``) must say the device kind it
resolved and, for CUDA, a worker owning ``cuda:0``; the CUDA cell's key must differ from
the CPU cell's (a GPU cell never stands in for a CPU one) and ``auto`` must be the CUDA
cell. Then, with ``--paper``, one paper-profile ``cnn-lstm`` cell (six training steps of
EfficientNet-B0 at 224 px, batch 16 × 5 frames) on the GPU, in this process, with its
device memory peak (``torch.cuda.max_memory_allocated``) and the process's peak RSS.

    python benchmarks/gpu_record_check.py --out DIR [--paper]

Prints one JSON document and writes it to ``DIR/gpu-record-check.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

TINY = dict(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
            classifiers=["small-cnn-lstm:epochs=1,windows_per_epoch=64,batch_size=16,"
                         "input_size=16"],
            L=[3], seeds=[0], pixel_mm=10.0, test_per_class=1, threads=1)
PAPER = dict(dataset="synthetic-forearm:users=4", encoders=["farneback"],
             classifiers=["cnn-lstm:epochs=1,windows_per_epoch=96"], L=[5], seeds=[0],
             profile="paper", threads=1, workers=1)


def one_run(fields: dict, out: Path) -> dict:
    """Run one scene into ``out``; its cell's key, status, device, and the run's record."""
    from tactbench.runner import Scene, read_record, run

    t0 = time.perf_counter()
    report = run(Scene(**fields, out=str(out)), progress=False, plots=False)
    [row] = report.rows
    record = read_record(out)
    return {"key": row["key"], "status": row["status"], "device": row.get("device"),
            "accuracy": row.get("accuracy"), "peak_rss_mb": row.get("peak_rss_mb"),
            "train_s": row.get("train_s"), "wall_s": round(time.perf_counter() - t0, 1),
            "error": row.get("error"),
            "record": {"compute": record.to_json()["compute"],
                       "workers": record.to_json()["workers"]}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--paper", action="store_true")
    args = ap.parse_args(argv)
    import tactbench  # noqa: F401 — first, so that it pins the CPU kernels before torch loads
    import torch

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc: dict = {"cuda": torch.cuda.is_available(),
                 "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
                 "torch": torch.__version__}
    runs = {dev: one_run({**TINY, "device": dev}, out / f"tiny-{dev}")
            for dev in ("cpu", "cuda", "auto")}
    doc["tiny"] = runs
    cpu, cuda, auto = runs["cpu"], runs["cuda"], runs["auto"]
    checks = {
        "cpu record says cpu": cpu["record"]["compute"]["device"] == "cpu",
        "cuda record says cuda": cuda["record"]["compute"]["device"] == "cuda",
        "cuda worker owns cuda:0": cuda["record"]["workers"]["devices"] == ["cuda:0"],
        "cuda key differs from cpu key": cuda["key"] != cpu["key"],
        "auto is the cuda cell": auto["key"] == cuda["key"],
        "every cell ok": all(r["status"] == "ok" for r in runs.values()),
    }
    if args.paper:
        torch.cuda.reset_peak_memory_stats()
        paper = one_run({**PAPER, "device": "cuda"}, out / "paper-cuda")
        paper["cuda_max_allocated_gib"] = round(torch.cuda.max_memory_allocated() / 2 ** 30, 2)
        paper["cuda_max_reserved_gib"] = round(torch.cuda.max_memory_reserved() / 2 ** 30, 2)
        doc["paper"] = paper
        checks["paper cell ok"] = paper["status"] == "ok"
    doc["checks"] = checks
    text = json.dumps(doc, indent=1, default=str)
    (out / "gpu-record-check.json").write_text(text + "\n")
    print(text)
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
