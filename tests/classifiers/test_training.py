"""Devices, precision, window order and the shared training loop
(tactbench.classifiers.training); profiles and seeds have their own test files."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from tactbench.classifiers.training import (
    FitReport,
    TrainingInterrupted,
    epoch_order,
    precision_for,
    select_device,
    train_loop,
)

BUILTIN = ("small-cnn-lstm", "cnn-lstm", "taxel-lstm", "logreg")


pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ----------------------------------------------------------------------------- window order


def test_epoch_order_permutes_cuts_and_repeats():
    rng = np.random.default_rng(0)
    assert sorted(epoch_order(rng, 10, 0)) == list(range(10))
    cut = epoch_order(rng, 10, 4)
    assert len(cut) == 4 and len(set(cut)) == 4
    more = epoch_order(rng, 10, 25)
    assert len(more) == 25 and set(more) == set(range(10))
    a = epoch_order(np.random.default_rng(3), 50, 20)
    b = epoch_order(np.random.default_rng(3), 50, 20)
    assert np.array_equal(a, b)


# ----------------------------------------------------------------------------- devices


def test_select_device():
    assert select_device("cpu").type == "cpu"
    assert select_device(None).type == "cpu"
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert select_device("auto").type == expected
    with pytest.raises(ValueError, match="unknown device"):
        select_device("gpu-please")
    with pytest.raises(ValueError, match="not supported"):
        select_device("meta")


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is present on this machine")
def test_asking_for_cuda_without_it_is_an_error_not_a_fallback():
    with pytest.raises(ValueError, match="CUDA is not available"):
        select_device("cuda")


def test_mixed_precision_settings():
    assert not precision_for(torch.device("cpu"), None).enabled
    cpu = precision_for(torch.device("cpu"), True)
    assert cpu.enabled and cpu.dtype == torch.bfloat16 and not cpu.scale_gradients
    # The CUDA choice is made without touching a GPU, so it is checked here too.
    gpu = precision_for(torch.device("cuda"), None)
    assert gpu.enabled and gpu.dtype == torch.float16 and gpu.scale_gradients
    assert not precision_for(torch.device("cuda"), False).enabled


# ----------------------------------------------------------------------------- the loop


def _toy_problem(n=64, seed=0):
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 4, generator=g)
    y = (x[:, 0] > 0).long() + (x[:, 1] > 0).long()
    return x, y


def _run(model, *, epochs=3, amp=None, progress=None, seed=0, per_epoch=0):
    x, y = _toy_problem()
    report = FitReport(classifier="toy", seed=seed, device="cpu", amp=bool(amp))
    dev = torch.device("cpu")
    train_loop(model, lambda idx: (x[idx], y[idx]), n_windows=len(x), report=report,
               epochs=epochs, batch_size=16, windows_per_epoch=per_epoch, optimizer="adam",
               lr=0.05, device=dev, precision=precision_for(dev, amp), progress=progress)
    return report


def test_train_loop_lowers_the_loss_and_reports_what_it_did():
    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(4, 16), nn.ReLU(), nn.Linear(16, 3))
    calls = []
    report = _run(model, epochs=5, progress=lambda d, t, **i: calls.append((d, t, i)))
    assert report.epochs == 5 and report.steps == 20 and report.windows_seen == 5 * 64
    assert report.epoch_losses[-1] < report.epoch_losses[0]
    assert report.final_loss == report.epoch_losses[-1]
    assert report.train_seconds > 0 and report.windows_per_second > 0
    assert [c[0] for c in calls] == list(range(1, 21))
    assert {c[1] for c in calls} == {20}
    assert calls[-1][2]["epoch"] == 5 and "loss" in calls[-1][2]
    assert not model.training  # left in eval mode


def test_windows_per_epoch_sets_the_epoch_size():
    model = nn.Linear(4, 3)
    report = _run(model, epochs=2, per_epoch=32)
    assert report.steps == 4 and report.windows_seen == 64


def test_a_keyboard_interrupt_stops_cleanly_with_a_report():
    model = nn.Sequential(nn.Linear(4, 8), nn.Dropout(0.5), nn.Linear(8, 3))

    def progress(done, total, **info):
        if done == 3:
            raise KeyboardInterrupt

    with pytest.raises(TrainingInterrupted) as info:
        _run(model, epochs=5, progress=progress)
    assert isinstance(info.value, KeyboardInterrupt)
    assert info.value.report.interrupted and info.value.report.steps == 3
    assert not model.training


def test_the_mixed_precision_path_runs_on_the_cpu():
    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(4, 16), nn.ReLU(), nn.Linear(16, 3))
    report = _run(model, epochs=3, amp=True)
    assert report.amp and np.isfinite(report.final_loss)


def test_bad_loop_settings_are_rejected():
    with pytest.raises(ValueError, match="unknown optimizer"):
        x, y = _toy_problem()
        dev = torch.device("cpu")
        train_loop(nn.Linear(4, 3), lambda i: (x[i], y[i]), n_windows=64,
                   report=FitReport("toy", 0, "cpu", False), epochs=1, batch_size=8,
                   windows_per_epoch=0, optimizer="rmsprop-ish", lr=0.1, device=dev,
                   precision=precision_for(dev, None))
