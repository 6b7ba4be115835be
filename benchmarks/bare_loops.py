"""Each stage of the main job against a bare loop of the same work (issue 36).

    python benchmarks/bare_loops.py [--out docs/benchmarks/bare-loops.json] [--recordings 20]

On one thread, from the simulator's default data set (made once, cached):

- **farneback**: the registered encoder on recordings imaged at the quick profile's
  5 mm against a bare ``cv2.calcOpticalFlowFarneback`` loop over the same uint8 frames
  with the same parameters (the encoder also pads each frame by its ``margin``, computes
  magnitude and angle channels and checks its output);
- **training**: one optimiser step of the quick profile's ``small-cnn-lstm`` network on a
  batch of prepared windows (a bare torch loop: forward, loss, backward, AdamW), against
  the seconds per step a committed cell of docs/results/study-quick spent in its fit;
- **side by side**: the same bare loop alone, and in two processes at once (one per
  core, as the main job trains its cells), alternated twice: what two cells on the two
  cores of one machine cost each other, with no tactbench code in the loop.

Median of repeats; the machine and date are recorded.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import tactbench  # noqa: F401 — first: it pins the CPU kernels
from tactbench.classifiers.costs import median_seconds

REPO = Path(__file__).resolve().parents[1]


def farneback(recordings: int) -> dict:
    """ms per frame: the encoder against the bare cv2 loop."""
    import cv2
    import numpy as np

    from tactbench.datasets.loading import load_dataset
    from tactbench.plugins import load_registry

    cv2.setNumThreads(1)
    registry = load_registry()
    data = load_dataset("synthetic-forearm", registry=registry)
    step = max(1, len(data.lengths()) // recordings)
    images = data.images(5.0, "linear", indices=range(0, len(data.lengths()), step))
    frames = sum(len(s) for s in images)
    enc = registry.build("encoder", "farneback")
    o = enc.options()
    args = (o["pyr_scale"], o["levels"], o["winsize"], o["iterations"], o["poly_n"],
            o["poly_sigma"], 0)
    u8 = [(np.clip(s, 0, 1) * 255).astype(np.uint8) for s in images]

    def bare() -> None:
        for seq in u8:
            prev = np.zeros_like(seq[0])
            for frame in seq:
                cv2.calcOpticalFlowFarneback(prev, frame, None, *args)
                prev = frame

    encoder = median_seconds(lambda: [enc.encode(s) for s in images], 3) / frames
    loop = median_seconds(bare, 3) / frames
    return {"frames": frames, "frame_shape": list(images[0].shape[1:]),
            "encoder_ms_per_frame": 1e3 * encoder, "bare_cv2_ms_per_frame": 1e3 * loop,
            "ratio": encoder / loop, "options": o}


def training() -> dict:
    """ms per optimiser step: a bare torch loop against the committed cells' fits."""
    import torch

    from tactbench.classifiers.costs import _step_seconds  # the bare loop plan times
    from tactbench.plugins import load_registry

    torch.set_num_threads(1)
    rows = [json.loads(p.read_text())
            for p in sorted((REPO / "docs/results/study-quick/cells").glob("*.json"))]
    spec = rows[0]["classifier"]
    clf = load_registry().build("classifier", spec, classes=len(rows[0]["classes"]))
    clf.L = rows[0]["L"]
    out = {"classifier": spec}
    for channels, encoder in ((1, "raw"), (3, "farneback")):
        net = clf._build_net((channels, 72, 67), len(rows[0]["classes"]), pretrained=False)
        prepared = net.prepare(torch.zeros((1, channels, 72, 67))).shape[1:]
        bare = _step_seconds(clf, net, prepared, clf.L, len(rows[0]["classes"]))
        fits = [r["fit"] for r in rows if r["encoder"] == encoder]
        in_cell = statistics.median(f["train_seconds"] / f["steps"] for f in fits)
        out[encoder] = {"bare_ms_per_step": 1e3 * bare, "cell_ms_per_step": 1e3 * in_cell,
                        "ratio": in_cell / bare,
                        "cells_trained_side_by_side": True}
    return out


def _bare_steps(channels: int, steps: int = 60) -> float:
    """Median ms of ``steps`` optimiser steps of the committed cells' network, one thread
    (the loop of :func:`training`, timed over more steps so two processes overlap)."""
    import torch

    from tactbench.classifiers.training import make_optimizer
    from tactbench.plugins import load_registry

    torch.set_num_threads(1)
    row = json.loads(next(iter(sorted((REPO / "docs/results/study-quick/cells")
                                      .glob("*.json")))).read_text())
    clf = load_registry().build("classifier", row["classifier"], classes=len(row["classes"]))
    clf.L = row["L"]
    net = clf._build_net((channels, 72, 67), len(row["classes"]), pretrained=False)
    net.train()
    prepared = net.prepare(torch.zeros((1, channels, 72, 67))).shape[1:]
    opt = make_optimizer(clf.optimizer, net.parameters(), lr=clf.lr, momentum=clf.momentum,
                         weight_decay=clf.weight_decay)
    x = torch.rand((clf.batch_size, row["L"], *prepared))
    y = torch.randint(0, len(row["classes"]), (clf.batch_size,))
    times = []
    for i in range(steps + 5):
        t0 = time.perf_counter()
        opt.zero_grad(set_to_none=True)
        torch.nn.functional.cross_entropy(net(x), y).backward()
        opt.step()
        if i >= 5:  # warm-up steps untimed
            times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def side_by_side(channels: int = 3, rounds: int = 2) -> dict:
    """The bare loop alone and two of it at once (two processes), alternated."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    alone, pairs = [], []
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(_bare_steps, [channels, channels], [5, 5]))  # start both workers
        for _ in range(rounds):
            alone.append(pool.submit(_bare_steps, channels).result())
            pairs += list(pool.map(_bare_steps, [channels, channels]))
    return {"channels": channels, "alone_ms_per_step": alone,
            "side_by_side_ms_per_step": pairs,
            "ratio": statistics.median(pairs) / statistics.median(alone)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/benchmarks/bare-loops.json")
    parser.add_argument("--recordings", type=int, default=20)
    args = parser.parse_args()
    doc = {"benchmark": "bare-loops", "command": "python " + " ".join(sys.argv),
           "farneback": farneback(args.recordings), "training": training(),
           "side_by_side": side_by_side(),
           "machine": platform.platform(), "python": sys.version.split()[0],
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    Path(args.out).write_text(json.dumps(doc, indent=2) + "\n")
    print(json.dumps({k: doc[k] for k in ("farneback", "training", "side_by_side")},
                     indent=1))


if __name__ == "__main__":
    main()
