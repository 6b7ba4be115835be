"""The recipe options of small-cnn-lstm: temporal heads, label smoothing, augmentation,
one-cycle schedule, a validation split carved by recording with the best weights kept."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tactbench.classifiers.io import load_model
from tactbench.classifiers.nets import SequenceNet, SmallCNN
from tactbench.classifiers.training import (
    VAL_WINDOWS,
    BestWeights,
    augment_windows,
    carve_validation,
)
from tactbench.data.windows import Windows, test_windows, training_windows
from tactbench.errors import InputError
from tactbench.plugins import load_registry

from .test_classifiers import moving_blobs

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = ("small-cnn-lstm:epochs=2,windows_per_epoch=0,batch_size=8,input_size=12,width=4,"
        "hidden=8,fc=16")


def build(**options):
    return load_registry().build("classifier", TINY, **options)


def data(L=3, **kw):
    seqs, labels = moving_blobs(**kw)
    return training_windows(seqs, labels, L), test_windows(seqs, labels, L)


@pytest.mark.parametrize("head", ["lstm", "concat", "tcn"])
def test_every_head_maps_windows_to_logits(head):
    net = SequenceNet(SmallCNN(2, 4, 2), frame_shape=(2, 12, 12), n_classes=5, hidden=8,
                      fc=16, dropout=0.0, input_size=12, temporal=head, L=4)
    x = torch.rand(3, 4, 2, 12, 12)
    assert net(x).shape == (3, 5)
    net.eval()  # BatchNorm's running statistics: the same features either way
    feats = net.encode(x.reshape(12, 2, 12, 12)).reshape(3, 4, -1)
    assert torch.allclose(net.classify(feats), net(x), atol=1e-6)


def test_the_lstm_head_keeps_the_parameter_names_models_were_saved_with():
    net = SequenceNet(SmallCNN(1, 4, 2), frame_shape=(1, 12, 12), n_classes=3, hidden=8,
                      fc=16, dropout=0.0, input_size=12)
    assert {k.split(".")[0] for k in net.state_dict()} == {"normalize", "encoder", "lstm",
                                                           "head"}


@pytest.mark.parametrize("options", [
    {"head": "concat"}, {"head": "tcn"},
    {"head": "concat", "label_smoothing": 0.1, "optimizer": "adamw", "schedule": "onecycle",
     "shift": 1, "gain": 0.2},
    {"head": "concat", "val_fraction": 0.3, "patience": 1, "epochs": 3},
])
def test_recipes_learn_reproduce_and_read_back(options, tmp_path):
    train, test = data()
    a, b = build(**options), build(**options)
    a.fit(train, seed=0)
    b.fit(train, seed=0)
    pa = a.predict_proba(test)
    assert np.array_equal(pa, b.predict_proba(test))  # same seed, one thread: same model
    a.save(tmp_path / "m.safetensors")
    loaded, _ = load_model(tmp_path / "m.safetensors")
    assert loaded.options() == a.options()
    assert np.allclose(loaded.predict_proba(test), pa, atol=1e-6)


def test_a_new_option_at_its_default_trains_the_model_of_before():
    train, test = data()
    plain, explicit = build(), build(head="lstm", label_smoothing=0.0, shift=0, gain=0.0,
                                     val_fraction=0.0, patience=0)
    plain.fit(train, seed=1)
    explicit.fit(train, seed=1)
    assert np.array_equal(plain.predict_proba(test), explicit.predict_proba(test))


def test_concat_refuses_windows_of_another_length():
    train, _ = data(L=3)
    clf = build(head="concat")
    clf.fit(train, seed=0)
    with pytest.raises(InputError, match="L = 3"):
        clf.predict(np.zeros((2, 4, 1, 12, 12), np.float32))


@pytest.mark.parametrize("options, message", [
    ({"head": "gru"}, "head"),
    ({"label_smoothing": 1.0}, "label_smoothing"),
    ({"patience": 2}, "val_fraction"),
    ({"shift": 1, "shared_features": 1}, "shared_features=0"),
    ({"shift": 9}, "shift"),
    ({"schedule": "triangle"}, "schedule"),
])
def test_bad_recipe_options_are_one_line_errors(options, message):
    with pytest.raises(InputError, match=message):
        build(**options)


def test_early_stopping_keeps_the_best_epoch_and_reports_it():
    train, _ = data(n=30)
    clf = build(head="concat", val_fraction=0.3, epochs=4)
    report = clf.fit(train, seed=0)
    assert len(report["val_accuracy"]) == report["epochs"] == 4
    assert report["val_accuracy"][report["best_epoch"] - 1] == max(report["val_accuracy"])
    assert report["train_cpu_seconds"] > 0


def test_best_weights_restores_the_best_and_counts_patience():
    net = torch.nn.Linear(2, 2)
    best = BestWeights(patience=2)
    assert not best.update(net, 0.5, 1)
    kept = net.weight.detach().clone()
    with torch.no_grad():
        net.weight.add_(1.0)
    assert not best.update(net, 0.4, 2)
    assert best.update(net, 0.5, 3)  # not better: two epochs without a gain
    best.restore(net)
    assert torch.equal(net.weight, kept) and best.epoch == 1


def test_validation_is_carved_by_whole_recordings_of_every_class():
    train, _ = data(n=30)
    rest, val = carve_validation(train, 0.2, seed=0)
    assert set(rest.seq_index).isdisjoint(val.seq_index)
    assert len(rest) + len(val) == len(train)
    assert set(val.labels) == set(train.labels)
    again = carve_validation(train, 0.2, seed=0)[1]
    assert np.array_equal(again.seq_index, val.seq_index)
    users = np.arange(30) % 5  # recording → user: whole users held out
    rest, val = carve_validation(train, 0.2, seed=0, groups=users)
    assert len(set(users[val.seq_index])) == 1
    assert set(users[rest.seq_index]).isdisjoint(users[val.seq_index])


def test_validation_windows_are_capped():
    seqs = [np.zeros((VAL_WINDOWS + 10, 1, 2, 2), np.float32) for _ in range(4)]
    train = training_windows(seqs, [0, 0, 1, 1], 1)
    assert len(carve_validation(train, 0.5, seed=0)[1]) == VAL_WINDOWS
    one = Windows(seqs[:1], np.zeros(3, np.int64), np.arange(3), np.zeros(3, np.int64), 1)
    with pytest.raises(InputError, match="val_fraction=0"):
        carve_validation(one, 0.5, seed=0)


def test_augmentation_moves_and_scales_whole_windows():
    x = torch.zeros(64, 3, 2, 8, 8)
    x[:, :, :, 4, 4] = 1.0
    out = augment_windows(x, np.random.default_rng(0), shift=1, gain=0.0)
    assert out.shape == x.shape and float(out.sum()) == float(x.sum())  # nothing falls off
    where = out[:, 0, 0].flatten(1).argmax(1)
    assert len(set(where.tolist())) == 9  # every offset in [-1, 1]² drawn
    for t in range(3):  # the same offset for every frame and channel of a window
        assert torch.equal(out[:, t], out[:, 0])
    scaled = augment_windows(x, np.random.default_rng(0), shift=0, gain=0.5)
    factor = scaled.amax(dim=(1, 2, 3, 4))
    assert float(factor.min()) >= np.exp(-0.5) - 1e-6 and float(factor.max()) <= np.exp(0.5)
    assert torch.equal(augment_windows(x, np.random.default_rng(0)), x)
