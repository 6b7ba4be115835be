"""Training throughput and the quick profile's budget.

Measurements on a synthetic gesture-like task made here (5 classes of
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
3. ``speed``: windows per second of each model's fit loop (``small-cnn-lstm`` on 1- and
   3-channel frames, ``taxel-lstm``, ``cnn-lstm`` at quick sizes), the old path
   ("before": NCHW encoding) against channels-last ("after") and channels-last with
   ``shared_features=1``, interleaved in one process; FLOPs per window (forward +
   backward, ``FlopCounterMode``) against the dense-GEMM rate measured here.
4. ``threads``: one step loop at 1 and 2 threads (2 threads per cell, or two
   1-thread cells at once); ``compile``: ``torch.compile`` (inductor) against eager,
   compile time included.
5. ``paper-step``: the peak RSS of one ``paper``-profile ``cnn-lstm`` training step
   on the CPU (224 px, batch 16 × 5 frames) without and with gradient
   checkpointing, each in a fresh process.
6. ``vote``: prediction on every window of 150 test sequences (the ``vote`` test window,
   the runner's default) by a quick-profile ``small-cnn-lstm``, each distinct frame
   encoded once (the default) against every frame of every window (the path before),
   interleaved; seconds per test sequence and the largest difference in probability.
7. ``paper-epoch`` (only with CUDA): one epoch of the paper profile
   (``cnn-lstm``, 224 px, SGD 1e-3, batch 16) on the GPU.

With ``--recipes``, instead: accuracy against training CPU-seconds of ``small-cnn-lstm``
recipes (:data:`RECIPES`: the shipped one, the one issue 28 measured, and one change
each from it) on the default data (``tactbench run``'s: the simulated forearm, quick
profile, L = 5, vote window, paper split), each paired run by run with
``sklearn:HistGradientBoostingClassifier`` on the same cells through
:func:`tactbench.runner.analysis.comparisons.comparisons`. The cells are one ``tactbench
run`` (kept in ``--run-out``, so a rerun adds only what is missing; ``--stored`` trains
nothing), read back through the run folder's store
(:class:`tactbench.runner.ResultStore`), each recipe found by the spec its cells carry
(:func:`tactbench.profiles.canonical_classifier`); CPU-seconds are the ones each row
records of its fitting process (every thread:
:func:`tactbench.runner.analysis.report.training_cpu_seconds`), wall seconds beside
them. It writes ``--out`` (JSON: machine, date, load, per-recipe accuracy, costs,
intervals) and a PNG beside it.

Usage::

    python benchmarks/training.py [--threads 2] [--out docs/benchmarks/training.json]
                                  [--skip quick] [--sequences 1750]
    python benchmarks/training.py --recipes [LABEL ...] [--encoders farneback]
                                  [--seeds 0 1] [--reference LABEL]
                                  [--out docs/benchmarks/recipes.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from tactbench.plugins import load_registry
from tactbench.profiles import canonical_classifier
from tactbench.runner import ResultStore, comparisons, ok_rows, training_cpu_seconds

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
    return Windows(seqs, windows.seq_index, windows.starts, windows.labels, windows.L)


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


# --------------------------------------------------------------------------- speed (issue 21)

#: What each variant of ``measure_speed`` changes against the old path ("before":
#: NCHW encoding, SmallCNN's ReLU before its pool, every frame of every window encoded).
VARIANTS = {
    "before": {"channels_last": False, "pool_before_relu": False, "options": {}},
    "after": {"channels_last": True, "pool_before_relu": True, "options": {}},
    "after+shared_features": {"channels_last": True, "pool_before_relu": True,
                              "options": {"shared_features": 1}},
}


def _fit_seconds(reg, name, train, opts, *, channels_last: bool,
                 pool_before_relu: bool = True) -> tuple[float, dict]:
    """Loop seconds of one ``fit`` with the encoder's memory format and SmallCNN's block
    order chosen (the class defaults are what the toolkit runs; ``False`` is the old
    path)."""
    import warnings

    from tactbench.classifiers.nets import SequenceNet, SmallCNN

    saved = SequenceNet.channels_last, SmallCNN.pool_before_relu
    SequenceNet.channels_last = channels_last
    SmallCNN.pool_before_relu = pool_before_relu
    try:
        clf = reg.build("classifier", name, **opts)
        steps = {"cpu": 0.0}

        def progress(done, total, **info):  # CPU time of the steps 2 .. total alone
            if "val_accuracy" in info:
                return
            if done == 1:
                steps["start"] = time.process_time()
            if done == total:  # not BatchNorm recalibration, which follows the loop
                steps["cpu"] = time.process_time() - steps["start"]

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # cnn-lstm: no ImageNet weights here
            rep = clf.fit(train, None, seed=0, progress=progress)
    finally:
        SequenceNet.channels_last, SmallCNN.pool_before_relu = saved
    # the first step is left out of the CPU time (it starts the clock): scale to all
    per_step = steps["cpu"] / max(rep["steps"] - 1, 1)
    return rep["train_seconds"], per_step * rep["steps"], rep


def step_flops(clf, train, batch: int, *, shared: bool = False) -> float:
    """FLOPs of one training step (forward + backward) per window: 3 × the forward's,
    counted by ``torch.utils.flop_counter.FlopCounterMode`` (matrix products and
    convolutions; a backward pass costs two forwards: the gradients of the input and of
    the weights).

    The forward count only: torch 2.13's counter overcounts the backward of grouped
    convolutions (a depthwise 3 × 3 over 64 channels: 22× too many), which would inflate
    EfficientNet-B0's count ~13×; for networks without grouped convolutions (SmallCNN)
    its full count and 3 × forward agree within a few per cent (the first layer needs no
    input gradient)."""
    import torch
    import torch.nn.functional as F
    from torch.utils.flop_counter import FlopCounterMode

    from tactbench.classifiers.batching import FrameBank

    torch.manual_seed(0)
    net = clf._build_net(tuple(train.frame_shape), 5, pretrained=False)
    with torch.no_grad():
        bank = FrameBank(train, net.prepare)
    if shared:  # a batch as shared_features draws it: whole runs of windows
        from tactbench.classifiers.batching import window_runs
        from tactbench.classifiers.training import epoch_order

        idx = epoch_order(np.random.default_rng(0), len(train), 0, window_runs(train))[:batch]
        x, y = bank.shared_batch(idx)
    else:
        x, y = bank.batch(np.random.default_rng(0).permutation(len(train))[:batch])
    net.train()
    counter = FlopCounterMode(display=False)
    with counter:
        loss = F.cross_entropy(net(x), y)
    loss.backward()  # not counted (see above)
    return 3 * counter.get_total_flops() / batch


def gemm_rate(m: int, k: int, n: int, *, seconds: float = 1.0) -> tuple[float, float]:
    """FLOPs this CPU sustains on a dense float32 ``(m, k) @ (k, n)``: per wall second
    (best run) and per CPU second of this process (all runs; steadier when other jobs
    share the cores)."""
    import torch

    a, b = torch.randn(m, k), torch.randn(k, n)
    out = torch.empty(m, n)
    torch.mm(a, b, out=out)
    best, runs = float("inf"), 0
    cpu0, end = time.process_time(), time.perf_counter() + seconds
    while time.perf_counter() < end or runs < 3:
        t0 = time.perf_counter()
        torch.mm(a, b, out=out)
        best = min(best, time.perf_counter() - t0)
        runs += 1
    flops = 2.0 * m * k * n
    return flops / best, flops * runs / max(time.process_time() - cpu0, 1e-9)


def measure_speed(cases, *, repeats: int, threads: int) -> dict:
    """Windows per second of each model's fit loop, old path against new, interleaved
    (before, after, after+shared, before, …; the fastest of each counts: other jobs
    only ever slow a run down), with FLOPs per window and the achieved fraction of the
    dense-GEMM rate measured here."""
    from tactbench.plugins import load_registry
    from tactbench.profiles import profile_options

    reg = load_registry()
    # The reference rates: a square GEMM (the CPU's best case) and GEMMs shaped like the
    # convolutions' im2col products (skinny: many pixels × few channels).
    measured = {"square 1024": gemm_rate(1024, 1024, 1024, seconds=2.0),
                "conv-like 81920×144×32": gemm_rate(81920, 144, 32, seconds=2.0),
                "conv-like 5120×288×64": gemm_rate(5120, 288, 64, seconds=2.0)}
    rates = {k: v[0] for k, v in measured.items()}
    cpu_rates = {k: v[1] for k, v in measured.items()}
    sustainable, sustainable_cpu = rates["square 1024"], cpu_rates["square 1024"]
    print("dense GEMM: " + ", ".join(f"{k} {v / 1e9:.1f} GFLOP/s "
                                     f"({cpu_rates[k] / 1e9:.1f} per CPU-s)"
                                     for k, v in rates.items()), flush=True)
    rows = []
    for name, train, n_steps in cases:
        opts = profile_options("quick", name)
        opts.update(epochs=1, windows_per_epoch=n_steps * opts.get("batch_size", 64),
                    schedule="constant")
        times: dict[str, list[float]] = {v: [] for v in VARIANTS}
        cpu: dict[str, list[float]] = {v: [] for v in VARIANTS}
        for _ in range(repeats):
            for variant, how in VARIANTS.items():
                secs, cpu_s, rep = _fit_seconds(reg, name, train,
                                                dict(opts, **how["options"]),
                                                channels_last=how["channels_last"],
                                                pool_before_relu=how["pool_before_relu"])
                times[variant].append(secs)
                cpu[variant].append(cpu_s)
        clf = reg.build("classifier", name, **opts)
        windows = n_steps * clf.batch_size
        flops = step_flops(clf, train, clf.batch_size)
        flops_shared = step_flops(clf, train, clf.batch_size, shared=True)
        row = {"classifier": name, "frame_shape": list(train.frame_shape),
               "input_size": getattr(clf, "input_size", None), "batch_size": clf.batch_size,
               "steps": n_steps, "repeats": repeats, "threads": threads,
               "flops_per_window": flops, "flops_per_window_shared": flops_shared,
               "seconds": times, "cpu_seconds": cpu}
        for variant in VARIANTS:
            wps = windows / min(times[variant])
            wpc = windows / min(cpu[variant])
            f = flops_shared if "shared" in variant else flops
            row[variant] = {"windows_per_s": wps, "windows_per_cpu_s": wpc,
                            "gflop_per_s": wps * f / 1e9,
                            "fraction_of_gemm": wps * f / sustainable,
                            "fraction_of_gemm_per_cpu_s": wpc * f / sustainable_cpu}
        for variant in ("after", "after+shared_features"):
            key = "speedup_" + variant.replace("after+", "")
            row[key] = row[variant]["windows_per_s"] / row["before"]["windows_per_s"]
            row[key + "_cpu"] = (row[variant]["windows_per_cpu_s"]
                                 / row["before"]["windows_per_cpu_s"])
        rows.append(row)
        print(f"{name:15s} {str(train.frame_shape):13s} {flops / 1e6:8.1f} MFLOP/window "
              f"(shared {flops_shared / 1e6:.1f})  " + "  ".join(
                  f"{v} {row[v]['windows_per_s']:6.0f} win/s "
                  f"{row[v]['windows_per_cpu_s']:6.0f} win/CPU-s "
                  f"({100 * row[v]['fraction_of_gemm_per_cpu_s']:.0f} % of GEMM)"
                  for v in VARIANTS)
              + f"  after/before {row['speedup_after']:.2f}× wall, "
                f"{row['speedup_after_cpu']:.2f}× CPU", flush=True)
    return {"gemm_flops_per_s": rates, "gemm_flops_per_cpu_s": cpu_rates, "rows": rows}


def _quick_batch(train):
    """``small-cnn-lstm`` at the quick profile, a fresh seeded network for ``train``'s
    frames and its first training batch (frames prepared): ``(clf, net, x, y)``."""
    import torch

    from tactbench.classifiers.batching import FrameBank
    from tactbench.plugins import load_registry
    from tactbench.profiles import profile_options

    clf = load_registry().build("classifier", "small-cnn-lstm",
                                **profile_options("quick", "small-cnn-lstm"))
    torch.manual_seed(0)
    net = clf._build_net(tuple(train.frame_shape), 5, pretrained=False)
    with torch.no_grad():
        bank = FrameBank(train, net.prepare)
    x, y = bank.batch(np.arange(clf.batch_size))
    return clf, net, x, y


def measure_compile(train, *, steps: int, repeats: int) -> dict:
    """``torch.compile`` (inductor) of ``small-cnn-lstm``'s network against eager, on the
    same prepared batch: compile seconds, and step time after it (best of interleaved)."""
    import torch
    import torch.nn.functional as F

    clf, net, x, y = _quick_batch(train)

    def stepper(module):
        opt = torch.optim.Adam(net.parameters(), lr=1e-4)

        def step():
            opt.zero_grad(set_to_none=True)
            F.cross_entropy(module(x), y).backward()
            opt.step()
        return step

    net.train()
    eager = stepper(net)
    t0 = time.perf_counter()
    compiled = stepper(torch.compile(net))
    compiled()
    compile_s = time.perf_counter() - t0
    best = {"eager": float("inf"), "compiled": float("inf")}
    for _ in range(repeats):
        for label, step in (("eager", eager), ("compiled", compiled)):
            t0 = time.perf_counter()
            for _ in range(steps):
                step()
            best[label] = min(best[label], (time.perf_counter() - t0) / steps)
    out = {"compile_seconds": compile_s, "eager_step_s": best["eager"],
           "compiled_step_s": best["compiled"],
           "speedup": best["eager"] / best["compiled"],
           "break_even_steps": (compile_s / max(best["eager"] - best["compiled"], 1e-9)
                                if best["compiled"] < best["eager"] else None)}
    print(f"torch.compile small-cnn-lstm: compile {compile_s:.1f} s, step eager "
          f"{1e3 * best['eager']:.0f} ms, compiled {1e3 * best['compiled']:.0f} ms "
          f"({out['speedup']:.2f}×)", flush=True)
    return out


def measure_vote(*, repeats: int, n_sequences: int = 150) -> dict:
    """Prediction of every window of ``n_sequences`` test sequences (``vote``), shared
    frames against the plain path, interleaved (best of ``repeats``)."""
    import tactbench.classifiers.base as base
    from tactbench.data.windows import training_windows
    from tactbench.plugins import load_registry
    from tactbench.profiles import profile_options

    seqs, labels = synthetic_sequences(n_sequences + 50, channels=1, seed=3)
    train = training_windows(seqs[:50], labels[:50], 5)
    test = training_windows(seqs[50:], labels[50:], 5)
    opts = {**profile_options("quick", "small-cnn-lstm"), "epochs": 1,
            "windows_per_epoch": 256}
    clf = load_registry().build("classifier", "small-cnn-lstm", **opts)
    clf.fit(train, seed=0)  # the weights do not matter for speed; some training does
    shared_path = base.shares_at_inference
    plain_path = lambda windows, net: False  # noqa: E731 - the path before
    best = {"shared": float("inf"), "plain": float("inf")}
    proba = {}
    try:
        for _ in range(repeats):
            for label, path in (("plain", plain_path), ("shared", shared_path)):
                base.shares_at_inference = path
                t0 = time.perf_counter()
                proba[label] = clf.predict_proba(test)
                best[label] = min(best[label], time.perf_counter() - t0)
    finally:
        base.shares_at_inference = shared_path
    out = {"sequences": n_sequences, "windows": len(test), "L": 5,
           "plain_s": best["plain"], "shared_s": best["shared"],
           "plain_ms_per_sequence": 1e3 * best["plain"] / n_sequences,
           "shared_ms_per_sequence": 1e3 * best["shared"] / n_sequences,
           "speedup": best["plain"] / best["shared"],
           "max_abs_probability_difference": float(np.abs(proba["plain"]
                                                          - proba["shared"]).max())}
    print(f"vote prediction, {len(test)} windows of {n_sequences} sequences: plain "
          f"{best['plain']:.2f} s, shared frames {best['shared']:.2f} s "
          f"({out['speedup']:.2f}×)", flush=True)
    return out


def measure_threads(train, *, steps: int, repeats: int) -> dict:
    """A grid of cells on 2 cores: one cell with 2 threads at a time, or two cells with
    1 thread each at once. Windows per second of one step loop at 1 and 2 threads
    (best of interleaved); two 1-thread cells give at most twice the 1-thread rate."""
    import torch
    import torch.nn.functional as F

    clf, net, x, y = _quick_batch(train)
    opt = torch.optim.Adam(net.parameters(), lr=1e-4)
    net.train()
    old = torch.get_num_threads()
    best = {1: float("inf"), 2: float("inf")}
    try:
        for _ in range(repeats):
            for n in (1, 2):
                torch.set_num_threads(n)
                t0 = time.perf_counter()
                for _ in range(steps):
                    opt.zero_grad(set_to_none=True)
                    F.cross_entropy(net(x), y).backward()
                    opt.step()
                best[n] = min(best[n], (time.perf_counter() - t0) / steps)
    finally:
        torch.set_num_threads(old)
    one, two = clf.batch_size / best[1], clf.batch_size / best[2]
    out = {"windows_per_s_1_thread": one, "windows_per_s_2_threads": two,
           "two_thread_scaling": two / one,
           "grid_2_workers_x_1_thread_upper_bound": 2 * one}
    print(f"threads small-cnn-lstm: 1 thread {one:.0f} win/s, 2 threads {two:.0f} win/s "
          f"(×{two / one:.2f}); 2 workers × 1 thread ≤ {2 * one:.0f} win/s", flush=True)
    return out


def paper_step(checkpoint: bool) -> dict:
    """One ``paper``-profile ``cnn-lstm`` training step on the CPU (224 px, batch 16 of
    5 frames, SGD) in this process: its peak resident memory (``ru_maxrss``), with or
    without gradient checkpointing of the backbone. Run in a fresh process per case."""
    import resource

    import torch
    import torch.nn.functional as F

    from tactbench.plugins import load_registry
    from tactbench.profiles import profile_options

    opts = profile_options("paper", "cnn-lstm")
    clf = load_registry().build("classifier", "cnn-lstm", **opts)
    torch.manual_seed(0)
    net = clf._build_net((3, 224, 224), 5, pretrained=False)
    if not checkpoint:
        net.checkpoint_segments = 0
    x = torch.rand(clf.batch_size, 5, 3, 224, 224)
    y = torch.arange(clf.batch_size) % 5
    opt = torch.optim.SGD(net.parameters(), lr=clf.lr)
    net.train()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    opt.zero_grad(set_to_none=True)
    F.cross_entropy(net(x), y).backward()
    opt.step()
    step_s = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"checkpoint": checkpoint, "checkpoint_segments": net.checkpoint_segments,
            "peak_rss_mb": peak, "rss_before_step_mb": before, "step_seconds": step_s,
            "batch": [clf.batch_size, 5, 3, 224, 224]}


def measure_paper_step() -> list[dict]:
    """:func:`paper_step` without and with checkpointing, each in its own process."""
    rows = []
    for flag in ("off", "on"):
        out = subprocess.run([sys.executable, __file__, "--paper-step", flag],
                             check=True, capture_output=True, text=True).stdout
        row = json.loads(out.strip().splitlines()[-1])
        rows.append(row)
        print(f"paper-step cnn-lstm 224 px, checkpointing {flag}: peak RSS "
              f"{row['peak_rss_mb']:.0f} MB, step {row['step_seconds']:.1f} s", flush=True)
    return rows


# --------------------------------------------------------------------------- recipes

#: The tree every recipe is paired with.
BASELINE = "sklearn:HistGradientBoostingClassifier"
#: The recipe issue 28 measured, spelled out: with the quick profile's optimiser of the
#: time (Adam 3e-3, cosine), so that its cells keep their identity after the default moved.
_ADAM = "optimizer=adam,schedule=cosine,weight_decay=0"
_ISSUE = "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=24000," + _ADAM
_ONECYCLE = "optimizer=adamw,schedule=onecycle,weight_decay=0.01"
#: Recipes of ``--recipes``: label → classifier spec (the quick profile fills the rest).
RECIPES = {
    # the quick default until issue 28: 32 px, LSTM head, Adam 3e-3 cosine, 4 × 8000 windows
    "shipped": "small-cnn-lstm:input_size=32,head=lstm,windows_per_epoch=8000," + _ADAM,
    "issue": _ISSUE,  # 16 px, concat head, 4 × 24 000 windows
    "issue-160k": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=40000," + _ADAM,
    "tcn": "small-cnn-lstm:input_size=16,head=tcn,windows_per_epoch=24000," + _ADAM,
    # today's quick default (issue 28): the same as plain "small-cnn-lstm"
    "adamw-onecycle": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=24000,"
                      + _ONECYCLE,
    "adamw-onecycle-160k": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=40000,"
                           + _ONECYCLE,
    # issue 36: the same at half the training cost, by half the windows or half the width
    "adamw-onecycle-48k": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=12000,"
                          + _ONECYCLE,
    "adamw-onecycle-w8": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=24000,"
                         "width=8," + _ONECYCLE,
    # ... and between the default and half: 2/3 and 3/4 of the windows, 3/4 of the width
    "adamw-onecycle-64k": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=16000,"
                          + _ONECYCLE,
    "adamw-onecycle-72k": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=18000,"
                          + _ONECYCLE,
    "adamw-onecycle-w12": "small-cnn-lstm:input_size=16,head=concat,windows_per_epoch=24000,"
                          "width=12," + _ONECYCLE,
    "smoothing": _ISSUE + ",label_smoothing=0.1",
    "augment": _ISSUE + ",shift=1,gain=0.2",
    "early-stop": "small-cnn-lstm:input_size=16,head=concat,epochs=8,windows_per_epoch=12000,"
                  "val_fraction=0.1,patience=3," + _ADAM,
}


def _load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def measure_recipes(labels: list[str], encoders: list[str], seeds: list[int], *,
                    threads: int, run_out: Path, extra: list[str],
                    stored: bool = False, reference: str | None = None) -> dict:
    """One ``tactbench run`` of every recipe and the baseline; per recipe and encoder:
    accuracy, CPU and wall seconds per cell, and (recipe − baseline) paired over runs,
    and (recipe − ``reference``, one of the recipes) when given.
    ``stored``: run nothing, read the cells ``run_out`` holds."""
    specs = {label: RECIPES[label] for label in labels}
    registry = load_registry()
    named = {canonical_classifier(spec, "quick", registry=registry): label
             for label, spec in [*specs.items(), ("baseline", BASELINE)]}
    cmd = [str(Path(sys.executable).with_name("tactbench")), "run", "--out", str(run_out),
           "--threads", str(threads), "--no-plots"]
    for seed in seeds:
        cmd += ["--seed", str(seed)]
    for enc in encoders:
        cmd += ["--encoder", enc]
    for spec in [BASELINE, *specs.values()]:  # the cheap baseline first: a run cut short
        cmd += ["--classifier", spec]         # still pairs what it finished
    cmd += extra
    load_before, t0 = _load(), time.perf_counter()
    if not stored:
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    # the verified rows of the cells finished so far (a run cut short keeps them)
    rows = [r for r in ok_rows(ResultStore(run_out).stored_rows()) if int(r["seed"]) in seeds]
    compared = [c.to_dict() for c in comparisons(rows) if c.factor == "classifier"]
    out = {"command": " ".join(cmd), "from_stored": stored, "wall_s": time.perf_counter() - t0,
           "load_before": load_before, "load_after": _load(), "recipes": []}
    for spec, label in named.items():
        for enc in encoders:
            cells = [r for r in rows if r["encoder"] == enc and r["classifier"] == spec]
            if not cells:
                continue
            acc = [100 * r["accuracy"] for r in cells]
            cpu = [c for c in (training_cpu_seconds([r]) for r in cells) if c is not None]
            entry = {"recipe": label, "spec": spec, "encoder": enc, "runs": len(cells),
                     "accuracy_mean": float(np.mean(acc)), "accuracy": acc,
                     "cpu_s_mean": float(np.mean(cpu)) if cpu else None,
                     "wall_s_mean": float(np.mean([r["train_s"] for r in cells]))}
            for other in ("baseline", reference):
                paired = _paired(compared, named, label, other, enc)
                if paired is not None:
                    entry["vs_" + ("baseline" if other == "baseline" else "reference")] = \
                        {"reference": other, **paired}
            out["recipes"].append(entry)
    return out


def _paired(compared: list[dict], named: dict, label: str, other: str | None,
            encoder: str) -> dict | None:
    """``label`` − ``other`` in points, paired over runs, from the run's comparisons;
    None when ``other`` is ``label`` itself, not given or not compared."""
    if other is None or other == label:
        return None
    for c in compared:
        if c.get("encoder") == encoder and \
                {named.get(c["a"]), named.get(c["b"])} == {label, other}:
            sign = 1 if named.get(c["a"]) == other else -1  # label − other
            low, high = sorted((sign * c["low"], sign * c["high"]))
            return {"difference": 100 * sign * c["difference"], "low": 100 * low,
                    "high": 100 * high, "runs": c["runs"], "method": c["method"]}
    return None


def plot_recipes(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for enc, marker in zip(sorted({e["encoder"] for e in result["recipes"]}), "os^"):
        for e in (e for e in result["recipes"] if e["encoder"] == enc):
            x = e["cpu_s_mean"] if e["cpu_s_mean"] is not None else e["wall_s_mean"]
            ax.scatter(x, e["accuracy_mean"], marker=marker,
                       color="black" if e["recipe"] == "baseline" else None)
            ax.annotate(f"{e['recipe']} ({enc})", (x, e["accuracy_mean"]), fontsize=7,
                        xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("training CPU-seconds per cell (process time, all threads)")
    ax.set_ylabel("test accuracy, % (mean over runs)")
    ax.set_title("small-cnn-lstm recipes against HistGradientBoosting (default data)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def recipes_main(args) -> int:
    import torch

    labels = args.recipes or list(RECIPES)
    unknown = [x for x in labels if x not in RECIPES]
    if unknown:
        raise SystemExit(f"unknown recipes {unknown}; known: {', '.join(RECIPES)}")
    if args.reference is not None and args.reference not in labels:
        raise SystemExit(f"--reference {args.reference} is not among the recipes run: "
                         f"{', '.join(labels)}")
    result = {"command": "python " + " ".join(sys.argv), "threads": args.threads,
              "machine": platform.platform(), "cpu_count": __import__("os").cpu_count(),
              "torch": torch.__version__, "date": time.strftime("%Y-%m-%d %H:%M UTC",
                                                                time.gmtime()),
              "note": "2-core VM shared with other jobs (see load): CPU-seconds are the "
                      "robust cost; wall seconds grow with contention",
              **measure_recipes(labels, args.encoders, args.seeds, threads=args.threads,
                                run_out=args.run_out, extra=args.run_args,
                                stored=args.stored, reference=args.reference)}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    plot_recipes(result, args.out.with_suffix(".png"))
    for e in result["recipes"]:
        vs = e.get("vs_baseline")
        interval = (f"{vs['difference']:+.1f} [{vs['low']:+.1f}, {vs['high']:+.1f}]"
                    if vs else "")
        cpu = f"{e['cpu_s_mean']:.0f}" if e["cpu_s_mean"] is not None else "?"
        ref = e.get("vs_reference")
        if ref:
            interval += (f"  − {ref['reference']}: {ref['difference']:+.1f} "
                         f"[{ref['low']:+.1f}, {ref['high']:+.1f}]")
        print(f"{e['recipe']:18s} {e['encoder']:10s} {e['accuracy_mean']:5.1f} %  "
              f"{cpu:>5s} CPU-s {e['wall_s_mean']:5.0f} s  {interval}")
    print(f"wrote {args.out} and {args.out.with_suffix('.png')}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipes", nargs="*", metavar="LABEL",
                    help=f"accuracy against training CPU-s of these recipes (none named: "
                         f"all of {', '.join(RECIPES)}) instead of the other parts")
    ap.add_argument("--encoders", nargs="+", default=["raw", "farneback"])
    ap.add_argument("--run-out", type=Path, default=Path("tactbench-out/recipes"),
                    help="where the recipes' tactbench run keeps its cells")
    ap.add_argument("--reference", metavar="LABEL",
                    help="--recipes: pair every other recipe with this one too")
    ap.add_argument("--stored", action="store_true",
                    help="--recipes: train nothing, report the cells --run-out holds")
    ap.add_argument("--run-args", nargs="*", default=[],
                    help="more tactbench run options (e.g. --init-seed 0-2)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--sequences", type=int, default=1750, help="training sequences")
    ap.add_argument("--steps", type=int, default=100,
                    help="optimizer steps of small-cnn-lstm in the overhead test (cnn-lstm: 1/5)")
    ap.add_argument("--repeats", type=int, default=2, help="overhead test repeats (fastest counts)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--channels", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--skip", nargs="*", default=[],
                    choices=["overhead", "speed", "compile", "threads", "vote", "quick",
                             "paper-step", "paper-epoch"])
    ap.add_argument("--out", type=Path, default=Path("docs/benchmarks/training.json"))
    ap.add_argument("--paper-step", choices=["off", "on"],
                    help="(internal) one paper-profile cnn-lstm step in this process; "
                         "prints its peak RSS as JSON")
    args = ap.parse_args(argv)
    if args.recipes is not None:
        if args.out == Path("docs/benchmarks/training.json"):
            args.out = Path("docs/benchmarks/recipes.json")
        return recipes_main(args)

    import torch

    torch.set_num_threads(args.threads)
    if args.paper_step:
        print(json.dumps(paper_step(args.paper_step == "on")))
        return 0
    result: dict = {"command": "python " + " ".join(sys.argv), "threads": args.threads,
                    "machine": platform.platform(), "torch": torch.__version__,
                    "date": time.strftime("%Y-%m-%d"),
                    "note": "2-core CPU VM shared with other jobs: timings vary by ±30 %"}
    measure_parts(args, result)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


def measure_parts(args, result: dict) -> None:
    """Every part not in ``--skip``, into ``result``; ``--out`` is written after each."""
    from tactbench.data.windows import training_windows

    small = None
    if any(part not in args.skip for part in ("overhead", "speed", "threads", "compile",
                                              "paper-epoch")):
        seqs, labels = synthetic_sequences(300, channels=3, seed=2)
        small = training_windows(seqs, labels, 5)
    if "overhead" not in args.skip:
        vectors = taxel_windows(small)
        cases = [("small-cnn-lstm", small, args.steps), ("taxel-lstm", vectors, args.steps),
                 ("cnn-lstm", small, max(1, args.steps // 5))]
        result["overhead"] = measure_overhead(cases, repeats=args.repeats)
        result["logreg"] = measure_logreg(small)
    def save() -> None:  # after every part: a part cut short keeps those before it
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")

    if "speed" not in args.skip:
        vectors = taxel_windows(small)
        # one channel (raw pressure) and three (pressure + flow): the main job's two inputs
        seqs1, labels1 = synthetic_sequences(300, channels=1, seed=2)
        cases = [("small-cnn-lstm", training_windows(seqs1, labels1, 5), args.steps),
                 ("small-cnn-lstm", small, args.steps), ("taxel-lstm", vectors, args.steps),
                 ("cnn-lstm", small, max(1, args.steps // 5))]
        result["speed"] = measure_speed(cases, repeats=args.repeats, threads=args.threads)
        save()
    if "threads" not in args.skip:
        result["threads_per_cell"] = measure_threads(small, steps=10, repeats=args.repeats)
        save()
    if "compile" not in args.skip:
        result["compile"] = measure_compile(small, steps=10, repeats=args.repeats)
        save()
    if "vote" not in args.skip:
        result["vote"] = measure_vote(repeats=args.repeats)
        save()
    if "quick" not in args.skip:
        result["quick"] = measure_quick(args.sequences, args.seeds, args.channels)
        save()
    if "paper-step" not in args.skip:
        result["paper_step"] = measure_paper_step()
        save()
    if "paper-epoch" not in args.skip:
        result["paper_epoch"] = measure_paper_epoch(small)


if __name__ == "__main__":
    raise SystemExit(main())
