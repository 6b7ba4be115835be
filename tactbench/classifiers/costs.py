"""What one cell of a torch sequence classifier will cost, measured here before any training.

``tactbench plan`` needs a cell's time on a fresh machine, where no pilot row exists. A
torch classifier's fit is a fixed number of optimiser steps (``epochs`` × its windows per
epoch ÷ ``batch_size``) on frames prepared once (resized to the network's input), then
one forward pass per test window: :func:`estimate_seconds` builds the cell's own network
and times each of those three on random input of the cell's shapes, on one thread, and
adds them up. The numbers do not depend on the values of the input (dense float
arithmetic), so random frames time what real ones would. A few hundred milliseconds.

What it leaves out: reading the encoding from disk and the normalisation sample (seconds
at most on the default data); ``benchmarks/first_run.py`` measures how far the whole
estimate lands from the wall time it forecasts (docs/runner.md, "What plan says a run
will take").
"""

from __future__ import annotations

import math
import time
from typing import Any, Sequence

from tactbench.classifiers.training import make_optimizer

#: Optimiser steps timed after :data:`WARMUP_STEPS` untimed ones (allocations, oneDNN's
#: first-call kernel choice).
TIMED_STEPS = 20
WARMUP_STEPS = 3
#: Frames prepared (resized) in one timed call.
PREPARE_FRAMES = 256


def median_seconds(fn, repeats: int) -> float:
    """The median seconds of ``repeats`` calls of ``fn`` (one call first, untimed)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return sorted(times)[len(times) // 2]


def estimate_seconds(clf: Any, *, frame_shape: Sequence[int], L: int, n_classes: int,
                     n_train_windows: int, n_frames: int, n_test_windows: int) -> float:
    """Seconds one cell of ``clf`` (a :class:`~tactbench.classifiers.base.
    TorchSequenceClassifier`, unfitted) takes on one CPU thread: its training steps,
    preparing ``n_frames`` frames of ``frame_shape`` once, and predicting
    ``n_test_windows`` windows of length ``L``. Builds the network without pretrained
    weights (the same arithmetic) and leaves ``clf`` unfitted."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(0)
            clf.L = L
            net = clf._build_net(tuple(frame_shape), n_classes, pretrained=False)
            with torch.no_grad():
                frames = torch.rand((PREPARE_FRAMES, *frame_shape))
                prepare_s = median_seconds(lambda: net.prepare(frames), 3) / PREPARE_FRAMES
                prepared = net.prepare(frames[:1]).shape[1:]
            step_s = _step_seconds(clf, net, prepared, L, n_classes)
            predict_s = _predict_seconds(clf, net, prepared, L)
    finally:
        torch.set_num_threads(threads)
        clf.L = None
    per_epoch = clf.windows_per_epoch or n_train_windows
    steps = clf.epochs * math.ceil(per_epoch / clf.batch_size)
    batches = math.ceil(n_test_windows / clf.eval_batch_size)
    return steps * step_s + n_frames * prepare_s + batches * predict_s


def _step_seconds(clf: Any, net: Any, prepared: Sequence[int], L: int,
                  n_classes: int) -> float:
    """Median seconds of one optimiser step on a batch of prepared windows."""
    import torch

    net.train()
    opt = make_optimizer(clf.optimizer, net.parameters(), lr=clf.lr, momentum=clf.momentum,
                         weight_decay=clf.weight_decay)
    x = torch.rand((clf.batch_size, L, *prepared))
    y = torch.randint(0, n_classes, (clf.batch_size,))
    loss_fn = torch.nn.CrossEntropyLoss()

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        loss_fn(net(x), y).backward()
        opt.step()

    for _ in range(WARMUP_STEPS):
        step()
    return median_seconds(step, TIMED_STEPS)


def _predict_seconds(clf: Any, net: Any, prepared: Sequence[int], L: int) -> float:
    """Median seconds of one forward pass over a batch of ``eval_batch_size`` windows."""
    import torch

    net.eval()
    x = torch.rand((clf.eval_batch_size, L, *prepared))
    with torch.no_grad():
        return median_seconds(lambda: net(x), 3)
