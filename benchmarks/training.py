"""Training throughput and the quick profile's budget.

Three measurements, on a synthetic gesture-like task made here (5 classes of
moving/settling Gaussian contacts, sequences of 5–27 frames of 60×70 px: the
size the runner's quick profile images at ~5 mm/px):

1. ``overhead``: windows per second of each classifier's ``fit`` at its quick
   profile sizes, against a bare torch loop (same network, same optimiser, same
   batches, tensors already resized in memory) in the same process. The
   toolkit's overhead (frame bank, normalisation statistics, progress, report)
   should stay ≤ 10 %.
2. ``quick``: one full quick-profile training of ``small-cnn-lstm`` on ~30 000
   windows of L = 5 (C = 1 and C = 3), seconds and test accuracy; the runner's
   goal is six of these (raw vs farneback × 3 seeds) plus data and encoding in
   ≤ 10 minutes on 2 cores.
3. ``paper-epoch`` (only with CUDA): one epoch of the paper profile
   (``cnn-lstm``, 224 px, SGD 1e-3, batch 16) on the GPU.

Usage::

    python benchmarks/training.py [--threads 2] [--out docs/benchmarks/training.json]
                                  [--skip quick] [--sequences 1750]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

GESTURES = ("grasp", "2h-grasp", "twist", "push", "pull")


def synthetic_sequences(n: int, *, channels: int = 1, height: int = 60, width: int = 70,
                        seed: int = 0) -> tuple[list[np.ndarray], np.ndarray]:
    """``n`` labelled sequences ``(T, C, H, W)`` float32 in [0, 1], T in 5..27.

    Classes differ in contact count, size and dynamics (grasp settles fast, twist
    slides across, pull slides along, push is one large fast-rising contact,
    2h-grasp has two hands), with random placement, amplitude and noise. With
    ``channels=3`` the extra channels are the absolute frame difference and its
    3×3 box-smoothed version: a cheap flow-like stand-in.
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    seqs, labels = [], np.arange(n) % len(GESTURES)
    rng.shuffle(labels)
    for label in labels:
        t_len = int(rng.integers(5, 28))
        t = np.arange(t_len, dtype=np.float32)[:, None]
        onset = rng.uniform(1.0, 4.0)
        if label == 0:  # grasp: 4 fingertips, settles within a few frames
            nb, sigma = 4, 3.0
            amp = np.clip((t + 1) / onset, 0, 1)
            vx, vy = 0.0, 0.0
        elif label == 1:  # two-hand grasp: 8 contacts in two groups
            nb, sigma = 8, 3.0
            amp = np.clip((t + 1) / onset, 0, 1)
            vx, vy = 0.0, 0.0
        elif label == 2:  # twist: fingertips slide across the arm
            nb, sigma = 4, 3.0
            amp = np.clip((t + 1) / onset, 0, 1)
            vx, vy = rng.choice([-1.0, 1.0]) * rng.uniform(0.6, 1.2), 0.0
        elif label == 3:  # push: one palm, fast rise
            nb, sigma = 1, 7.0
            amp = np.clip((t + 1) / (0.5 * onset), 0, 1)
            vx, vy = 0.0, 0.0
        else:  # pull: fingertips slide along the arm
            nb, sigma = 4, 3.0
            amp = np.clip((t + 1) / onset, 0, 1)
            vx, vy = 0.0, rng.choice([-1.0, 1.0]) * rng.uniform(0.6, 1.2)
        moving = np.minimum(t, onset + rng.uniform(3, 10))  # then the user holds still
        cx0 = rng.uniform(12, width - 12)
        cy0 = rng.uniform(12, height - 12)
        spread = 12.0 if label != 1 else 22.0
        bx = cx0 + rng.normal(0, spread / 2, nb)
        by = cy0 + rng.normal(0, spread / 3, nb)
        if label == 1:
            bx[nb // 2:] += rng.choice([-1, 1]) * 20
        cx = bx[None, :] + vx * moving  # (T, nb)
        cy = by[None, :] + vy * moving
        peak = rng.uniform(0.5, 1.0, nb)[None, :] * amp
        d2 = ((xx[None, None] - cx[..., None, None]) ** 2
              + (yy[None, None] - cy[..., None, None]) ** 2)
        img = (peak[..., None, None] * np.exp(-d2 / (2 * sigma ** 2))).sum(1)
        img += rng.normal(0, 0.03, img.shape).astype(np.float32)
        img = np.clip(img, 0, 1).astype(np.float32)
        if channels == 1:
            seq = img[:, None]
        else:
            prev = np.concatenate([np.zeros_like(img[:1]), img[:-1]])
            diff = np.abs(img - prev)
            pad = np.pad(diff, ((0, 0), (1, 1), (1, 1)), mode="edge")
            smooth = sum(pad[:, i:i + height, j:j + width] for i in range(3)
                         for j in range(3)) / 9.0
            seq = np.stack([img, diff, smooth], axis=1)[:, :channels]
        seqs.append(np.ascontiguousarray(seq, dtype=np.float32))
    return seqs, labels.astype(np.int64)


def split(seqs, labels, test_per_class: int, seed: int):
    rng = np.random.default_rng(seed)
    test = np.concatenate([rng.permutation(np.flatnonzero(labels == k))[:test_per_class]
                           for k in np.unique(labels)])
    mask = np.zeros(len(labels), bool)
    mask[test] = True
    tr = [s for s, m in zip(seqs, mask) if not m]
    te = [s for s, m in zip(seqs, mask) if m]
    return tr, labels[~mask], te, labels[mask]


def bare_loop(clf, train, *, steps: int, seed: int) -> float:
    """Seconds for ``steps`` optimizer steps of the same network in a plain torch loop,
    on windows already resized and stacked in memory (no toolkit code in the loop)."""
    import torch
    import torch.nn.functional as F

    from tactbench.classifiers.training import make_optimizer

    torch.manual_seed(seed)
    net = clf._build_net(tuple(train.frame_shape), 5, pretrained=False)
    n = min(len(train), steps * clf.batch_size)
    x = torch.from_numpy(train.batch(np.arange(n)))
    b, length = x.shape[:2]
    with torch.no_grad():
        x = net.prepare(x.reshape(b * length, *x.shape[2:]))
    x = x.reshape(b, length, *x.shape[1:]).contiguous()
    y = torch.from_numpy(train.labels[:n])
    opt = make_optimizer(clf.optimizer, net.parameters(), lr=clf.lr, momentum=clf.momentum,
                         weight_decay=clf.weight_decay)
    net.train()
    gen = torch.Generator().manual_seed(seed)
    start = time.perf_counter()
    for s in range(steps):
        idx = torch.randint(0, n, (clf.batch_size,), generator=gen)
        opt.zero_grad(set_to_none=True)
        loss = F.cross_entropy(net(x[idx]), y[idx])
        loss.backward()
        opt.step()
    return time.perf_counter() - start


def measure_overhead(cases: list[tuple[str, object, int]], *, repeats: int) -> list[dict]:
    """Bare loop and ``fit`` alternately, ``repeats`` times each; the fastest of each
    counts (other jobs share the cores, and only ever slow a run down)."""
    import warnings

    from tactbench.plugins import load_registry
    from tactbench.profiles import profile_options

    reg = load_registry()
    rows = []
    for name, train, n_steps in cases:
        opts = profile_options("quick", name)
        opts.update(epochs=1, windows_per_epoch=n_steps * opts.get("batch_size", 64),
                    schedule="constant")
        bare, fit, loop = [], [], []
        for _ in range(repeats):
            clf = reg.build("classifier", name, **opts)
            bare.append(bare_loop(clf, train, steps=n_steps, seed=0))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # cnn-lstm: no ImageNet weights here
                start = time.perf_counter()
                rep = clf.fit(train, None, seed=0, progress=lambda *a, **k: None)
                fit.append(time.perf_counter() - start)
            loop.append(rep["train_seconds"])
        windows = n_steps * clf.batch_size
        bare_s, fit_s, loop_s = min(bare), min(fit), min(loop)
        row = {"classifier": name, "input_size": getattr(clf, "input_size", None),
               "frame_shape": list(train.frame_shape), "batch_size": clf.batch_size,
               "steps": n_steps, "repeats": repeats,
               "bare_windows_per_s": windows / bare_s, "fit_windows_per_s": windows / fit_s,
               "loop_windows_per_s": windows / loop_s,
               "setup_seconds": fit_s - loop_s,
               "overhead_loop": loop_s / bare_s - 1.0, "overhead_total": fit_s / bare_s - 1.0,
               "bare_seconds": bare, "fit_seconds": fit}
        rows.append(row)
        print(f"{name:15s} {str(train.frame_shape):15s} "
              f"bare {row['bare_windows_per_s']:6.0f} win/s  "
              f"fit loop {row['loop_windows_per_s']:6.0f} win/s "
              f"({100 * row['overhead_loop']:+.1f} %)"
              f"  fit with set-up {row['fit_windows_per_s']:6.0f} win/s "
              f"({100 * row['overhead_total']:+.1f} %, set-up {row['setup_seconds']:.1f} s)",
              flush=True)
    return rows


def taxel_windows(windows):
    """The same windows as taxel vectors ``(T, N)``: every 5th pixel of the first channel
    (a ~5 px taxel pitch, like CySkin's 7.5 mm at 1.5 mm/px)."""
    from tactbench.data.windows import Windows

    seqs = [np.ascontiguousarray(s[:, 0, ::5, ::5].reshape(s.shape[0], -1))
            for s in windows.sequences]
    return Windows(seqs, windows.seq_index, windows.starts, windows.labels, windows.length)


def measure_logreg(train) -> dict:
    from tactbench.plugins import load_registry

    clf = load_registry().build("classifier", "logreg")
    start = time.perf_counter()
    rep = clf.fit(train, None, seed=0)
    fit_s = time.perf_counter() - start
    row = {"classifier": "logreg", "train_windows": len(train), "fit_seconds": fit_s,
           "fit_windows_per_s": len(train) / fit_s, "steps": rep["steps"]}
    print(f"logreg          {str(train.frame_shape):15s} fit {len(train)} windows in "
          f"{fit_s:.1f} s ({row['fit_windows_per_s']:.0f} win/s)", flush=True)
    return row


def measure_quick(n_sequences: int, seeds, channels_list) -> list[dict]:
    from tactbench.data.windows import test_windows, training_windows
    from tactbench.plugins import load_registry
    from tactbench.profiles import profile_options

    reg = load_registry()
    rows = []
    for channels in channels_list:
        t0 = time.perf_counter()
        seqs, labels = synthetic_sequences(n_sequences + 150, channels=channels, seed=1)
        gen_s = time.perf_counter() - t0
        tr, ytr, te, yte = split(seqs, labels, 30, seed=0)
        train = training_windows(tr, ytr, 5)
        test = test_windows(te, yte, 5)
        for seed in seeds:
            opts = profile_options("quick", "small-cnn-lstm")
            clf = reg.build("classifier", "small-cnn-lstm", **opts)
            start, cpu0 = time.perf_counter(), time.process_time()
            rep = clf.fit(train, None, seed=seed)
            fit_s, cpu_s = time.perf_counter() - start, time.process_time() - cpu0
            acc = float((clf.predict(test) == test.labels).mean())
            row = {"channels": channels, "seed": seed, "train_windows": len(train),
                   "fit_seconds": fit_s, "fit_cpu_seconds": cpu_s,
                   "loop_seconds": rep["train_seconds"],
                   "windows_seen": rep["windows_seen"], "test_accuracy": acc,
                   "final_loss": rep["final_loss"], "data_seconds": gen_s}
            rows.append(row)
            print(f"quick small-cnn-lstm C={channels} seed={seed}: {len(train)} windows, fit "
                  f"{fit_s:.1f} s (loop {rep['train_seconds']:.1f} s, CPU {cpu_s:.1f} s), "
                  f"test accuracy "
                  f"{acc:.3f}, final loss {rep['final_loss']:.3f}", flush=True)
    return rows


def measure_paper_epoch(train) -> dict | None:
    import torch

    if not torch.cuda.is_available():
        print("paper-epoch: no CUDA device, skipped", flush=True)
        return None
    from tactbench.plugins import load_registry
    from tactbench.profiles import profile_options

    opts = profile_options("paper", "cnn-lstm")
    opts["epochs"] = 1
    clf = load_registry().build("classifier", "cnn-lstm", **opts)
    start = time.perf_counter()
    rep = clf.fit(train, None, seed=0, device="cuda")
    torch.cuda.synchronize()
    row = {"classifier": "cnn-lstm", "profile": "paper", "device": torch.cuda.get_device_name(),
           "train_windows": len(train), "epoch_seconds": time.perf_counter() - start,
           "loop_seconds": rep["train_seconds"], "amp": rep["amp"]}
    print(f"paper-epoch on {row['device']}: {row['epoch_seconds']:.1f} s", flush=True)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--sequences", type=int, default=1750, help="training sequences")
    ap.add_argument("--steps", type=int, default=100,
                    help="optimizer steps of small-cnn-lstm in the overhead test (cnn-lstm: 1/5)")
    ap.add_argument("--repeats", type=int, default=2, help="overhead test repeats (fastest counts)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--channels", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--skip", nargs="*", default=[], choices=["overhead", "quick", "paper-epoch"])
    ap.add_argument("--out", type=Path, default=Path("docs/benchmarks/training.json"))
    args = ap.parse_args(argv)

    import torch

    torch.set_num_threads(args.threads)
    from tactbench.data.windows import training_windows

    result: dict = {"command": "python " + " ".join(sys.argv), "threads": args.threads,
                    "machine": platform.platform(), "torch": torch.__version__,
                    "date": time.strftime("%Y-%m-%d"),
                    "note": "2-core CPU VM shared with other jobs: timings vary by ±30 %"}
    small = None
    if "overhead" not in args.skip or "paper-epoch" not in args.skip:
        seqs, labels = synthetic_sequences(300, channels=3, seed=2)
        small = training_windows(seqs, labels, 5)
    if "overhead" not in args.skip:
        vectors = taxel_windows(small)
        cases = [("small-cnn-lstm", small, args.steps), ("taxel-lstm", vectors, args.steps),
                 ("cnn-lstm", small, max(1, args.steps // 5))]
        result["overhead"] = measure_overhead(cases, repeats=args.repeats)
        result["logreg"] = measure_logreg(small)
    if "quick" not in args.skip:
        result["quick"] = measure_quick(args.sequences, args.seeds, args.channels)
    if "paper-epoch" not in args.skip:
        result["paper_epoch"] = measure_paper_epoch(small)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
