"""How tactbench's cost grows with the dataset: peak memory, wall time and cache disk.

    python benchmarks/scale.py [--users 4 8 16 38 76 152] [--pixel-mm 5 1]
                               [--max-users-1mm 38] [--precision float32 uint8]
                               [--classifier logreg] [--out docs/scale]

Each point is one ``tactbench run`` in a fresh process with an empty cache: the simulated
forearm with N users (``synthetic-forearm:users=N``; 38 is the study's size, more users are
generated the same way), imaged at the given pixel size, encoded with Farnebäck and one
training cell (``--classifier``, L = 5, seed 0). Measured per point:

- peak resident memory of the run's process (``wait4``'s ``ru_maxrss``), and the step that
  set it as the run's rows report it;
- wall time of the whole run, and of its parts as the rows report them (imaging, encoding,
  training);
- disk used by the encoding cache (and by the simulator's dataset cache).

Goal (issue 13): memory flat in the dataset's size, time linear. Writes ``scale.json``,
``scale.csv`` and ``scale.png`` under ``--out``. Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def folder_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def run_point(users: int, pixel_mm: float, precision: str, classifier: str,
              extra: list[str]) -> dict:
    """One ``tactbench run`` in a fresh process and cache; its costs."""
    work = Path(tempfile.mkdtemp(prefix="tactbench-scale-"))
    cache, out = work / "cache", work / "out"
    env = {**os.environ, "TACTBENCH_CACHE": str(cache)}
    argv = [sys.executable, "-m", "tactbench", "run",
            "--dataset", f"synthetic-forearm:users={users}", "--encoder", "farneback",
            "--classifier", classifier, "-L", "5", "--seed", "0",
            "--pixel-mm", f"{pixel_mm:g}", "--precision", precision,
            "--out", str(out), "--no-plots", "--json", *extra]
    start = time.perf_counter()
    # output to files, not pipes: nothing reads a pipe while wait4 waits
    with open(work / "stdout", "w") as so, open(work / "stderr", "w") as se:
        proc = subprocess.Popen(argv, env=env, stdout=so, stderr=se)
        # wait4 gives this child's own rusage (ru_maxrss in KiB on Linux)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    stderr = (work / "stderr").read_text()
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        shutil.rmtree(work, ignore_errors=True)
        sys.exit(f"tactbench run failed ({code}) at users={users}, {pixel_mm} mm:\n"
                 f"{stderr[-3000:]}")
    rows = json.loads((out / "results.json").read_text())["rows"]
    row = rows[0]
    encodings = cache / "encodings"
    metas = [json.loads(p.read_text()) for p in encodings.glob("*/meta.json")]
    meta = metas[0] if metas else {}
    offsets = list(encodings.glob("*/offsets.npy"))
    samples = None
    if offsets:
        import numpy as np

        samples = int(len(np.load(offsets[0])) - 1)
    point = {
        "users": users, "pixel_mm": pixel_mm, "precision": precision,
        "classifier": classifier,
        "samples": samples,
        "frames": int(meta.get("frames", 0)),
        "frame_shape": meta.get("frame_shape"),
        "wall_s": wall,
        "peak_rss_mb": usage.ru_maxrss / 1024.0,
        "peak_step": row.get("peak_step"),
        "imaging_s": float(meta.get("imaging_seconds", 0.0)),
        "encode_s": float(meta.get("encode_seconds", 0.0)),
        "train_s": float(row.get("train_s", 0.0)),
        "cell_peak_rss_mb": row.get("peak_rss_mb"),
        "cache_bytes": folder_bytes(encodings) if encodings.exists() else 0,
        "dataset_cache_bytes": folder_bytes(cache) - (folder_bytes(encodings)
                                                       if encodings.exists() else 0),
        "accuracy": row.get("accuracy"),
        "n_train_windows": row.get("n_train_windows"),
    }
    shutil.rmtree(work, ignore_errors=True)
    return point


def plot(points: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    series: dict[tuple, list[dict]] = {}
    for p in points:
        series.setdefault((p["pixel_mm"], p["precision"]), []).append(p)
    for (mm, prec), pts in sorted(series.items()):
        pts = sorted(pts, key=lambda p: p["users"])
        users = [p["users"] for p in pts]
        label = f"{mm:g} mm, {prec}"
        axes[0].plot(users, [p["peak_rss_mb"] / 1024 for p in pts], "o-", label=label)
        axes[1].plot(users, [p["wall_s"] / 60 for p in pts], "o-", label=label)
        axes[2].plot(users, [p["cache_bytes"] / 2 ** 30 for p in pts], "o-", label=label)
    for ax, title in zip(axes, ("peak resident memory (GiB)", "wall time (min)",
                                "encoding cache on disk (GiB)")):
        ax.set_xlabel("simulated users (38 = the study's size)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].axhline(4, color="grey", ls=":", lw=1)
    axes[0].legend(fontsize=8)
    fig.suptitle("tactbench run: farneback + one training cell, L = 5, fresh cache")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--users", type=int, nargs="+", default=[4, 8, 16, 38, 76, 152])
    parser.add_argument("--pixel-mm", type=float, nargs="+", default=[5.0, 1.0])
    parser.add_argument("--max-users-1mm", type=int, default=38,
                        help="largest user count run below 2 mm (time grows ~25× at 1 mm)")
    parser.add_argument("--precision", nargs="+", default=["float32", "uint8"])
    parser.add_argument("--classifier", default="logreg")
    parser.add_argument("--out", default="docs/scale")
    parser.add_argument("extra", nargs="*", help="more arguments for tactbench run")
    args = parser.parse_args()

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    points = []
    for mm in args.pixel_mm:
        for precision in args.precision:
            for users in args.users:
                if mm < 2 and users > args.max_users_1mm:
                    continue
                point = run_point(users, mm, precision, args.classifier, args.extra)
                points.append(point)
                print(f"{mm:g} mm {precision:8s} users {users:4d}: "
                      f"peak {point['peak_rss_mb']:7.0f} MB ({point['peak_step']}), "
                      f"{point['wall_s']:7.1f} s, cache {point['cache_bytes'] / 2**20:8.1f} MiB",
                      flush=True)
                (out / "scale.json").write_text(json.dumps({
                    "benchmark": "scale", "command": " ".join(["python", *sys.argv]),
                    "machine": platform.platform(), "cpus": os.cpu_count(),
                    "python": platform.python_version(),
                    "date": time.strftime("%Y-%m-%d"), "points": points}, indent=2))
    with open(out / "scale.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(points[0]))
        writer.writeheader()
        writer.writerows(points)
    plot(points, out / "scale.png")


if __name__ == "__main__":
    main()
