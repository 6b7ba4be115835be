"""Each stage of the main job against a bare loop of the same work (issue 36).

    python benchmarks/bare_loops.py [--out docs/benchmarks/bare-loops.json] [--recordings 20]

On one thread, from the simulator's default data set (made once, cached):

- **farneback**: the registered encoder on recordings imaged at the quick profile's
  5 mm against a bare ``cv2.calcOpticalFlowFarneback`` loop over the same uint8 frames
  with the same parameters (the encoder also pads each frame by its ``margin``, computes
  magnitude and angle channels and checks its output);
- **training**: one optimiser step of the quick profile's ``small-cnn-lstm`` network on a
  batch of prepared windows (a bare torch loop: forward, loss, backward, AdamW), against
  the seconds per step a committed cell of docs/results/study-quick spent in its fit.

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/benchmarks/bare-loops.json")
    parser.add_argument("--recordings", type=int, default=20)
    args = parser.parse_args()
    doc = {"benchmark": "bare-loops", "command": "python " + " ".join(sys.argv),
           "farneback": farneback(args.recordings), "training": training(),
           "machine": platform.platform(), "python": sys.version.split()[0],
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    Path(args.out).write_text(json.dumps(doc, indent=2) + "\n")
    print(json.dumps({k: doc[k] for k in ("farneback", "training")}, indent=1))


if __name__ == "__main__":
    main()
