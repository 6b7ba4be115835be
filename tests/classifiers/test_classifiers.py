"""The classifier contract: build, fit, predict, reproduce, save and load."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest
import torch

from tactbench.classifiers import base, batching
from tactbench.classifiers.batching import FrameBank, WindowBatches, read_windows
from tactbench.classifiers.io import ModelFileError, load_model, read_header
from tactbench.classifiers.models import SmallCnnLstm
from tactbench.classifiers.training import TrainingInterrupted
from tactbench.data.windows import test_windows, training_windows
from tactbench.plugins import load_registry

#: Tiny settings so each fit takes well under a second.
TINY = {
    "small-cnn-lstm": "small-cnn-lstm:epochs=2,windows_per_epoch=0,batch_size=8,input_size=12,"
                      "width=4,hidden=8,fc=16",
    "cnn-lstm": "cnn-lstm:epochs=1,windows_per_epoch=16,batch_size=8,input_size=16,hidden=8,"
                "fc=8",
    "taxel-lstm": "taxel-lstm:epochs=2,windows_per_epoch=0,batch_size=8,width=16,features=8,"
                  "hidden=8,fc=16",
    "logreg": "logreg:max_iter=30",
}


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def moving_blobs(n=24, *, channels=1, size=12, seed=0, classes=3):
    """Sequences (T, C, size, size) of a 3×3 blob moving right / down / staying (by class)."""
    rng = np.random.default_rng(seed)
    seqs, labels = [], []
    for i in range(n):
        k = i % classes
        t_len = int(rng.integers(3, 7))
        seq = rng.random((t_len, channels, size, size), dtype=np.float32) * 0.05
        y0, x0 = rng.integers(1, 4, size=2)
        for t in range(t_len):
            dy, dx = [(0, t), (t, 0), (0, 0)][k % 3]
            seq[t, :, y0 + dy:y0 + dy + 3, x0 + dx:x0 + dx + 3] += 0.9
        seqs.append(np.clip(seq, 0, 1))
        labels.append(k)
    return seqs, np.array(labels)


def taxel_sequences(n=24, taxels=20, seed=0):
    """Taxel vectors (T, N): the class says which third of the taxels is pressed."""
    rng = np.random.default_rng(seed)
    seqs, labels = [], []
    for i in range(n):
        k = i % 3
        seq = rng.random((int(rng.integers(3, 7)), taxels), dtype=np.float32) * 0.1
        seq[:, k * 6:(k + 1) * 6] += 0.8
        seqs.append(seq)
        labels.append(k)
    return seqs, np.array(labels)


def data_for(name, **kw):
    seqs, labels = taxel_sequences(**kw) if name == "taxel-lstm" else moving_blobs(**kw)
    return training_windows(seqs, labels, 3), test_windows(seqs, labels, 3)


def build(name, **options):
    return load_registry().build("classifier", TINY[name], **options)


def fit(name, seed=0, **options):
    train, test = data_for(name)
    clf = build(name, **options)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cnn-lstm warns that it has no ImageNet weights
        report = clf.fit(train, test, seed=seed)
    return clf, report, test


@pytest.fixture(scope="module")
def fitted():
    """One fitted model of each classifier, shared by the read-only tests."""
    return {name: fit(name) for name in TINY}


# ----------------------------------------------------------------------------- registry


def test_builtin_classifiers_are_registered_without_importing_torch():
    names = load_registry().names("classifier")
    assert set(TINY) <= set(names)
    code = ("import sys, tactbench.classifiers, tactbench.plugins as p; "
            "p.load_registry(); print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"


def test_options_come_from_the_spec_and_unknown_ones_are_refused():
    clf = load_registry().build("classifier", "small-cnn-lstm:epochs=3,input_size=32")
    assert clf.epochs == 3 and clf.input_size == 32 and clf.width == 16
    with pytest.raises(ValueError, match="no option 'epoch'.*did you mean 'epochs'"):
        load_registry().build("classifier", "small-cnn-lstm:epoch=3")


# ----------------------------------------------------------------------------- predict


@pytest.mark.parametrize("name", list(TINY))
def test_predict_contract(fitted, name):
    clf, report, test = fitted[name]
    proba = clf.predict_proba(test)
    assert proba.shape == (len(test), 3) and proba.dtype == np.float32
    assert np.allclose(proba.sum(1), 1.0, atol=1e-5) and (proba >= 0).all()
    pred = clf.predict(test)
    assert pred.shape == (len(test),) and pred.dtype == np.int64
    assert np.array_equal(pred, proba.argmax(1))
    # An array of windows gives the same answer as the Windows object.
    assert np.allclose(clf.predict_proba(test.batch(slice(None))), proba, atol=1e-6)
    assert clf.predict_proba(test.batch(slice(0, 0))).shape == (0, 3)


@pytest.mark.parametrize("name", ["small-cnn-lstm", "taxel-lstm"])
def test_prediction_steps_shrink_to_a_byte_budget_with_the_same_answers(fitted, name,
                                                                        monkeypatch):
    clf, _report, test = fitted[name]
    whole = clf.predict_proba(test)
    assert clf._eval_step(test, clf.net) == clf.eval_batch_size  # tiny windows: no cap
    per_window = base.read_windows(test, slice(0, 1), clf.net.prepare).numel() * 4
    monkeypatch.setattr(base, "EVAL_INPUT_BYTES", 2 * per_window)
    assert clf._eval_step(test, clf.net) == 2
    assert np.allclose(clf.predict_proba(test), whole, atol=1e-6)


@pytest.mark.parametrize("name", list(TINY))
def test_fit_report(fitted, name):
    _clf, report, test = fitted[name]
    assert report["classifier"] == name and report["n_classes"] == 3
    assert report["epochs"] >= 1 and report["windows_seen"] > 0
    assert report["train_seconds"] > 0 and np.isfinite(report["final_loss"])
    assert len(report["val_accuracy"]) == report["epochs"]
    assert not report["interrupted"]
    json.dumps(report)  # JSON-ready


@pytest.mark.parametrize("name", ["small-cnn-lstm", "logreg", "taxel-lstm"])
def test_learns_an_easy_task(name):
    train, test = data_for(name, n=30)
    opts = {"small-cnn-lstm": {"epochs": 8}, "taxel-lstm": {"epochs": 15}}.get(name, {})
    clf = build(name, **opts)
    clf.fit(train, None, seed=1)
    assert (clf.predict(test) == test.labels).mean() >= 0.8


@pytest.mark.parametrize("name", list(TINY))
def test_same_seed_same_predictions_on_the_cpu(name):
    a, _, test = fit(name, seed=7)
    b, _, _ = fit(name, seed=7)
    assert np.array_equal(a.predict_proba(test), b.predict_proba(test))


def test_another_seed_gives_another_model():
    a, _, test = fit("small-cnn-lstm", seed=1)
    b, _, _ = fit("small-cnn-lstm", seed=2)
    assert not np.array_equal(a.predict_proba(test), b.predict_proba(test))


def test_fit_leaves_the_global_random_state_alone():
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    fit("small-cnn-lstm")
    assert torch.equal(torch.rand(3), expected)


# ----------------------------------------------------------------------------- classes


def test_n_classes_can_exceed_the_labels_seen():
    train, test = data_for("small-cnn-lstm")
    clf = build("small-cnn-lstm")
    report = clf.fit(train, None, seed=0, n_classes=5)
    assert report["n_classes"] == 5 and clf.predict_proba(test).shape == (len(test), 5)
    assert build("small-cnn-lstm", classes=4).fit(train, None, seed=0)["n_classes"] == 4
    with pytest.raises(ValueError, match="labels go up to 2 but only 2 classes"):
        build("small-cnn-lstm").fit(train, None, seed=0, n_classes=2)


# ----------------------------------------------------------------------------- bad input


def test_bad_input_is_refused_with_a_clear_message(fitted):
    train, _ = data_for("small-cnn-lstm")
    vectors, _ = data_for("taxel-lstm")
    with pytest.raises(ValueError, match="classifies taxel vectors"):
        build("taxel-lstm").fit(train, None, seed=0)
    with pytest.raises(ValueError, match="classifies images"):
        build("small-cnn-lstm").fit(vectors, None, seed=0)
    with pytest.raises(RuntimeError, match="not fitted"):
        build("small-cnn-lstm").predict(train)
    clf = fitted["small-cnn-lstm"][0]
    with pytest.raises(ValueError, match="do not match the trained frame shape"):
        clf.predict(np.zeros((2, 3, 2, 12, 12), np.float32))  # 2 channels, trained on 1
    with pytest.raises(ValueError, match="rank 5"):
        clf.predict(np.zeros((2, 12, 12), np.float32))
    with pytest.raises(TypeError, match="Windows"):
        build("small-cnn-lstm").fit(train.batch(slice(None)), None, seed=0)


def test_images_of_another_size_are_resized(fitted):
    clf, _, test = fitted["small-cnn-lstm"]
    bigger = np.repeat(np.repeat(test.batch(slice(0, 4)), 2, axis=-1), 2, axis=-2)
    assert clf.predict_proba(bigger).shape == (4, 3)


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is present on this machine")
def test_cuda_asked_for_without_cuda_is_an_error(fitted):
    train, _ = data_for("small-cnn-lstm")
    with pytest.raises(ValueError, match="CUDA is not available"):
        build("small-cnn-lstm").fit(train, None, seed=0, device="cuda")
    with pytest.raises(ValueError, match="CUDA is not available"):
        fitted["small-cnn-lstm"][0].to("cuda")


# ----------------------------------------------------------------------------- training


def test_progress_and_validation_accuracy_per_epoch():
    train, test = data_for("small-cnn-lstm")
    calls = []
    build("small-cnn-lstm", epochs=3).fit(train, test, seed=0,
                                          progress=lambda d, t, **i: calls.append((d, t, i)))
    steps = [c for c in calls if "val_accuracy" not in c[2]]
    evals = [c for c in calls if "val_accuracy" in c[2]]
    assert [c[0] for c in steps] == list(range(1, len(steps) + 1))
    assert steps[-1][0] == steps[-1][1]
    assert [c[2]["epoch"] for c in evals] == [1, 2, 3]


def test_keyboard_interrupt_leaves_a_usable_model():
    train, test = data_for("small-cnn-lstm")
    clf = build("small-cnn-lstm", epochs=50)

    def progress(done, total, **info):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(TrainingInterrupted):
        clf.fit(train, None, seed=0, progress=progress)
    assert clf.fit_report["interrupted"] and clf.fit_report["steps"] == 2
    assert clf.predict(test).shape == (len(test),)


def test_mixed_precision_on_the_cpu_trains_and_predicts():
    clf, report, test = fit("small-cnn-lstm", amp=True)
    assert report["amp"]
    assert np.isfinite(clf.predict_proba(test)).all()


def test_frame_bank_matches_windows_batch():
    seqs, labels = moving_blobs(6)
    windows = training_windows(seqs, labels, 5)  # some sequences are shorter: padded
    bank = FrameBank(windows, lambda t: t)
    idx = np.arange(len(windows))[::-1]
    x, y = bank.batch(idx)
    assert np.array_equal(x.numpy(), windows.batch(idx))
    assert np.array_equal(y.numpy(), windows.labels[idx])


@pytest.mark.parametrize("name", ["small-cnn-lstm", "taxel-lstm"])
def test_reading_per_batch_gives_the_same_model_as_the_frame_bank(monkeypatch, name):
    a, report_a, test = fit(name, seed=3)
    assert report_a["batches"] == "frame bank" and report_a["bank_mb"] > 0
    monkeypatch.setattr(batching, "BANK_BUDGET_BYTES", 0)  # nothing held: per batch
    b, report_b, _ = fit(name, seed=3)
    assert report_b["batches"] == "per batch" and report_b["loader_workers"] == 0
    assert np.array_equal(a.predict_proba(test), b.predict_proba(test))  # bit for bit
    assert report_a["val_accuracy"] == report_b["val_accuracy"]


def test_imagenet_and_no_normalisation():
    train, test = data_for("small-cnn-lstm", channels=3)
    clf = build("small-cnn-lstm", normalisation="imagenet")
    clf.fit(train, None, seed=0)
    assert torch.allclose(clf.net.normalize.mean.flatten(), torch.tensor([0.485, 0.456, 0.406]))
    with pytest.raises(ValueError, match="needs 3 channels"):
        build("small-cnn-lstm", normalisation="imagenet").fit(data_for("small-cnn-lstm")[0],
                                                              None, seed=0)
    clf = build("small-cnn-lstm", normalisation="none")
    clf.fit(train, None, seed=0)
    assert float(clf.net.normalize.std.min()) == 1.0


def test_the_old_option_name_normalize_is_refused_naming_the_new_one():
    """One spelling with the datasets' ``normalisation=``: no silent alias."""
    from tactbench.errors import InputError

    with pytest.raises(InputError, match="has no option 'normalize'; did you mean "
                                         "'normalisation'"):
        build("small-cnn-lstm", normalize="imagenet")


