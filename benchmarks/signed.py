"""Signed readings (each recording minus its own baseline): does the default CNN learn on
both encodings of such an own-data folder?

    python benchmarks/signed.py [--seeds 0-2] [--out docs/benchmarks/signed.json]

The folder is made from real data (``../shared/data/cyskin-fingers``,
``TACTBENCH_SHARED_DATA``: 373 CySkin recordings, 6 classes, 30 frames at 10 Hz, 716
taxels): each recording becomes a ``(T, 60, 12)`` grid — one row per CySkin module, in
the file's order, one column per taxel of the module (no layout of these modules was
published, so the grid is not the skin's geometry; the 4 absent taxels read 0) — minus
its own baseline, the per-taxel median of its first :data:`BASELINE_FRAMES` frames, so
about a third of the readings are negative. It is written as ``ROOT/<class>/<name>.npy``
(the own-data folder format, ``docs/own-data.md``) in a temporary folder.

Two readings of the same folder, each with the default cells (encoders ``raw`` and
``farneback``, ``small-cnn-lstm``, L = 5, the quick profile, the study's random split
``paper``, every window voting), one run per seed:

- ``default``: ``folder:path=ROOT`` — negative readings clipped at 0 (since issue 40;
  the same normalisation as ``vmin=0``, checked here);
- ``signed``: ``folder:path=ROOT,vmin=LO`` with ``LO`` the data's minimum — the range
  mapped onto [0, 1] with its sign, the default before.

Per cell it records test accuracy, accuracy on the training windows, what guessing gives
(``chance_accuracy``) and the learning mark (``tactbench.runner``'s ``learning``), and
per reading the mean Farnebäck flow of every frame pair after the first (px/frame): the
mechanism (a dip below the baseline is image structure the flow follows). Writes
``docs/benchmarks/signed.json`` with the command, machine and date. Exits 2 when the real
data is absent.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("TACTBENCH_SHARED_DATA", REPO.parent / "shared" / "data"))
#: Frames whose per-taxel median is each recording's baseline.
BASELINE_FRAMES = 3
#: Taxels per CySkin module (the id is ``module * 16 + index``, index 0–11).
MODULE_TAXELS = 12
ENCODERS = ("raw", "farneback")
CLASSIFIER = "small-cnn-lstm"
L = 5


def make_signed_folder(source: Path, root: Path, *, limit: int | None = None) -> dict:
    """Write each CySkin recording of ``source`` minus its baseline as a ``(T, modules,
    12)`` grid under ``root/<class>/``; ``limit`` recordings per class at most. Returns
    the folder's size and how many readings are negative."""
    from tactbench.datasets.cyskin_text import read_cyskin_folder

    ds = read_cyskin_folder(source)
    ids = ds.samples[0].recording.taxel_ids
    modules = list(dict.fromkeys((ids // 16).tolist()))
    row = np.array([modules.index(m) for m in (ids // 16).tolist()])
    written: dict[int, int] = {}
    negative = total = 0
    for sample in ds.samples:
        if limit is not None and written.get(sample.label, 0) >= limit:
            continue
        values = sample.recording.values.astype(np.float64)
        if not np.array_equal(sample.recording.taxel_ids, ids):
            raise SystemExit(f"{sample.source}: another set of taxels than the first file")
        grid = np.zeros((len(values), len(modules), MODULE_TAXELS))
        grid[:, row, ids % 16] = values
        signed = (grid - np.median(grid[:BASELINE_FRAMES], axis=0)).astype(np.float32)
        folder = root / ds.classes[sample.label]
        folder.mkdir(parents=True, exist_ok=True)
        np.save(folder / f"{Path(sample.source).stem}.npy", signed)
        written[sample.label] = written.get(sample.label, 0) + 1
        negative += int((signed < 0).sum())
        total += signed.size
    return {"recordings": sum(written.values()), "classes": list(ds.classes),
            "grid": [len(modules), MODULE_TAXELS], "negative_share": negative / total}


def readings(root: Path) -> dict[str, str]:
    """The two readings of the folder: name → dataset spec (see the module docstring)."""
    from tactbench.datasets.folder import read_folder

    lo = min(float(np.load(p).min()) for p in root.rglob("*.npy"))
    logging.getLogger("tactbench.datasets").setLevel(logging.ERROR)  # the note is known
    default, clipped = read_folder(root), read_folder(root, vmin=0)
    if default.normalisation != clipped.normalisation:
        raise SystemExit(f"the default reading ({default.normalisation}) is not vmin=0's "
                         f"({clipped.normalisation})")
    return {"default": f"folder:path={root}", "signed": f"folder:path={root},vmin={lo!r}"}


def mean_flow(spec: str, pixel_mm: float = 5.0) -> dict:
    """Mean Farnebäck flow (px/frame) of every frame pair after each recording's first,
    and the level a reading of 0 images at."""
    from tactbench.datasets.loading import load_dataset
    from tactbench.plugins import load_registry

    ds = load_dataset(spec)
    encoder = load_registry().build("encoder", "farneback")
    flows = []
    for images in ds.images(pixel_mm):
        f = encoder.flow(images[:-1], images[1:])
        flows.append(float(np.hypot(f[..., 0], f[..., 1]).mean()))
    rest = float(ds.normalise(np.zeros((1, ds.n_taxels), np.float32)).mean())
    return {"normalisation": ds.normalisation.spec, "rest_level": rest,
            "mean_flow_px_per_frame": float(np.mean(flows))}


def run_cells(spec: str, seeds: list[int], work: Path, name: str) -> list[dict]:
    from tactbench.runner import EncodingCache, Scene, run

    scene = Scene(dataset=spec, encoders=list(ENCODERS), classifiers=[CLASSIFIER], L=[L],
                  seeds=seeds, split="paper", test_window="vote", threads=1,
                  out=str(work / name))
    result = run(scene, progress=False, cache=EncodingCache(work / "cache"))
    keep = ("encoder", "seed", "accuracy", "train_accuracy", "chance_accuracy",
            "train_chance", "learning", "n_test", "n_train", "train_s", "status")
    rows = [{**{k: r.get(k) for k in keep},
             **{k: (r.get("fit") or {}).get(k) for k in ("final_loss", "train_cpu_seconds")}}
            for r in result.rows]
    bad = [r for r in result.rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"{name}: {len(bad)} cell(s) failed: {bad[0].get('error')}")
    return sorted(rows, key=lambda r: (r["encoder"], r["seed"]))


def summary(rows: list[dict]) -> dict:
    out = {}
    for enc in ENCODERS:
        mine = [r for r in rows if r["encoder"] == enc]
        out[enc] = {"accuracy": float(np.mean([r["accuracy"] for r in mine])),
                    "train_accuracy": float(np.mean([r["train_accuracy"] for r in mine])),
                    "chance_accuracy": float(np.mean([r["chance_accuracy"] for r in mine])),
                    "learned": sum(r["learning"] == "learned" for r in mine),
                    "cells": len(mine)}
    return out


def measure(seeds: list[int], work: Path) -> dict:
    made = make_signed_folder(SHARED / "cyskin-fingers", work / "folder")
    specs = readings(work / "folder")
    out: dict = {"folder": made, "readings": {}}
    for name, spec in specs.items():
        t0, c0 = time.perf_counter(), time.process_time()
        rows = run_cells(spec, seeds, work, name)
        out["readings"][name] = {"spec": spec.replace(str(work), "TMP"),
                                 **mean_flow(spec), "summary": summary(rows), "cells": rows,
                                 "wall_s": time.perf_counter() - t0}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-2", help="seeds, e.g. 0-2")
    ap.add_argument("--out", default=str(REPO / "docs" / "benchmarks" / "signed.json"))
    ap.add_argument("--work", help="folder for the runs (default: a temporary one)")
    args = ap.parse_args(argv)
    if not (SHARED / "cyskin-fingers").is_dir():
        print(f"{SHARED / 'cyskin-fingers'} is absent: this benchmark needs ../shared/data "
              f"(see its README)", file=sys.stderr)
        return 2
    from tactbench.machine import machine
    from tactbench.paths import atomic_write_text
    from tactbench.runner import parse_seeds

    seeds = parse_seeds(args.seeds.split(","))
    t0 = time.perf_counter()
    if args.work:
        res = measure(seeds, Path(args.work))
    else:
        with tempfile.TemporaryDirectory(prefix="tactbench-signed-") as tmp:
            res = measure(seeds, Path(tmp))
    doc = {"command": f"python benchmarks/signed.py --seeds {args.seeds}",
           "machine": machine(), "python": platform.python_version(),
           "date": datetime.now(timezone.utc).strftime("%Y-%m-%d"),
           "wall_s": time.perf_counter() - t0, "seeds": seeds,
           "cells": f"{'/'.join(ENCODERS)} × {CLASSIFIER} L={L}, quick profile, split "
                    f"paper, test window vote", **res}
    atomic_write_text(Path(args.out), json.dumps(doc, indent=1) + "\n")
    for name, r in res["readings"].items():
        said = ", ".join(f"{enc} {100 * s['accuracy']:.1f} % (train "
                         f"{100 * s['train_accuracy']:.1f} %, chance "
                         f"{100 * s['chance_accuracy']:.1f} %, learned {s['learned']}/"
                         f"{s['cells']})" for enc, s in r["summary"].items())
        print(f"{name}: {said}; rest at {r['rest_level']:.2f}, mean flow "
              f"{r['mean_flow_px_per_frame']:.4f} px/frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
