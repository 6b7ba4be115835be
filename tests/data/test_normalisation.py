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


@pytest.mark.parametrize("nan_fraction", [0.0, 0.02])
def test_baseline_fit_in_blocks_equals_the_plain_percentiles_to_the_bit(monkeypatch,
                                                                       nan_fraction):
    import tactbench.data.normalisation as norm

    monkeypatch.setattr(norm, "OFFSET_BLOCK_BYTES", 4 * 64 * 3)  # 3 taxels a block
    rng = np.random.default_rng(7)
    ids = np.arange(10)
    samples = []
    for k in range(4):
        values = rng.integers(0, 65535, size=(16, 10)).astype(np.float32)
        values[rng.random(values.shape) < nan_fraction] = np.nan
        samples.append(Sample(Recording(values, np.arange(16) * .1, ids), 0))
    before = [s.recording.values.copy() for s in samples]
    offset, scale = Normalisation.parse("baseline:low=5,high=99").fit(samples)

    stacked = np.concatenate(before, axis=0)
    pct = np.nanpercentile if nan_fraction else np.percentile
    want_offset = np.nan_to_num(pct(stacked, 5.0, axis=0), nan=0.0).astype(np.float32)
    rest = stacked - want_offset
    want_scale = max(float(np.percentile(rest[np.isfinite(rest)], 99.0)), 1.0)
    assert np.array_equal(offset, want_offset) and scale == want_scale
    for s, v in zip(samples, before):  # the readings themselves are left alone
        assert np.array_equal(s.recording.values, v, equal_nan=True)
