"""The ``sklearn`` classifier: conformance, features, options, seeding and model files."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("sklearn")

from tactbench.classifiers.io import load_model, read_header  # noqa: E402
from tactbench.classifiers.sklearn import SklearnClassifier, frame_features  # noqa: E402
from tactbench.data.windows import test_windows, training_windows  # noqa: E402
from tactbench.errors import InputError  # noqa: E402
from tactbench.plugins import load_registry  # noqa: E402
from tactbench.testing import check_classifier, tiny_windows  # noqa: E402


@pytest.fixture(scope="module")
def registry(one_torch_thread):
    """(One thread: scikit-learn follows torch's setting, and OpenMP threads waiting for
    each other on a busy 2-core machine make a tiny fit many times slower.)"""
    return load_registry()


@pytest.mark.parametrize("spec", [
    "sklearn:max_iter=20",  # HistGradientBoostingClassifier: predict_proba
    "sklearn:estimator=SVC,C=10",  # decision_function only (probability=False)
    "sklearn:estimator=LinearSVC",
    "sklearn:estimator=RandomForestClassifier,n_estimators=10,grid=2",
])
def test_conformance(spec, registry):
    check_classifier(spec, registry=registry)


def test_taxel_vectors_are_classified(registry):
    train, test = tiny_windows(1)
    clf = registry.build("classifier", "sklearn:estimator=RandomForestClassifier,"
                                       "n_estimators=20")
    clf.fit(train, None, seed=0, device="cpu", progress=None)
    assert (clf.predict(test) == test.labels).mean() >= 0.9


def test_image_features_by_hand():
    frames = np.zeros((2, 1, 5, 7), np.float32)
    frames[0, 0, 2, 3] = 0.7  # one pressed taxel, at row 2 of 5 and column 3 of 7
    f = frame_features(frames, grid=2)
    assert f.shape == (2, 8 + 4)
    mean, std, lo, hi, cy, sy, cx, sx = f[0, :8]
    assert mean == pytest.approx(0.7 / 35) and lo == 0 and hi == pytest.approx(0.7)
    assert (cy, cx) == (pytest.approx(2 / 4), pytest.approx(3 / 6))
    assert (sy, sx) == (0, 0)
    # 2 × 2 partition of 5 × 7: rows 0-2 | 3-4, columns 0-3 | 4-6; the taxel is top left
    assert f[0, 8:] == pytest.approx([0.7 / 12, 0, 0, 0])
    assert not f[1].any()  # a blank frame gives zeros


def test_spread_of_two_taxels_and_signed_channels():
    frames = np.zeros((1, 2, 3, 3), np.float32)
    frames[0, 0, 0, 0] = frames[0, 0, 2, 0] = 1.0  # rows 0 and 2 of column 0
    frames[0, 1, 1, 2] = -0.5  # a flow channel: the mass is |value|
    f = frame_features(frames, grid=1).reshape(2, 9)
    assert f[0, 4:8] == pytest.approx([0.5, 0.5, 0.0, 0.0])  # centre row 0.5, spread 0.5
    assert f[1, 2] == pytest.approx(-0.5) and f[1, 4:8] == pytest.approx([0.5, 0, 1.0, 0])


def test_vector_features_pool_consecutive_taxels():
    v = np.arange(8, dtype=np.float32)[None]
    f = frame_features(v, grid=2)  # 4 groups of 2 taxels
    assert f[0] == pytest.approx([3.5, np.std(np.arange(8)), 0, 7, 0.5, 2.5, 4.5, 6.5])


def test_windows_past_a_sequence_end_get_blank_features():
    seqs = [np.ones((2, 6), np.float32), np.ones((4, 6), np.float32)]
    clf = SklearnClassifier(grid=1)
    feats = clf._window_features(test_windows(seqs, [0, 1], 3))
    per_frame = feats.reshape(2, 3, -1)
    assert per_frame[0, 1].any() and not per_frame[0, 2].any()  # 2 frames, then blank
    assert per_frame[1, 2].any()


def test_random_state_comes_from_the_seed_unless_given(registry):
    train, _ = tiny_windows(3)
    clf = registry.build("classifier", "sklearn:estimator=RandomForestClassifier,"
                                       "n_estimators=5")
    clf.fit(train, None, seed=11, device="cpu")
    assert clf.model.random_state == 11
    fixed = registry.build("classifier", "sklearn:estimator=RandomForestClassifier,"
                                         "n_estimators=5,random_state=3")
    fixed.fit(train, None, seed=11, device="cpu")
    assert fixed.model.random_state == 3
    knn = registry.build("classifier", "sklearn:estimator=KNeighborsClassifier")
    knn.fit(train, None, seed=11, device="cpu")  # no random_state: nothing to set


@pytest.mark.parametrize("spec, match", [
    ("sklearn:estimator=HistGradientBoosting",
     "no classifier 'HistGradientBoosting'; did you mean 'HistGradientBoostingClassifier'"),
    ("sklearn:estimator=svc", "did you mean 'SVC'"),
    ("sklearn:estimator=SVC,gama=2", "SVC has no parameter 'gama' \\(did you mean 'gamma'"),
    ("sklearn:estimator=SVC,C=-1", "The 'C' parameter of SVC"),
    ("sklearn:estimator=OneVsRestClassifier", "cannot be built from text options"),
    ("sklearn:grid=0", "grid must be"),
])
def test_bad_options_are_one_line_at_build(spec, match, registry):
    with pytest.raises(InputError, match=match) as info:
        registry.build("classifier", spec)
    assert "\n" not in str(info.value)


def test_the_cpu_only_is_said(registry):
    train, _ = tiny_windows(3)
    with pytest.raises(InputError, match="runs on the CPU"):
        registry.build("classifier", "sklearn").fit(train, None, seed=0, device="cuda")


def test_an_estimator_with_only_predict_gives_one_hot_rows(monkeypatch):
    from sklearn.base import BaseEstimator, ClassifierMixin

    import tactbench.classifiers.sklearn as mod

    class MajorityOnly(ClassifierMixin, BaseEstimator):
        def fit(self, x, y):
            self.classes_ = np.unique(y)
            self.majority_ = np.bincount(y).argmax()
            return self

        def predict(self, x):
            return np.full(len(x), self.majority_)

    monkeypatch.setattr(mod, "estimator_classes", lambda: {"MajorityOnly": MajorityOnly})
    train, test = tiny_windows(3)
    clf = SklearnClassifier(estimator="MajorityOnly")
    clf.fit(train, None, seed=0, n_classes=4)
    proba = clf.predict_proba(test)
    majority = np.bincount(train.labels).argmax()
    assert proba.shape == (len(test), 4) and (proba[:, majority] == 1).all()
    assert proba.sum() == len(test)


def test_window_length_must_match(registry):
    train, _ = tiny_windows(3)
    clf = registry.build("classifier", "sklearn:estimator=KNeighborsClassifier")
    clf.fit(train, None, seed=0)
    longer = test_windows(list(train.sequences), list(range(len(train.sequences))), 4)
    with pytest.raises(InputError, match="L = 3"):
        clf.predict(longer)


def test_a_saved_model_refits_and_a_changed_one_is_refused(tmp_path, registry):
    train, test = tiny_windows(3)
    clf = registry.build("classifier", "sklearn:estimator=HistGradientBoostingClassifier,"
                                       "max_iter=20")
    clf.fit(train, None, seed=4)
    path = clf.save(tmp_path / "m.safetensors", {"classes": ["a", "b", "c"]})
    header = read_header(path)
    assert header["config"]["seed"] == 4 and header["config"]["sklearn"]
    loaded, meta = load_model(path, registry=registry)
    assert np.array_equal(loaded.predict_proba(test), clf.predict_proba(test))
    assert meta == {"classes": ["a", "b", "c"]}

    # What load_model hands to _restore, changed as a different scikit-learn would
    # change the refit: the saved predictions are not reproduced.
    config, tensors = clf.export()
    tensors = {k: v.clone() for k, v in tensors.items()}
    tensors["check_proba"] = tensors["check_proba"].flip(1)
    with pytest.raises(ValueError, match="does not reproduce the saved predictions"):
        SklearnClassifier._restore(json.loads(json.dumps(config)), tensors)
    del tensors["labels"]
    with pytest.raises(InputError, match="expected tensors"):
        SklearnClassifier._restore(config, tensors)
    config, tensors = clf.export()
    tensors["features"] = tensors["features"][:, :-1]
    with pytest.raises(InputError, match="do not fit"):
        SklearnClassifier._restore(config, tensors)


def test_saving_an_unfitted_model_is_refused(tmp_path):
    with pytest.raises(RuntimeError, match="not fitted"):
        SklearnClassifier().save(tmp_path / "m.safetensors")


def test_registering_and_importing_the_module_do_not_import_sklearn():
    code = ("import sys, tactbench.classifiers, tactbench.classifiers.sklearn; "
            "assert 'sklearn' not in sys.modules, 'sklearn imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_training_windows_of_two_sequences_and_more_classes_than_seen(registry):
    seqs = [np.zeros((4, 1, 6, 6), np.float32), np.ones((4, 1, 6, 6), np.float32)]
    train = training_windows(seqs, [0, 2], 2)
    clf = registry.build("classifier", "sklearn:estimator=DecisionTreeClassifier")
    clf.fit(train, None, seed=0, n_classes=3)
    p = clf.predict_proba(test_windows(seqs, [0, 2], 2))
    assert p.tolist() == [[1, 0, 0], [0, 0, 1]]
