"""The gesture simulator: shape of the dataset, determinism, cache, and the physics it claims."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.datasets import synthetic
from tactbench.datasets.synthetic import (
    CLASSES,
    SyntheticForearm,
    _rng,
    generate,
    make_device,
    make_user,
    simulate_pressure,
)
from tactbench.plugins import load_registry


@pytest.fixture(scope="module")
def small():
    return generate(users=2, repetitions=1)


@pytest.fixture(scope="module")
def device():
    return make_device(0)


def test_small_dataset_shape(small):
    assert len(small) == 2 * 5 * 2 * 1
    assert small.classes == CLASSES == ("Grasp", "2hGrasp", "Twist", "Push", "Pull")
    assert np.bincount(small.labels).tolist() == [4] * 5
    assert set(small.users) == {"u00", "u01"} and set(small.positions) == {"front", "side"}
    assert small.layout.n_taxels == 1558 and small.n_taxels == 1558
    for s in small:
        rec = s.recording
        assert 5 <= rec.n_frames <= 27
        assert np.allclose(np.diff(rec.timestamps), 0.1, atol=0.01)  # 10 Hz
        v = rec.values
        assert v.min() >= 0 and v.max() <= 65535 and np.array_equal(v, np.round(v))  # 16 bit


def test_images_at_a_coarse_pixel_size(small):
    imgs = small.images(pixel_mm=5.0)
    assert all(img.shape[1:] == (72, 67) and img.dtype == np.float32 for img in imgs)
    assert all(0 <= img.min() and img.max() <= 1 for img in imgs)
    # every sample touches the skin: the last frame has pressure somewhere
    assert all(img[-1].max() > 0.1 for img in imgs)


def test_deterministic_and_seeded(small):
    again = generate(users=2, repetitions=1)
    assert again.content_hash() == small.content_hash()
    other = generate(users=2, repetitions=1, seed=1)
    assert other.content_hash() != small.content_hash()


def test_a_users_samples_do_not_depend_on_how_many_users(small):
    three = generate(users=3, repetitions=1)
    first = [s for s in three if s.user in ("u00", "u01")]
    assert len(first) == len(small)
    for a, b in zip(small, first):
        assert np.array_equal(a.recording.values, b.recording.values)


def test_registered_and_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path))
    source = load_registry().build("dataset", "synthetic-forearm:users=1,repetitions=1")
    assert isinstance(source, SyntheticForearm)
    ds = source.load()
    folder = source.cache_path()
    assert folder.parent == tmp_path / "datasets" and (folder / "manifest.json").is_file()
    assert SyntheticForearm(users=1, repetitions=1).load().content_hash() == ds.content_hash()
    # a corrupted cache entry is regenerated, not trusted
    (folder / "arrays.npz").write_bytes(b"garbage")
    assert SyntheticForearm(users=1, repetitions=1).load().content_hash() == ds.content_hash()
    # the key follows the options and the generator version
    assert SyntheticForearm(users=2).cache_key() != SyntheticForearm(users=1).cache_key()
    monkeypatch.setattr(synthetic, "GENERATOR_VERSION", synthetic.GENERATOR_VERSION + 1)
    assert SyntheticForearm(users=1, repetitions=1).cache_path() != folder


def test_options_are_checked():
    with pytest.raises(ValueError, match="option users must be an integer"):
        SyntheticForearm(users="many")
    with pytest.raises(ValueError, match="has no option 'user'; did you mean 'users'"):
        load_registry().build("dataset", "synthetic-forearm:user=2")
    with pytest.raises(ValueError, match=r"option positions must be in 1..2 \(front, side\)"):
        generate(users=1, positions=3)
    with pytest.raises(ValueError, match="option seed must be ≥ 0"):
        SyntheticForearm(seed=-1)
    with pytest.raises(ValueError, match="unknown gesture 'Pat'"):
        simulate_pressure("Pat", make_user(0, 0), "front", _rng(0), np.zeros(3), np.zeros((2, 2)))


def test_sensor_model_has_dead_taxels_and_varied_baselines(device):
    assert device.dead.sum() == synthetic.DEAD_TAXELS
    assert device.baseline.std() > 100 and 0.7 < np.median(device.gain) < 1.3


# ------------------------------------------------------------------- physics

T = np.arange(0.0, 2.5, 0.05)


def _pressure(gesture, device, index, position="front"):
    user = make_user(0, index)
    return simulate_pressure(gesture, user, position, _rng("test", gesture, index), T,
                             device.layout.positions)


def _centroid(p, xy):
    w = p.sum(axis=1, keepdims=True) + 1e-9
    dx = (xy[:, 0] - synthetic.TOP_X + synthetic.CIRCUMFERENCE_MM / 2) % \
        synthetic.CIRCUMFERENCE_MM  # unwrap around the top of the arm
    return np.column_stack([(p * dx).sum(1), (p * xy[:, 1]).sum(1)]) / w


def test_grasp_settles_within_about_half_a_second(device):
    settled = []
    for i in range(12):
        total = _pressure("Grasp", device, i).sum(axis=1)
        final = total[T >= 1.5].mean()
        settled.append(np.abs(total[(T >= 0.5)] - final).max() / final)
    assert np.median(settled) < 0.1


def test_twist_rolls_round_the_axis_and_pull_shifts_along_it(device):
    xy = device.layout.positions
    moves = {"Twist": [], "Pull": [], "Grasp": []}
    for g in moves:
        for i in range(10):
            c = _centroid(_pressure(g, device, i), xy)
            early, late = c[(T > 0.3) & (T < 0.45)].mean(0), c[T > 2.2].mean(0)
            moves[g].append(np.abs(late - early))
    twist, pull, grasp = (np.median(np.array(moves[g]), axis=0) for g in ("Twist", "Pull",
                                                                          "Grasp"))
    assert twist[0] > 2 * twist[1] and twist[0] > 3 * grasp[0]  # round the arm (x)
    assert pull[1] > 2 * pull[0] and pull[1] > 3 * grasp[1]  # along the arm (y)


def test_twist_keeps_changing_fingertip_pressure(device):
    def late_change(g):
        out = []
        for i in range(10):
            p = _pressure(g, device, i)
            out.append(np.abs(np.diff(p[(T > 0.5) & (T < 1.5)], axis=0)).sum(1).mean()
                       / p[T > 0.5].sum(1).mean())
        return np.median(out)

    assert late_change("Twist") > 2 * late_change("Grasp")


def test_push_rises_while_the_contact_spreads(device):
    rising, spreading = [], []
    for i in range(10):
        p = _pressure("Push", device, i)
        total = p.sum(1)
        area = (p > 3.0).sum(1)  # taxels above 3 kPa
        k = int(np.argmax(total))
        rising.append(k > 3 and total[k // 2] < 0.8 * total[k])
        spreading.append(area[k] > area[max(k // 3, 1)])
    assert np.mean(rising) >= 0.7 and np.mean(spreading) >= 0.7


def test_grasp_twist_pull_share_contact_shapes(device):
    """Contact area a moment after touching overlaps between the three (same hand model)."""
    areas = {g: [] for g in ("Grasp", "Twist", "Pull")}
    for g in areas:
        for i in range(12):
            p = _pressure(g, device, i)
            areas[g].append((p[(T > 0.35) & (T < 0.5)] > 3.0).sum(1).mean())
    lo = max(np.percentile(a, 25) for a in areas.values())
    hi = min(np.percentile(a, 75) for a in areas.values())
    assert lo < hi  # interquartile ranges overlap


def test_no_class_is_given_away_by_one_trivial_cue():
    """Length, total pressure or contact position alone do not identify the gesture.

    For each cue, a one-feature Gaussian classifier trained on half of the users
    and tested on the other half stays far from perfect (chance is 0.2).
    """
    ds = generate(users=6, repetitions=2)
    vec = ds.vectors()
    xy = ds.layout.positions
    users = np.array([int(u[1:]) for u in ds.users])
    feats = {
        "length": np.array([len(v) for v in vec], dtype=float),
        "mean total pressure": np.array([v.sum(1).mean() for v in vec]),
        "final total pressure": np.array([v[-1].sum() for v in vec]),
        "centroid x": np.array([(v.sum(0) * xy[:, 0]).sum() / (v.sum() + 1e-9) for v in vec]),
        "centroid y": np.array([(v.sum(0) * xy[:, 1]).sum() / (v.sum() + 1e-9) for v in vec]),
    }
    y = ds.labels
    for name, x in feats.items():
        accs = []
        for fold in (0, 1):
            train, test = users % 2 != fold, users % 2 == fold
            mu = np.array([x[train & (y == c)].mean() for c in range(5)])
            sd = np.array([x[train & (y == c)].std() + 1e-9 for c in range(5)])
            ll = -0.5 * ((x[test, None] - mu) / sd) ** 2 - np.log(sd)
            accs.append((ll.argmax(1) == y[test]).mean())
        assert np.mean(accs) < 0.6, f"{name} alone classifies {np.mean(accs):.0%} of samples"


def test_load_reports_progress_through_its_callback_and_never_draws(tmp_path, monkeypatch,
                                                                    capfd):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path))
    calls = []
    source = SyntheticForearm(users=1, repetitions=1, positions=1)
    source.load(progress=lambda done, total: calls.append((done, total)))
    assert calls == [(k, 5) for k in range(1, 6)]
    calls.clear()
    source.load(progress=lambda done, total: calls.append((done, total)))
    assert calls == []  # the cache answered
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert [p.name for p in (tmp_path / "datasets").iterdir()] == [source.cache_path().name]