# ----------------------------------------------------------------------------- save / load


@pytest.mark.parametrize("name", list(TINY))
def test_save_and_load_round_trip(fitted, name, tmp_path):
    clf, _, test = fitted[name]
    meta = {"encoder": "farneback:winsize=9", "L": 3, "classes": ["a", "b", "c"],
            "input_size": getattr(clf, "input_size", None)}
    path = clf.save(tmp_path / "model.safetensors", meta)
    loaded, got = load_model(path)
    assert got == meta
    assert type(loaded) is type(clf) and loaded.options() == clf.options()
    assert loaded.n_classes == 3 and loaded.L == 3 and loaded.frame_shape == clf.frame_shape
    assert np.array_equal(loaded.predict_proba(test), clf.predict_proba(test))
    assert read_header(path)["classifier"] == name
    assert loaded.fit_report == json.loads(json.dumps(clf.fit_report))


def test_saving_needs_a_fitted_model_and_json_metadata(fitted, tmp_path):
    with pytest.raises(RuntimeError, match="not fitted"):
        build("small-cnn-lstm").save(tmp_path / "m.safetensors")
    with pytest.raises(ValueError, match="JSON"):
        fitted["logreg"][0].save(tmp_path / "m.safetensors", {"bad": object()})
    assert not (tmp_path / "m.safetensors").exists()


