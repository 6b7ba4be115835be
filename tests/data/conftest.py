"""Fixtures of the data-stage tests: a tiny grid layout and a tiny dataset on it."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.dataset import Dataset
from tactbench.data.layout import TaxelLayout
from tactbench.data.recording import Recording, Sample


def grid_layout(n_side=4, pitch=7.5):
    yy, xx = np.mgrid[0:n_side, 0:n_side]
    pos = np.column_stack([xx.ravel(), yy.ravel()]) * pitch
    return TaxelLayout(ids=np.arange(n_side * n_side) + 100, positions=pos, name="grid")


def make_dataset(n_samples=6, n_taxels=16, layout=True, seed=0, normalisation="fixed"):
    rng = np.random.default_rng(seed)
    ids = np.arange(n_taxels) + 100
    samples = []
    for k in range(n_samples):
        t = int(rng.integers(3, 8))
        values = rng.integers(0, 60000, (t, n_taxels)).astype(np.float32)
        rec = Recording(values, np.arange(t) * 0.1, ids)
        samples.append(Sample(rec, k % 3, user=f"u{k % 2}", position="front",
                              repetition=k // 3, source=f"s{k}"))
    return Dataset("tiny", samples, ("a", "b", "c"),
                   grid_layout() if layout else None, normalisation)


@pytest.fixture(name="grid_layout")
def grid_layout_fixture():
    """``grid_layout(n_side=4, pitch=7.5)``: a square lattice of taxels 100, 101, …"""
    return grid_layout


@pytest.fixture(name="make_dataset")
def make_dataset_fixture():
    """``make_dataset(n_samples=6, n_taxels=16, layout=True, seed=0, normalisation="fixed")``:
    6 samples of 3–7 frames, 3 classes, users u0/u1, on :func:`grid_layout`."""
    return make_dataset
