"""Normalisation: raw values → pressure in [0, 1], from a spec string."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.dataset import Dataset
from tactbench.data.normalisation import Normalisation
from tactbench.data.recording import Recording, Sample


def test_fixed_normalisation_maps_the_16_bit_range(make_dataset):
    ds = make_dataset()
    vec = ds.vectors()
    assert all(v.dtype == np.float32 and v.shape == s.recording.values.shape
               for v, s in zip(vec, ds))
    assert np.allclose(vec[0], ds[0].recording.values / 65535)
    assert min(v.min() for v in vec) >= 0 and max(v.max() for v in vec) <= 1


def test_baseline_normalisation_removes_each_taxels_rest_value():
    ids = np.arange(3)
    base = np.array([1000, 2000, 3000], np.float32)
    rest = np.tile(base, (20, 1))
    pressed = rest.copy()
    pressed[10:, 1] += 5000  # taxel 1 pressed in half the frames
    ds = Dataset("b", [Sample(Recording(rest, np.arange(20) * .1, ids), 0),
                       Sample(Recording(pressed, np.arange(20) * .1, ids), 0)], ("a",),
                 normalisation="baseline:low=5,high=99")
    offset, scale = ds.normalisation_params()
    assert np.allclose(offset, base) and scale == pytest.approx(5000)
    vec = ds.vectors()
    assert np.all(vec[0] == 0) and vec[1][15, 1] == pytest.approx(1.0)


def test_normalisation_specs():
    assert Normalisation.parse("fixed").spec == "fixed:offset=0,scale=65535"
    assert Normalisation.parse("fixed:scale=1023").options == (("offset", 0.0), ("scale", 1023.0))
    with pytest.raises(ValueError, match="unknown normalisation 'zscore'.*Choices: fixed, baseline"):
        Normalisation.parse("zscore")
    with pytest.raises(ValueError, match="has no option 'high'"):
        Normalisation.parse("fixed:high=3")
    with pytest.raises(ValueError, match="0 ≤ low < high ≤ 100"):
        Normalisation.parse("baseline:low=50,high=10")