def test_corrupt_and_foreign_files_give_clear_errors(fitted, tmp_path):
    clf = fitted["small-cnn-lstm"][0]
    good = clf.save(tmp_path / "good.safetensors", {})
    data = good.read_bytes()

    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"\x00\x01not a model at all" * 10)
    with pytest.raises(ModelFileError, match="not a readable model file"):
        load_model(junk)

    truncated = tmp_path / "truncated.safetensors"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelFileError, match="truncated"):
        load_model(truncated)

    from safetensors.torch import save_file

    foreign = tmp_path / "foreign.safetensors"
    save_file({"w": torch.zeros(2)}, str(foreign))
    with pytest.raises(ModelFileError, match="not a tactbench model"):
        load_model(foreign)

    with pytest.raises(ModelFileError, match="does not exist"):
        load_model(tmp_path / "missing.safetensors")


def _rewrite_header(src, dst, edit):
    from safetensors import safe_open
    from safetensors.torch import save_file

    with safe_open(str(src), framework="pt") as f:
        header = json.loads(f.metadata()["tactbench"])
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    edit(header)
    from tactbench.classifiers.io import payload_digest  # a consistent file, re-signed

    header["checksum"]["digest"] = payload_digest(header, tensors)
    save_file(tensors, str(dst), metadata={"tactbench": json.dumps(header)})
    return dst


