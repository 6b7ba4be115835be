"""Signed readings in an own-data folder (each recording minus its baseline, so many are
negative): clipped at 0 by default, so that rest images as no contact as every later
stage assumes, and the user is told in one line what was done and how to keep the sign."""

from __future__ import annotations

import importlib.util
import logging
import re
from pathlib import Path

import numpy as np
import pytest

from tactbench.datasets.folder import read_folder
from tactbench.datasets.loading import load_dataset
from tactbench.plugins import load_registry

NOTE = "tactbench: note:"
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def signed_folder(tmp_path_factory):
    """The simulator's recordings as a 'real' sensor gives them (rest ≈ 300 counts with
    noise, contact up to +1000), each minus its own baseline (the mean of its first 3
    frames): ROOT/<class>/<user>_<rep>.npy grids, many readings negative."""
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


def _mean_flow(ds, pixel_mm=10.0, n=6):
    """Mean Farnebäck flow (px/frame) over the frame pairs of ``n`` recordings."""
    encoder = load_registry().build("encoder", "farneback")
    flows = []
    for images in ds.images(pixel_mm)[:n]:
        f = encoder.flow(images[:-1], images[1:])
        flows.append(np.hypot(f[..., 0], f[..., 1]).mean())
    return float(np.mean(flows))


def test_signed_readings_are_clipped_at_0_so_rest_images_as_no_contact(signed_folder,
                                                                       caplog):
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        ds = read_folder(signed_folder, pitch_mm=10)
    [note] = _notes(caplog)
    assert "\n" not in note  # one line
    assert "% of the readings are negative" in note and "clipped at 0" in note
    raw = np.concatenate([s.recording.values.ravel() for s in ds.samples])
    assert (raw < 0).mean() > 0.2  # the fixture is what the issue describes
    # rest (a reading of 0) is what every later stage takes as no contact: image 0,
    # as the pixels off the skin and the frame the flow encoders put before the first
    assert ds.normalise(np.zeros((1, ds.n_taxels), np.float32)).max() == 0
    assert ds.normalise(np.minimum(ds.samples[0].recording.values, 0)).max() == 0
    images = ds.images(10.0)
    assert all(img.min() >= 0 and img.max() <= 1 for img in images)
    assert ds.normalisation == read_folder(signed_folder, pitch_mm=10, vmin=0).normalisation
    for name in ("raw", "farneback", "frame-diff"):
        out = load_registry().build("encoder", name).encode(images[0])
        assert np.isfinite(out).all(), name


def test_the_note_gives_the_option_that_keeps_the_sign_and_where_rest_then_reads(
        signed_folder, caplog):
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        read_folder(signed_folder, pitch_mm=10)
    [note] = _notes(caplog)
    lo = min(float(np.load(p).min()) for p in signed_folder.rglob("*.npy"))
    given = re.search(r"give vmin=(\S+) to keep the sign", note)
    assert given and float(given.group(1)) == pytest.approx(lo, rel=1e-3)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        signed = read_folder(signed_folder, pitch_mm=10, vmin=float(given.group(1)))
    assert _notes(caplog) == []  # a choice the user made is not remarked on
    rest = float(signed.normalise(np.zeros((1, signed.n_taxels), np.float32)).mean())
    assert 0 < rest < 1 and f"rest at {rest:.2f}" in note
    assert all(img.min() >= 0 and img.max() <= 1 for img in signed.images(10.0))


def test_readings_never_negative_keep_their_normalisation_and_give_no_note(
        signed_folder, tmp_path, caplog):
    for path in signed_folder.rglob("*.npy"):
        target = tmp_path / path.relative_to(signed_folder)
        target.parent.mkdir(exist_ok=True)
        np.save(target, np.abs(np.load(path)))
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        ds = read_folder(tmp_path, pitch_mm=10)
        read_folder(signed_folder, pitch_mm=10, normalisation="baseline")
    assert _notes(caplog) == []
    hi = max(float(np.load(p).max()) for p in tmp_path.rglob("*.npy"))
    assert dict(ds.normalisation.options) == {"offset": 0.0, "scale": hi}  # as before


def test_readings_all_at_or_below_0_keep_their_range(tmp_path, caplog):
    """Nothing above 0 to keep: clipped, every reading would be one value; their range
    is mapped as before, without a note."""
    rng = np.random.default_rng(0)
    for cls in ("a", "b"):
        (tmp_path / cls).mkdir()
        for i in range(2):
            np.save(tmp_path / cls / f"r{i}.npy",
                    -rng.uniform(0, 5, (4, 3, 3)).astype(np.float32))
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        ds = read_folder(tmp_path)
    assert _notes(caplog) == []
    lo = min(float(np.load(p).min()) for p in tmp_path.rglob("*.npy"))
    hi = max(float(np.load(p).max()) for p in tmp_path.rglob("*.npy"))
    assert dict(ds.normalisation.options) == {"offset": lo, "scale": hi - lo}


def _bench():
    spec = importlib.util.spec_from_file_location("signed_bench", REPO / "benchmarks" /
                                                  "signed.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_real_cyskin_recordings_minus_their_baseline(shared_data, tmp_path, caplog):
    """benchmarks/signed.py's folder (real CySkin recordings, each minus its baseline),
    10 recordings a class: clipped by default, rest images at 0, and kept signed the
    flow follows the dips (the benchmark trains the CNN on all of it)."""
    made = _bench().make_signed_folder(shared_data / "cyskin-fingers", tmp_path, limit=10)
    assert made["recordings"] == 60 and made["negative_share"] > 0.2
    with caplog.at_level(logging.WARNING, logger="tactbench.datasets"):
        clipped = read_folder(tmp_path)
    [note] = _notes(caplog)
    assert "clipped at 0" in note
    assert clipped.normalise(np.zeros((1, clipped.n_taxels), np.float32)).max() == 0
    lo = min(float(np.load(p).min()) for p in tmp_path.rglob("*.npy"))
    signed = read_folder(tmp_path, vmin=lo)
    assert _mean_flow(signed, 5.0, 20) > 5 * _mean_flow(clipped, 5.0, 20)


def test_plan_says_the_note_once_though_it_times_a_second_load(signed_folder, tmp_path,
                                                                 caplog):
    from tactbench.runner import Scene
    from tactbench.runner import forecast

    scene = Scene(dataset=str(signed_folder), encoders=["raw"], classifiers=["logreg"],
                  seeds=[0, 1, 2], test_per_class=1, out=str(tmp_path / "out"))
    with caplog.at_level(logging.WARNING):
        forecast(scene, load_registry())
    assert len(_notes(caplog)) == 1
    assert logging.getLogger("tactbench.datasets").isEnabledFor(logging.WARNING)  # restored
