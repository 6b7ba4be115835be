"""Signed readings in an own-data folder (each recording minus its baseline, so many are
negative): what reaches the encoders is in [0, 1], and the user is told in one line what
was done and how to choose otherwise."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from tactbench.datasets.folder import read_folder

NOTE = "tactbench: note:"


@pytest.fixture(scope="module")
def signed_folder(tmp_path_factory):
    """The simulator's recordings as a 'real' sensor gives them (rest ≈ 300 counts with
    noise, contact up to +1000), each minus its own baseline (the mean of its first 3
    frames): ROOT/<class>/<user>_<rep>.npy grids, many readings negative."""
    from tactbench.datasets.loading import load_dataset

    ds = load_dataset("synthetic-forearm:users=2,repetitions=1")
    rng = np.random.default_rng(3)
    root = tmp_path_factory.mktemp("signed")
    for i, (sample, frames) in enumerate(zip(ds.samples, ds.images(10.0))):
        counts = 300 + 1000 * frames + rng.normal(0, 8, frames.shape)
        signed = (counts - counts[:3].mean(axis=0)).astype(np.float32)
        folder = root / ds.classes[sample.label]
        folder.mkdir(exist_ok=True)
        np.save(folder / f"{sample.user}_{i}.npy", signed)
    return root


def _notes(caplog):
    return [r.getMessage() for r in caplog.records if r.getMessage().startswith(NOTE)]


def test_signed_readings_reach_the_encoders_in_range_and_the_user_is_told(
        signed_folder, caplog):
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        ds = read_folder(signed_folder, pitch_mm=10)
    [note] = _notes(caplog)
    assert "% of the readings are negative" in note and "vmin=0" in note
    assert "\n" not in note  # one line
    raw = np.concatenate([s.recording.values.ravel() for s in ds.samples])
    assert (raw < 0).mean() > 0.2  # the fixture is what the issue describes
    images = ds.images(10.0)
    assert all(img.min() >= 0 and img.max() <= 1 for img in images)
    rest = float(ds.normalise(np.zeros((1, ds.n_taxels), np.float32)).mean())
    assert f"a reading of 0 is {rest:.2f}" in note and 0 < rest < 1
    # the encoders take these frames as their contract says, and give finite values
    from tactbench.plugins import load_registry

    registry = load_registry()
    for name in ("raw", "farneback", "frame-diff"):
        out = registry.build("encoder", name).encode(images[0])
        assert np.isfinite(out).all(), name


def test_vmin_0_clips_signed_readings_at_rest_without_a_note(signed_folder, caplog):
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        ds = read_folder(signed_folder, pitch_mm=10, vmin=0)
        read_folder(signed_folder, pitch_mm=10, normalisation="baseline")
    assert _notes(caplog) == []  # a choice the user made is not remarked on
    values = ds.samples[0].recording.values
    assert ds.normalise(np.minimum(values, 0)).max() == 0  # below rest reads as no pressure
    assert all(img.min() >= 0 and img.max() <= 1 for img in ds.images(10.0))


def test_readings_that_are_never_negative_give_no_note(signed_folder, tmp_path, caplog):
    for path in signed_folder.rglob("*.npy"):
        target = tmp_path / path.relative_to(signed_folder)
        target.parent.mkdir(exist_ok=True)
        np.save(target, np.abs(np.load(path)))
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        read_folder(tmp_path, pitch_mm=10)
    assert _notes(caplog) == []