def test_mismatched_files_give_clear_errors(fitted, tmp_path):
    good = fitted["small-cnn-lstm"][0].save(tmp_path / "good.safetensors", {})

    def wider(h):
        h["config"]["options"]["width"] = 8

    with pytest.raises(ModelFileError, match="does not match classifier 'small-cnn-lstm'"):
        load_model(_rewrite_header(good, tmp_path / "a.safetensors", wider))

    def renamed(h):
        h["classifier"] = "no-such-model"

    with pytest.raises(ModelFileError, match="cannot rebuild classifier 'no-such-model'"):
        load_model(_rewrite_header(good, tmp_path / "b.safetensors", renamed))

    def newer(h):
        h["version"] = 99

    with pytest.raises(ModelFileError, match="newer"):
        load_model(_rewrite_header(good, tmp_path / "c.safetensors", newer))

    def other_kind(h):
        h["classifier"] = "logreg"

    with pytest.raises(ModelFileError, match="does not match classifier 'logreg'"):
        load_model(_rewrite_header(good, tmp_path / "d.safetensors", other_kind))


def test_a_failed_fit_leaves_no_model_that_looks_fitted():
    train, test = data_for("small-cnn-lstm")
    clf = build("small-cnn-lstm")

    def progress(done, total, **info):
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        clf.fit(train, None, seed=0, progress=progress)
    with pytest.raises(RuntimeError, match="not fitted"):
        clf.predict(test)


