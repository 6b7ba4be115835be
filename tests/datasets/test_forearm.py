"""The generated CySkin-like forearm: the study's sheet, modules and cylinder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactbench.datasets.forearm import cyskin_forearm


def test_forearm_matches_the_study():
    lay = cyskin_forearm()
    assert lay.n_taxels == 1558
    assert lay.bounds == (0.0, 0.0, 334.0, 357.0)  # 357 × 334 px at 1 mm
    modules, slots = np.divmod(lay.ids, 16)
    assert slots.max() <= 11  # 12 slots per module
    per_module = np.bincount(modules)[np.unique(modules)]
    assert per_module.max() <= 11 and per_module.min() >= 1  # up to 11 taxels
    # taxels of a module lie on a 7.5 mm lattice
    first = lay.positions[modules == modules[0]]
    d = np.linalg.norm(first[:, None] - first[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert d.min(axis=1) == pytest.approx(np.full(len(first), 7.5))
    assert 7.0 <= lay.median_spacing() <= 7.6
    assert np.all((lay.positions >= 0) & (lay.positions <= [334, 357]))


def test_forearm_is_a_cylinder_and_deterministic():
    lay = cyskin_forearm()
    radius = 334 / (2 * math.pi)
    r = np.hypot(lay.positions_3d[:, 0], lay.positions_3d[:, 1])
    assert r == pytest.approx(np.full(lay.n_taxels, radius))
    assert np.linalg.norm(lay.normals, axis=1) == pytest.approx(np.ones(lay.n_taxels))
    again = cyskin_forearm()
    assert np.array_equal(lay.ids, again.ids) and np.array_equal(lay.positions, again.positions)


def test_forearm_smaller_counts():
    lay = cyskin_forearm(100, circumference_mm=120, length_mm=100)
    assert lay.n_taxels == 100 and len(np.unique(lay.ids)) == 100
    with pytest.raises(ValueError, match="modules"):
        cyskin_forearm(5000, circumference_mm=120, length_mm=100)


@pytest.mark.parametrize("kwargs, message", [
    (dict(n_taxels=0), "n_taxels must be ≥ 1"),
    (dict(pitch_mm=-1.0), "pitch_mm must be > 0"),
])
def test_forearm_refuses_bad_options(kwargs, message):
    with pytest.raises(ValueError, match=message):
        cyskin_forearm(**kwargs)
