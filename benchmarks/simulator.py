"""The gesture simulator: generation time, and what its classes look like.

    python benchmarks/simulator.py [--users 38] [--version 2] [--json docs/simulator-stats.json]

Generates ``synthetic-forearm`` (no cache, one process; ``--version 1`` the first
simulator) and reports, each recording taken over its contact (from the first frame whose
total pressure is 10 % of its range above the quietest frame to the one before the last
that is 50 % above it: the hold, before the release; version 2's recordings have a lead-in and a tail without
contact around it):

- generation time (goal, issue 3: the default 1900 samples in ≤ 60 s on one core);
- per class: frames per sample, mean total pressure, time for the total
  pressure to settle (first frame after which it stays within 10 % of its
  final value), how far the pressure centroid moves round the arm (x) and
  along it (y) after the first 0.3 s;
- trivial cues: for each of length, mean/final total pressure, contact area
  and centroid, the accuracy of a one-feature Gaussian classifier trained on
  half of the users and tested on the other half (chance: 0.20). A value near
  1 would mean a class is given away by that cue alone.

These numbers describe the data; they are not tuned toward any result.
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

GOAL_S = 60.0


def one_feature_accuracy(x: np.ndarray, y: np.ndarray, users: np.ndarray) -> float:
    classes = np.unique(y)
    accs = []
    for fold in (0, 1):
        train, test = users % 2 != fold, users % 2 == fold
        mu = np.array([x[train & (y == c)].mean() for c in classes])
        sd = np.array([x[train & (y == c)].std() + 1e-9 for c in classes])
        ll = -0.5 * ((x[test, None] - mu) / sd) ** 2 - np.log(sd)
        accs.append(float((classes[ll.argmax(1)] == y[test]).mean()))
    return float(np.mean(accs))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--users", type=int, default=38)
    parser.add_argument("--version", type=int, default=2)
    parser.add_argument("--json", dest="json_out")
    args = parser.parse_args()

    from tactbench.datasets.synthetic_forearm import generate

    start = time.perf_counter()
    cpu0 = time.process_time()
    ds = generate(users=args.users, version=args.version)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu0
    print(f"generated {len(ds)} samples in {wall:.1f} s wall, {cpu:.1f} s CPU "
          f"(goal ≤ {GOAL_S:.0f} s for 1900 on one core)")
    feats, timing = sample_features(ds)
    per = class_rows(ds, feats, timing)
    users = np.array([int(u[1:]) for u in ds.users])
    cues = {k: one_feature_accuracy(np.array(v, dtype=float), ds.labels, users)
            for k, v in feats.items()}
    print("\none-feature accuracy, users split in halves (chance 0.20):")
    for k, acc in cues.items():
        print(f"  {k:<22}{acc:.2f}")
    doc = {"benchmark": "simulator", "command": " ".join(["python"] + sys.argv),
           "machine": platform.platform(), "cpus": os.cpu_count(), "threads": 1,
           "date": time.strftime("%Y-%m-%d"), "samples": len(ds), "version": args.version,
           "content_hash": ds.content_hash(),
           "generation_wall_s": wall, "generation_cpu_s": cpu, "goal_s": GOAL_S,
           "classes": per, "one_feature_accuracy": cues}
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump(doc, fh, indent=2)
            fh.write("\n")


def sample_features(ds) -> tuple[dict[str, list[float]], dict[str, np.ndarray]]:
    """Each sample's one-number cues (name → values) and its timing of contact (lead-in
    and contact frames, settling seconds, centroid movement in x and y)."""
    from tactbench.datasets.synthetic import CIRCUMFERENCE_MM, TOP_X

    vec = ds.vectors()
    xy = ds.layout.positions
    xu = (xy[:, 0] - TOP_X + CIRCUMFERENCE_MM / 2) % CIRCUMFERENCE_MM  # unwrapped round the top
    feats: dict[str, list[float]] = {k: [] for k in (
        "length", "mean total pressure", "final total pressure", "final contact area",
        "centroid x", "centroid y", "peak total pressure", "lead-in frames",
        "frames in contact")}
    settle, move_x, move_y, lead, contact_frames = [], [], [], [], []
    for s, whole in zip(ds, vec):
        ts = s.recording.timestamps
        total = whole.sum(1)
        rise = total - total.min()
        contact = np.flatnonzero(rise > 0.1 * max(np.ptp(total), 1e-9))
        first, end = (int(contact[0]), int(contact[-1])) if len(contact) else (0, len(total) - 1)
        held = np.flatnonzero(rise >= 0.5 * max(np.ptp(total), 1e-9))
        # the frame before the last at half the range: the hold, before the release
        last = max(first, int(held[-1]) - 1) if len(held) else end
        lead.append(first)
        contact_frames.append(end - first + 1)
        feats["lead-in frames"].append(float(first))
        feats["frames in contact"].append(float(end - first + 1))
        feats["peak total pressure"].append(float(total.max()))
        v, ts, total = whole[first:last + 1], ts[first:last + 1], total[first:last + 1]
        final = total[-1]
        off = np.abs(total - final) > 0.1 * max(final, 1e-9)
        settle.append(float(ts[np.nonzero(off)[0][-1] + 1] - ts[0]) if off.any() else 0.0)
        w = v.sum(1, keepdims=True) + 1e-9
        cx, cy = (v * xu).sum(1) / w[:, 0], (v * xy[:, 1]).sum(1) / w[:, 0]
        late = ts - ts[0] >= 0.3
        move_x.append(float(np.ptp(cx[late])) if late.sum() > 1 else 0.0)
        move_y.append(float(np.ptp(cy[late])) if late.sum() > 1 else 0.0)
        feats["length"].append(len(whole))
        feats["mean total pressure"].append(float(total.mean()))
        feats["final total pressure"].append(float(final))
        feats["final contact area"].append(float((v[-1] > 0.05).sum()))
        feats["centroid x"].append(float((v.sum(0) * xu).sum() / (v.sum() + 1e-9)))
        feats["centroid y"].append(float((v.sum(0) * xy[:, 1]).sum() / (v.sum() + 1e-9)))
    timing = {"settle": settle, "move_x": move_x, "move_y": move_y, "lead": lead,
              "contact": contact_frames}
    return feats, {k: np.array(v) for k, v in timing.items()}


def class_rows(ds, feats: dict[str, list[float]], timing: dict[str, np.ndarray]
               ) -> list[dict]:
    """One row a class (medians of its samples' lengths and timing), printed as a table."""
    y, lengths, per = ds.labels, ds.lengths(), []
    settle, move_x, move_y = timing["settle"], timing["move_x"], timing["move_y"]
    print(f"\n{'class':<9}{'frames (med)':>13}{'settle s (med)':>15}{'Δx mm (med)':>13}"
          f"{'Δy mm (med)':>13}{'total (mean)':>14}")
    for c, name in enumerate(ds.classes):
        m = y == c
        row = {"class": name, "samples": int(m.sum()),
               "frames_median": float(np.median(lengths[m])),
               "frames_min": int(lengths[m].min()), "frames_max": int(lengths[m].max()),
               "lead_in_frames_median": float(np.median(timing["lead"][m])),
               "contact_frames_median": float(np.median(timing["contact"][m])),
               "settle_s_median": float(np.median(settle[m])),
               "centroid_move_x_mm_median": float(np.median(move_x[m])),
               "centroid_move_y_mm_median": float(np.median(move_y[m])),
               "mean_total_pressure": float(np.mean(np.array(feats["mean total pressure"])[m]))}
        per.append(row)
        print(f"{name:<9}{row['frames_median']:>13g}{row['settle_s_median']:>15.2f}"
              f"{row['centroid_move_x_mm_median']:>13.1f}{row['centroid_move_y_mm_median']:>13.1f}"
              f"{row['mean_total_pressure']:>14.1f}")
    return per


if __name__ == "__main__":
    main()