@pytest.mark.parametrize("spec", ["logreg", "taxel-lstm:epochs=4,windows_per_epoch=0,"
                                              "batch_size=32"])
def test_real_cyskin_recordings_without_a_layout(shared_data, spec):
    """The real CySkin finger-count recordings (716 taxels, no layout): trained on 9
    recordings per class, the held-out ones are recognised."""
    from tactbench.datasets.cyskin_text import read_cyskin_text

    root = shared_data / "cyskin-fingers"
    train_seqs, train_labels, test_seqs, test_labels = [], [], [], []
    for k, folder in enumerate(sorted(p for p in root.iterdir() if p.is_dir())):
        for i, path in enumerate(sorted(folder.glob("*.txt"))[:12]):
            values = read_cyskin_text(path).values
            # Raw counts reach ~20000; NaN marks a missing taxel.
            seq = np.clip(np.nan_to_num(values) / 20000.0, 0, 1).astype(np.float32)
            (test_seqs if i % 4 == 0 else train_seqs).append(seq)
            (test_labels if i % 4 == 0 else train_labels).append(k)
    train = training_windows(train_seqs, train_labels, 5)
    test = test_windows(test_seqs, test_labels, 5)
    clf = load_registry().build("classifier", spec)
    clf.fit(train, None, seed=0)
    assert clf.n_classes == 6 and clf.frame_shape == (716,)
    assert (clf.predict(test) == test.labels).mean() >= 0.8


@pytest.mark.parametrize("name", list(TINY))
def test_builtins_pass_the_conformance_checks(name):
    from tactbench.classifiers.conformance import check_classifier

    check_classifier(TINY[name])


class Unseeded(SmallCnnLstm):
    """A broken classifier: its probabilities are not reproducible."""

    name = "unseeded"

    def predict_proba(self, x):
        p = super().predict_proba(x)
        return (p + np.random.random(p.shape).astype(np.float32)) / 2


def test_the_conformance_checks_catch_a_broken_classifier():
    from tactbench.classifiers.conformance import check_classifier
    from tactbench.registry import Component, Registry

    registry = Registry([Component("classifier", "unseeded", f"{__name__}:Unseeded",
                                   "test", (), "test", "test")])
    with pytest.raises(AssertionError, match="same seed gave different probabilities"):
        check_classifier("unseeded:" + TINY["small-cnn-lstm"].split(":", 1)[1],
                         registry=registry)


