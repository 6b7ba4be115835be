"""Profiles, seeds, devices and the shared training loop (tactbench.classifiers.training)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from torch import nn

from tactbench.classifiers.training import (
    PROFILE_NAMES,
    FitReport,
    TrainingInterrupted,
    derive_seed,
    epoch_order,
    precision_for,
    profile_options,
    select_device,
    train_loop,
)
from tactbench.plugins import load_registry

BUILTIN = ("small-cnn-lstm", "cnn-lstm", "taxel-lstm", "logreg")


pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ----------------------------------------------------------------------------- profiles


def test_paper_profile_is_the_papers_protocol():
    opts = profile_options("paper", "cnn-lstm")
    assert opts["optimizer"] == "sgd" and opts["lr"] == 1e-3 and opts["epochs"] == 100
    assert opts["input_size"] == 224
    assert opts["windows_per_epoch"] == 0  # every training window, every epoch


def test_quick_is_the_default_and_matches_the_class_defaults():
    reg = load_registry()
    for name in BUILTIN:
        default = reg.build("classifier", name).options()
        quick = reg.build("classifier", name, **profile_options("quick", name)).options()
        assert default == quick, name
    assert profile_options(classifier="small-cnn-lstm") == profile_options("quick",
                                                                           "small-cnn-lstm")


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("name", BUILTIN)
def test_every_profile_option_is_accepted_and_user_options_override(profile, name):
    opts = profile_options(profile, name)
    clf = load_registry().build("classifier", name, **opts)
    for key, value in opts.items():
        assert getattr(clf, key) == value
    if "epochs" in opts:
        opts["epochs"] = 1
        assert load_registry().build("classifier", name, **opts).epochs == 1


def test_profile_options_returns_a_fresh_dict():
    profile_options("quick", "small-cnn-lstm")["epochs"] = 999
    assert profile_options("quick", "small-cnn-lstm")["epochs"] != 999


def test_unknown_profile_or_classifier_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown profile 'fast'.*quick, paper"):
        profile_options("fast", "small-cnn-lstm")
    with pytest.raises(LookupError, match="unknown classifier"):
        profile_options("quick", "no-such-classifier")


def test_profiles_are_defined_once_in_tactbench_profiles():
    import tactbench.classifiers.training as training
    import tactbench.profiles as profiles

    # the old import path is the same function, not a copy
    assert training.profile_options is profiles.profile_options
    assert training.PROFILE_NAMES == profiles.PROFILE_NAMES == ("quick", "paper")
    assert [profiles.get_profile(n).pixel_mm for n in profiles.PROFILE_NAMES] == [5.0, 1.0]
    with pytest.raises(ValueError, match="unknown profile 'fast'.*quick, paper"):
        profiles.get_profile("fast")


def test_a_plugin_classifier_declares_its_own_profiles(tmp_path, monkeypatch):
    # read through the registry given (a plugin added without installing it)
    import tactbench
    from tactbench.plugins import collect_registry, make_plugin_manager

    (tmp_path / "profiled_clf.py").write_text(
        "from tactbench.classifiers.classical import PooledLogReg\n\n"
        "class Profiled(PooledLogReg):\n"
        "    profiles = {'paper': {'max_iter': 500}}\n")
    monkeypatch.syspath_prepend(str(tmp_path))

    class Plugin:
        @tactbench.hookimpl
        def register_classifiers(self, register):
            register("profiled", "profiled_clf:Profiled", summary="declares profiles")
            register("plain", "tactbench.classifiers.classical:PooledLogReg",
                     summary="declares none")

    reg = collect_registry(make_plugin_manager(entry_points=False,
                                               extra=[("profiled", Plugin())]))
    assert profile_options("paper", "profiled", registry=reg) == {"max_iter": 500}
    assert profile_options("quick", "profiled", registry=reg) == {}
    assert profile_options("paper", "plain", registry=reg) == {}


# ----------------------------------------------------------------------------- seeds


def test_derive_seed_is_stable_across_processes_and_separates_parts():
    code = "from tactbench.classifiers.training import derive_seed; print(derive_seed(0, 'raw', 5))"
    outs = set()
    for hashseed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=hashseed)
        outs.add(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                text=True, check=True).stdout.strip())
    assert outs == {str(derive_seed(0, "raw", 5))}
    seeds = {derive_seed(0, "raw", 5), derive_seed(1, "raw", 5), derive_seed(0, "flow", 5),
             derive_seed(0, "raw", 6), derive_seed("0", "raw", 5)}
    assert len(seeds) == 5
    assert all(0 <= s < 2 ** 63 for s in seeds)


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
