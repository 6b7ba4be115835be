"""The person model (synthetic-forearm version 2): people differ in ways a classifier feels.

A reduced set (12 people × 5 gestures × 2 positions × 5 repetitions); per recording, the
onset window's features of tactbench's ``logreg`` (per frame: mean, standard deviation,
maximum, and the mean over a 4 × 4 partition of the skin), computed on the taxels. Leaving
people out costs a logistic regression accuracy (a corrected-t interval over 8 seeds below
0), and a 1-nearest-neighbour classifier's accuracy differs between people beyond binomial
noise (a variance component whose interval excludes 0). Both fail on the person model
before each person had their own way of doing each gesture (its gap's interval included
0, its variance component's too). The estimators are those of benchmarks/people.py, which
measures both on the default set with tactbench's own encoders and classifier.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from tactbench.data.splits import make_splits
from tactbench.data.windows import dataset_onsets, window_starts
from tactbench.datasets import people
from tactbench.datasets.synthetic import CIRCUMFERENCE_MM, LENGTH_MM
from tactbench.datasets.synthetic_forearm import generate

REPO = Path(__file__).resolve().parents[2]
L = 5
GRID = 4  # tactbench's logreg: the mean over a 4 × 4 partition of the image


def _bench():
    spec = importlib.util.spec_from_file_location("people_bench", REPO / "benchmarks" /
                                                  "people.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def reduced():
    ds = generate(users=12, repetitions=5, version=2)
    starts = window_starts([s.recording.n_frames for s in ds], L, dataset_onsets(ds))
    xy = ds.layout.positions
    cell = (np.clip((xy[:, 0] / CIRCUMFERENCE_MM * GRID).astype(int), 0, GRID - 1) * GRID
            + np.clip((xy[:, 1] / LENGTH_MM * GRID).astype(int), 0, GRID - 1))
    count = np.bincount(cell, minlength=GRID * GRID).clip(1)
    feats = []
    for s, a in zip(ds, starts):
        v = np.nan_to_num(ds.normalise(s.recording.values))[a:a + L]
        pooled = np.zeros((GRID * GRID, L))
        np.add.at(pooled, cell, v.T)
        feats.append(np.concatenate([v.mean(1), v.std(1), v.max(1),
                                     (pooled / count[:, None]).ravel()]))
    return ds, np.array(feats)


def _standard(x, train):
    return (x - x[train].mean(0)) / (x[train].std(0) + 1e-6)


def _nearest(x, y, train, test):
    z = _standard(x, train)
    d = ((z[test][:, None, :] - z[train][None]) ** 2).sum(-1)
    return y[train][d.argmin(1)]


def _logreg(x, y, train, test):
    from sklearn.linear_model import LogisticRegression

    z = _standard(x, train)
    return LogisticRegression(max_iter=500).fit(z[train], y[train]).predict(z[test])


@pytest.mark.slow("trains enough cells on both splits for an accuracy difference to show")
def test_leaving_people_out_costs_accuracy(reduced):
    ds, x = reduced
    y, users = ds.labels, np.asarray(ds.users)
    diffs, ratios = [], []
    for seed in range(8):
        acc = {}
        for split in ("paper", "users"):
            [s] = make_splits(split, labels=y, users=users, seed=seed, test_per_class=6)
            acc[split] = (_logreg(x, y, s.train, s.test) == y[s.test]).mean()
            ratios.append(len(s.test) / len(s.train))
        diffs.append(acc["users"] - acc["paper"])
    gap = _bench().corrected_t_interval(diffs, max(ratios))
    assert gap["high"] < 0, gap  # users split harder, interval excludes 0
    assert gap["mean"] < -0.1, gap


def test_accuracy_differs_between_people_beyond_binomial_noise(reduced):
    ds, x = reduced
    y, users = ds.labels, np.asarray(ds.users)
    correct = np.zeros(len(y), dtype=bool)
    for fold in make_splits("users:folds=3", labels=y, users=users, seed=0):
        correct[fold.test] = _nearest(x, y, fold.train, fold.test) == y[fold.test]
    v = _bench().between_person_variance(correct, users)
    assert v["people"] == 12 and v["tests_per_person"] == 50
    assert v["per_person_sd"] > v["binomial_sd"] and v["low"] > 0, v  # interval excludes 0
    assert v["chi2_p"] < 0.01
    # the estimator itself: people who all score alike show no variance beyond noise
    rng = np.random.default_rng(0)
    alike = _bench().between_person_variance(rng.random(4000) < 0.6,
                                             np.repeat([f"p{i}" for i in range(40)], 100))
    assert alike["low"] < 0 < alike["high"] and alike["chi2_p"] > 0.05


def test_recordings_start_before_contact_and_end_after_release(reduced):
    ds, _ = reduced
    onsets = np.asarray(dataset_onsets(ds))
    names = np.asarray(ds.users)
    assert np.median(onsets) >= 3 and (onsets == 0).mean() < 0.1  # a lead-in without touch
    # the lead-in is a personal habit: people differ more than one person's recordings do
    per_person = [onsets[names == u] for u in np.unique(names)]
    assert np.var([p.mean() for p in per_person]) > np.mean([p.var() for p in per_person]) / 50
    tails = []
    for s in ds:
        total = np.nansum(ds.normalise(s.recording.values), axis=1)
        contact = total - total.min() > 0.1 * np.ptp(total)
        tails.append(len(contact) - 1 - np.flatnonzero(contact)[-1])
    assert np.median(tails) >= 3  # released, then frames without contact


def test_people_are_drawn_from_the_documented_distributions():
    ps = [people.make_person(0, i) for i in range(400)]
    hands = np.array([p.hand_mm for p in ps])
    assert hands.min() >= 160 and hands.max() <= 200 and abs(np.median(hands) - 180) < 2
    slop = np.array([p.sloppiness for p in ps])
    assert 0.9 < np.median(slop) < 1.1 and np.percentile(slop, 90) > 1.6  # some are sloppy
    tips = np.array([p.fingertips for p in ps])
    assert np.allclose(tips.mean(0), people.FINGERTIP_GRIP, atol=0.07)  # alike for the three
    assert 0.4 < np.mean([p.push_flat for p in ps]) < 0.7
    lead = np.array([p.lead_in for p in ps])
    assert lead.min() >= 0.1 and lead.max() <= 2.0 and 0.5 < np.median(lead) < 0.7
    # each person does each gesture their own way: placement, force and tempo per gesture,
    # spread as documented, and which parts of the hand land drawn with the person's odds
    habits = np.array([[(h.dx, h.dy, np.log(h.force), np.log(h.tempo)) for h in p.habits]
                       for p in ps])
    assert habits.shape == (400, 5, 4)
    assert np.allclose(habits.reshape(-1, 4).std(0),
                       [*people.GESTURE_PLACE_MM, people.GESTURE_FORCE_SIGMA,
                        people.GESTURE_TEMPO_SIGMA], rtol=0.08)
    assert np.abs(habits.reshape(-1, 4).mean(0)).max() < 1.5  # centred on the person's style
    parts = np.array([[h.parts for h in p.habits] for p in ps], dtype=float)  # (400, 5, 5)
    odds = np.array([p.part_p for p in ps])
    assert np.allclose(parts.mean((0, 1)), odds.mean(0), atol=0.03)
    assert (parts.std(1) > 0).mean() > 0.5  # the same person lands different parts per gesture
    # a person is the same whoever else is generated, and a session shifts them a little
    assert repr(people.make_person(0, 7)) == repr(ps[7])
    a = people.make_session(0, ps[0], "front")
    b = people.make_session(0, ps[0], "side")
    assert a != b and abs(a.force - 1) < 0.4 and abs(a.dx) < 25


def test_leaving_people_out_costs_accuracy_on_the_same_recordings(reduced):
    """benchmarks/people.py's design: every recording tested once by a model that never
    saw its person (users:folds=5) and once by one that saw the person's other repetitions
    (group:repetition:folds=5); the difference per users fold, on that fold's recordings."""
    from tactbench.data.splits import dataset_groups

    ds, x = reduced
    y, users = ds.labels, np.asarray(ds.users)
    bench = _bench()
    diffs = []
    for seed in range(2):
        pred = {}
        for design in (bench.UNSEEN, bench.SEEN):
            p = np.full(len(y), -1)
            for fold in make_splits(design, labels=y, users=users, seed=seed,
                                    groups=dataset_groups(ds)):
                p[fold.test] = _logreg(x, y, fold.train, fold.test)
            assert (p >= 0).all()  # each design tests every recording once
            pred[design] = {"indices": list(range(len(y))), "labels": y.tolist(),
                            "predictions": p.tolist()}
        folds = make_splits(bench.UNSEEN, labels=y, users=users, seed=seed)
        diffs += bench.paired_fold_differences(pred[bench.UNSEEN], pred[bench.SEEN], folds)
    gap = bench.corrected_kfold_interval(diffs, bench.FOLDS)
    assert gap["runs"] == 10 and gap["test_train_ratio"] == pytest.approx(0.25)
    assert gap["high"] < 0, gap  # people unseen: lower, the interval excludes 0
    # the two designs must have tested the same recordings
    short = {"indices": [0], "labels": [0], "predictions": [0]}
    with pytest.raises(SystemExit, match="same recordings"):
        bench.paired_fold_differences(pred[bench.UNSEEN], short, folds)