def test_batchnorm_statistics_are_recalibrated_after_short_training():
    """EfficientNet's BN momentum is 0.01: a short fit leaves running statistics near
    their initial 0/1, which makes every test window look alike. cnn-lstm re-estimates
    them from the final weights."""
    def stem_var(clf):
        bn = next(m for m in clf.net.modules() if isinstance(m, torch.nn.BatchNorm2d))
        return bn.running_var.clone()

    stale, _, _ = fit("cnn-lstm", bn_recalibration_batches=0, epochs=1, windows_per_epoch=8)
    fresh, _, test = fit("cnn-lstm", epochs=1, windows_per_epoch=8)
    assert fresh.bn_recalibration_batches > 0  # on by default for cnn-lstm
    assert torch.allclose(stem_var(stale), torch.ones_like(stem_var(stale)), atol=0.1)
    assert not torch.allclose(stem_var(fresh), torch.ones_like(stem_var(fresh)), atol=0.1)
    # and it stays deterministic
    again, _, _ = fit("cnn-lstm", epochs=1, windows_per_epoch=8)
    assert np.array_equal(fresh.predict_proba(test), again.predict_proba(test))


# ----------------------------------------------------------------------------- memory


class CountingSequence:
    """A stored sequence (the interface of the runner's cache: ``shape``, ``len``,
    slicing, ``__array__``) over an array, that records every slice read from it."""

    def __init__(self, array: np.ndarray, reads: list) -> None:
        self._array, self.reads = array, reads
        self.shape, self.dtype, self.ndim = array.shape, np.dtype(np.float32), array.ndim

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, index):
        start, stop, _ = index.indices(len(self))  # slices only, like the cache's
        self.reads.append(stop - start)
        return self._array[index].copy()

    def __array__(self, dtype=None, copy=None):
        self.reads.append(len(self))
        return self._array.astype(dtype or np.float32)


def lazy_data(n=24, **kw):
    seqs, labels = moving_blobs(n, **kw)
    reads: list[int] = []
    lazy = [CountingSequence(s, reads) for s in seqs]
    return (training_windows(lazy, labels, 3), test_windows(lazy, labels, 3), reads,
            training_windows(seqs, labels, 3))


def test_read_windows_prepares_in_sub_batches_and_matches_the_frame_bank(monkeypatch):
    from tactbench.classifiers.nets import resize_frames

    train, _, reads, in_memory = lazy_data(size=12)
    prepare = lambda t: resize_frames(t, 5)  # noqa: E731
    idx = np.arange(len(train))[::-1]
    bank = FrameBank(in_memory, prepare)
    one_window = 3 * 1 * 12 * 12 * 4  # L × C × H × W float32
    monkeypatch.setattr(batching, "READ_CHUNK_BYTES", 2 * one_window)
    reads.clear()
    x = read_windows(train, idx, prepare)
    assert x.shape == (len(train), 3, 1, 5, 5)
    assert torch.equal(x, bank.batch(idx)[0])  # bit for bit, padding included
    assert max(reads) <= 3  # never more than one window's frames per read
    xb, yb = WindowBatches(train, prepare)[idx[:4]]
    assert torch.equal(xb, x[:4]) and np.array_equal(yb.numpy(), train.labels[idx[:4]])
    assert read_windows(train, idx[:0], prepare).shape == (0, 3, 1, 5, 5)


def test_a_fit_above_the_budget_reads_batches_and_never_builds_the_bank(monkeypatch):
    train, test, reads, _ = lazy_data()
    monkeypatch.setattr(batching, "BANK_BUDGET_BYTES", 1024)  # below this tiny bank

    def no_bank(*args, **kwargs):
        raise AssertionError("the frame bank was built above the budget")

    monkeypatch.setattr(batching.FrameBank, "__init__", no_bank)
    clf = build("small-cnn-lstm")
    report = clf.fit(train, None, seed=0)
    assert report["batches"] == "per batch" and report["bank_mb"] * 2 ** 20 > 1024
    longest = max(len(s) for s in train.sequences)
    assert reads and max(reads) <= longest  # no read of more than one sequence
    assert clf.predict(test).shape == (len(test),)


