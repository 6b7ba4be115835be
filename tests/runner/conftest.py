"""Fixtures of the runner's tests: a tiny real grid, a private encoding cache, a registry
with test classifier plugins (loadable in worker processes), a dataset without layout."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from tactbench.runner import EncodingCache, Scene

HERE = Path(__file__).resolve().parent
# the runner's test helpers (prediction_rows) import by name under --import-mode=importlib
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

# A tiny but real grid: the simulator at 2 users, coarse 10 mm images, a small CNN
# trained for one short epoch. Seconds per cell, not minutes.
TINY_DATASET = "synthetic-forearm:users=2,repetitions=1"
TINY_CLF = "small-cnn-lstm:epochs=1,windows_per_epoch=64,batch_size=16,input_size=16"


@pytest.fixture
def tiny_scene(tmp_path):
    """``tiny_scene(**fields)``: a :class:`Scene` of the tiny grid (2 encoders × 2 seeds)
    writing to ``tmp_path/out``; ``fields`` override."""

    def make(**over) -> Scene:
        fields = dict(dataset=TINY_DATASET, encoders=["raw", "frame-diff"],
                      classifiers=[TINY_CLF], L=[3], seeds=[0, 1], test_per_class=1,
                      pixel_mm=10.0, threads=1, workers=1, out=str(tmp_path / "out"))
        fields.update(over)
        return Scene(**fields)

    return make


@pytest.fixture
def cache(tmp_path):
    return EncodingCache(tmp_path / "cache")


@pytest.fixture
def fake_registry(monkeypatch):
    """Built-ins plus the classifiers of ``fake_components`` (added-logreg, failing,
    interrupted), added only through ``make_plugin_manager(extra=...)``: no entry point
    and no installed plugin knows them. Their module is importable in worker processes."""
    import sys

    from tactbench.plugins import collect_registry, make_plugin_manager

    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])]))
    monkeypatch.delenv("TACTBENCH_TEST_FAIL", raising=False)
    sys.modules.pop("fake_components", None)
    import fake_components

    return collect_registry(make_plugin_manager(entry_points=False,
                                                extra=[("fake", fake_components)]))


@pytest.fixture
def nolayout_dataset(tmp_path) -> Path:
    """A saved dataset of taxel vectors without a layout: 2 classes × 6 samples of
    8 frames × 5 taxels, each class a different taxel pressed (a learnable task)."""
    from tactbench.data.dataset import Dataset
    from tactbench.data.recording import Recording, Sample

    rng = np.random.default_rng(0)
    samples = []
    for i in range(12):
        label = i % 2
        values = rng.uniform(0.0, 0.1, (8, 5)).astype(np.float32)
        values[:, label] += 0.8
        rec = Recording(values, np.arange(8) * 0.1, np.arange(5))
        samples.append(Sample(rec, label=label, user=f"u{i % 3}", position="front",
                              repetition=i // 2, source="test"))
    path = tmp_path / "nolayout"
    Dataset(name="nolayout", samples=samples, classes=("a", "b"), layout=None).save(path)
    return path


@pytest.fixture
def drawn(monkeypatch):
    """The figures write_plots closes, by name (their label), to look at what was drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures = {}
    close = plt.close

    def keep(fig=None):
        figures[fig.get_label()] = fig
        close(fig)

    monkeypatch.setattr(plt, "close", keep)
    return figures
