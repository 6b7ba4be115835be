"""Imaging Φ speed: 1558 taxels → 357 × 334 images, against scipy's griddata per frame.

    python benchmarks/imaging.py [--frames 500] [--griddata-frames 10] \
        [--json docs/imaging-benchmark.json]

Runs on one core (BLAS/OpenMP threads pinned to 1 before numpy loads). For each
method and pixel size it reports the operator's build time, frames per second
applying it one frame at a time (each image dropped before the next, as in a
stream) and in batches of 100, and — for linear at
1 mm — ``scipy.interpolate.griddata(method="linear")`` called per frame on the
same frames in the same run, with the speed-up and the largest difference
between the two images on the pixels both fill. Goals (issue 3): ≥ 100× faster
than griddata per frame, ≥ 2000 frames/s on one core.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

GOAL_SPEEDUP = 100.0
GOAL_FPS = 2000.0


def _rate(fn, n_frames: int, min_seconds: float = 1.0) -> float:
    """Frames per second of ``fn()`` that processes ``n_frames`` per call (best of runs)."""
    fn()  # warm-up
    best = float("inf")
    spent, runs = 0.0, 0
    while spent < min_seconds or runs < 3:
        start = time.perf_counter()
        fn()
        dt = time.perf_counter() - start
        best = min(best, dt)
        spent += dt
        runs += 1
    return n_frames / best


def _stream(imager, frames) -> None:
    """One frame at a time, each image used and dropped before the next (as a live
    stream does); keeping hundreds of 1 mm images alive would time the allocator."""
    for frame in frames:
        image = imager.apply(frame)
        del image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500,
                        help="frames per single-frame timing run")
    parser.add_argument("--griddata-frames", type=int, default=10)
    parser.add_argument("--json", dest="json_out")
    args = parser.parse_args()

    from scipy.interpolate import griddata

    from tactbench.data.imaging import Imager
    from tactbench.datasets.forearm import cyskin_forearm

    layout = cyskin_forearm()
    rng = np.random.default_rng(0)
    frames = rng.uniform(0, 1, (max(args.frames, 100), layout.n_taxels)).astype(np.float32)
    rows = []
    print(f"{'method':<9}{'px mm':>6}{'image':>11}{'build s':>9}{'single f/s':>12}"
          f"{'batch f/s':>11}")
    for method in ("linear", "gaussian"):
        for pixel in (1.0, 4.0, 5.0):
            start = time.perf_counter()
            imager = Imager(layout, pixel_mm=pixel, method=method)
            build = time.perf_counter() - start
            single = _rate(lambda: _stream(imager, frames[:args.frames]), args.frames)
            batch = _rate(lambda: imager.apply(frames[:100]), 100)
            h, w = imager.shape
            rows.append({"method": method, "pixel_mm": pixel, "shape": [h, w],
                         "build_s": build, "single_fps": single, "batch_fps": batch})
            print(f"{method:<9}{pixel:>6g}{f'{h}×{w}':>11}{build:>9.3f}{single:>12.0f}"
                  f"{batch:>11.0f}")

    # the reference: griddata per frame (a Delaunay triangulation each call)
    imager = Imager(layout, pixel_mm=1.0, method="linear")
    h, w = imager.shape
    x0, y0, _, _ = layout.bounds
    gx, gy = np.meshgrid(x0 + np.arange(w) + 0.5, y0 + np.arange(h) + 0.5)
    n = args.griddata_frames
    start = time.perf_counter()
    ref = [griddata(layout.positions, f, (gx, gy), method="linear", fill_value=0.0)
           for f in frames[:n]]
    grid_fps = n / (time.perf_counter() - start)
    ours = imager.apply(frames[:n])
    both = (imager.coverage >= 1) & np.all([r != 0 for r in ref], axis=0)
    diff = max(float(np.abs(o[both] - r[both]).max()) for o, r in zip(ours, ref))
    lin1 = next(r for r in rows if r["method"] == "linear" and r["pixel_mm"] == 1.0)
    speed_single = lin1["single_fps"] / grid_fps
    speed_batch = lin1["batch_fps"] / grid_fps
    print(f"\ngriddata(linear) per frame at 1 mm: {grid_fps:.1f} frames/s")
    print(f"speed-up, Φ linear 1 mm: {speed_single:.0f}× one frame at a time, "
          f"{speed_batch:.0f}× in batches (goal ≥ {GOAL_SPEEDUP:.0f}×)")
    print(f"frames/s, Φ linear 1 mm: {lin1['single_fps']:.0f} single, "
          f"{lin1['batch_fps']:.0f} batched (goal ≥ {GOAL_FPS:.0f})")
    print(f"largest |Φ − griddata| on pixels both fill: {diff:.2e}")
    doc = {
        "benchmark": "imaging", "command": " ".join(["python"] + sys.argv),
        "machine": platform.platform(), "cpus": os.cpu_count(), "threads": 1,
        "python": sys.version.split()[0], "numpy": np.__version__,
        "date": time.strftime("%Y-%m-%d"),
        "layout": {"taxels": layout.n_taxels, "bounds_mm": list(layout.bounds)},
        "rows": rows,
        "griddata_fps_1mm": grid_fps, "speedup_single": speed_single,
        "speedup_batch": speed_batch, "max_abs_difference_vs_griddata": diff,
        "goals": {"speedup": GOAL_SPEEDUP, "fps": GOAL_FPS},
    }
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump(doc, fh, indent=2)
            fh.write("\n")


if __name__ == "__main__":
    main()