def test_the_normalisation_sample_is_read_lazily_and_merged_above_the_budget(monkeypatch):
    train, _, reads, in_memory = lazy_data(n=30, channels=2)
    whole = build("small-cnn-lstm")
    net = whole._build_net(train.frame_shape, 3, pretrained=False)
    with torch.no_grad():
        whole._set_normalization(net, in_memory, seed=0)
    monkeypatch.setattr(base, "NORM_SAMPLE_BYTES", 0)
    monkeypatch.setattr(batching, "READ_CHUNK_BYTES", 7 * 2 * 12 * 12 * 4)  # 7 frames
    streamed = build("small-cnn-lstm")._build_net(train.frame_shape, 3, pretrained=False)
    reads.clear()
    with torch.no_grad():
        build("small-cnn-lstm")._set_normalization(streamed, train, seed=0)
    assert max(reads) <= max(len(s) for s in train.sequences)
    assert torch.allclose(streamed.normalize.mean, net.normalize.mean, rtol=1e-5, atol=1e-7)
    assert torch.allclose(streamed.normalize.std, net.normalize.std, rtol=1e-5, atol=1e-7)


def test_streamed_statistics_equal_the_whole_arrays():
    from tactbench.classifiers.batching import streamed_mean_std

    x = torch.rand(50, 3, 4, 5, dtype=torch.float64) * torch.tensor([1.0, 5.0, 0.1]
                                                                     ).reshape(1, 3, 1, 1)
    mean, std = streamed_mean_std([x[:7], x[7:8], x[8:8], x[8:]])
    assert torch.allclose(mean, x.mean(dim=[0, 2, 3])) and torch.allclose(std, x.std(dim=[0, 2, 3]))
    rows = torch.rand(40, 6, dtype=torch.float64)  # (windows, features): per column
    mean, std = streamed_mean_std([rows[:13], rows[13:]])
    assert torch.allclose(mean, rows.mean(0)) and torch.allclose(std, rows.std(0))


def test_logreg_above_the_budget_accumulates_over_chunks_with_the_same_result(monkeypatch):
    import tactbench.classifiers.classical as classical

    train, test, reads, _ = lazy_data(n=30)
    whole = build("logreg")
    whole.fit(train, None, seed=0)
    monkeypatch.setattr(classical, "FEATURE_CHUNK", 16)
    for budget in (2000, 0):  # 2000 B: a bank of frame features; 0: read per chunk
        monkeypatch.setattr(batching, "BANK_BUDGET_BYTES", budget)
        reads.clear()
        chunked = build("logreg")
        chunked.fit(train, None, seed=0)
        assert max(reads) <= max(len(s) for s in train.sequences)
        assert np.allclose(chunked.predict_proba(test), whole.predict_proba(test), atol=1e-6)
        assert np.array_equal(chunked.predict(test), whole.predict(test))


def test_the_budget_can_be_set_from_the_environment(monkeypatch):
    from tactbench.classifiers.batching import bank_budget_bytes, loader_workers
    from tactbench.errors import InputError

    monkeypatch.setenv("TACTBENCH_BANK_MIB", "1.5")
    assert bank_budget_bytes() == int(1.5 * 2 ** 20)
    monkeypatch.setenv("TACTBENCH_BANK_MIB", "lots")
    with pytest.raises(InputError, match="TACTBENCH_BANK_MIB"):
        bank_budget_bytes()
    monkeypatch.delenv("TACTBENCH_BANK_MIB")
    assert bank_budget_bytes() == batching.BANK_BUDGET_BYTES
    assert loader_workers(torch.device("cpu")) == 0
    monkeypatch.setenv("TACTBENCH_LOADER_WORKERS", "-1")
    with pytest.raises(InputError, match="TACTBENCH_LOADER_WORKERS"):
        loader_workers(torch.device("cpu"))


def test_dataloader_workers_give_the_same_model(monkeypatch):
    a, _, test = fit("small-cnn-lstm", seed=4)
    monkeypatch.setattr(batching, "BANK_BUDGET_BYTES", 0)
    b, _, _ = fit("small-cnn-lstm", seed=4)
    monkeypatch.setenv("TACTBENCH_LOADER_WORKERS", "1")
    c, report, _ = fit("small-cnn-lstm", seed=4)
    assert report["loader_workers"] == 1
    assert np.array_equal(b.predict_proba(test), c.predict_proba(test))
