"""The plain-torch EfficientNet-B0 and loading public B0 state dicts into it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from tactbench.classifiers.efficientnet import (
    EfficientNetB0,
    detect_layout,
    export_state_dict,
    load_weights,
)


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _model(channels=3, seed=0):
    torch.manual_seed(seed)
    return EfficientNetB0(channels).eval()


def test_b0_has_the_published_size_and_shape():
    model = _model()
    # EfficientNet-B0 has 5,288,548 parameters, 1,281,000 of them in the ImageNet
    # classifier (1280 × 1000 + 1000), which a feature extractor leaves out.
    assert sum(p.numel() for p in model.parameters()) == 5_288_548 - 1_281_000
    assert len(model.blocks) == 16
    with torch.no_grad():
        assert model(torch.zeros(2, 3, 32, 32)).shape == (2, 1280)
        assert _model(1)(torch.zeros(1, 1, 40, 48)).shape == (1, 1280)


#: Keys and shapes from each public implementation's own naming (a few per layout:
#: first block without expansion, an expanding block, the last block, the head).
ANCHORS = {
    "lukemelas": {
        "_conv_stem.weight": (32, 3, 3, 3),
        "_blocks.0._depthwise_conv.weight": (32, 1, 3, 3),
        "_blocks.0._se_reduce.weight": (8, 32, 1, 1),
        "_blocks.0._project_conv.weight": (16, 32, 1, 1),
        "_blocks.1._expand_conv.weight": (96, 16, 1, 1),
        "_blocks.1._bn0.running_var": (96,),
        "_blocks.15._project_conv.weight": (320, 1152, 1, 1),
        "_conv_head.weight": (1280, 320, 1, 1),
        "_bn1.weight": (1280,),
    },
    "torchvision": {
        "features.0.0.weight": (32, 3, 3, 3),
        "features.1.0.block.0.0.weight": (32, 1, 3, 3),
        "features.1.0.block.1.fc1.weight": (8, 32, 1, 1),
        "features.1.0.block.2.0.weight": (16, 32, 1, 1),
        "features.2.0.block.0.0.weight": (96, 16, 1, 1),
        "features.2.0.block.2.fc1.weight": (4, 96, 1, 1),
        "features.7.0.block.3.0.weight": (320, 1152, 1, 1),
        "features.8.0.weight": (1280, 320, 1, 1),
    },
    "timm": {
        "conv_stem.weight": (32, 3, 3, 3),
        "blocks.0.0.conv_dw.weight": (32, 1, 3, 3),
        "blocks.0.0.conv_pw.weight": (16, 32, 1, 1),
        "blocks.1.0.conv_pw.weight": (96, 16, 1, 1),
        "blocks.1.0.se.conv_reduce.weight": (4, 96, 1, 1),
        "blocks.5.3.conv_pwl.weight": (192, 1152, 1, 1),
        "blocks.6.0.conv_pwl.weight": (320, 1152, 1, 1),
        "conv_head.weight": (1280, 320, 1, 1),
        "bn2.running_mean": (1280,),
    },
}
HEADS = {"lukemelas": "_fc", "torchvision": "classifier.1", "timm": "classifier"}


@pytest.mark.parametrize("layout", sorted(ANCHORS))
def test_layouts_use_the_public_key_names(layout):
    state = export_state_dict(_model(), layout)
    for key, shape in ANCHORS[layout].items():
        assert tuple(state[key].shape) == shape, key
    assert detect_layout(state) == layout


@pytest.mark.parametrize("layout", sorted(ANCHORS))
@pytest.mark.parametrize("suffix", [".pth", ".safetensors"])
def test_weights_load_from_a_file_of_each_layout(layout, suffix, tmp_path):
    source = _model(seed=1)
    state = export_state_dict(source, layout)
    head = HEADS[layout]
    state[f"{head}.weight"] = torch.randn(1000, 1280)  # the ImageNet classifier: unused
    state[f"{head}.bias"] = torch.randn(1000)
    path = tmp_path / f"b0{suffix}"
    if suffix == ".pth":
        torch.save({f"module.{k}": v for k, v in state.items()}, path)  # DataParallel prefix
    else:
        from safetensors.torch import save_file

        save_file(state, str(path))
    target = _model(seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a complete backbone loads without warnings
        report = load_weights(target, path)
    assert report.layout == layout and not report.missing and not report.shape_mismatch
    assert report.unused == sorted([f"{head}.bias", f"{head}.weight"])
    x = torch.rand(2, 3, 32, 32)
    with torch.no_grad():
        assert torch.allclose(target(x), source(x), atol=1e-5)


def test_rgb_weights_are_adapted_to_other_channel_counts():
    source = _model(3, seed=1)
    state = export_state_dict(source, "torchvision")
    target = _model(1, seed=2)
    report = load_weights(target, state)
    assert report.adapted and not report.missing
    stem = source.stem.conv.weight
    assert torch.allclose(target.stem.conv.weight, stem.mean(1, keepdim=True) * 3)
    # A grey image seen by the adapted stem equals that image repeated as RGB.
    grey = torch.rand(1, 1, 32, 32)
    with torch.no_grad():
        assert torch.allclose(target.stem.conv(grey), source.stem.conv(grey.repeat(1, 3, 1, 1)),
                              atol=1e-5)


def test_partial_and_foreign_weights_are_reported():
    state = export_state_dict(_model(seed=1), "lukemelas")
    del state["_blocks.3._depthwise_conv.weight"]
    state["_blocks.4._se_reduce.bias"] = torch.zeros(7)
    with pytest.warns(UserWarning, match="stay at random initialisation"):
        report = load_weights(_model(), state)
    assert report.missing == ["blocks.3.dw.conv.weight"]
    assert report.shape_mismatch and "blocks.4.se.reduce.bias" in report.shape_mismatch[0]
    with pytest.raises(ValueError, match="not an EfficientNet-B0 state dict"):
        load_weights(_model(), {"fc.weight": torch.zeros(3, 3)})


def test_unreadable_weight_files_are_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        load_weights(_model(), tmp_path / "nope.pth")
    bad = tmp_path / "bad.pth"
    bad.write_bytes(b"garbage")
    with pytest.raises(ValueError, match="cannot read weights file"):
        load_weights(_model(), bad)


def test_cnn_lstm_uses_the_weights_file_and_warns_without_one(tmp_path):
    from tactbench.data.windows import training_windows
    from tactbench.plugins import load_registry

    rng = np.random.default_rng(0)
    seqs = [rng.random((4, 1, 16, 16), dtype=np.float32) for _ in range(6)]
    train = training_windows(seqs, [0, 1, 0, 1, 0, 1], 2)
    path = tmp_path / "b0.pth"
    torch.save(export_state_dict(_model(seed=1), "timm"), path)
    spec = "cnn-lstm:epochs=1,windows_per_epoch=8,batch_size=4,input_size=16,hidden=4,fc=4"
    clf = load_registry().build("classifier", spec, weights=str(path))
    report = clf.fit(train, None, seed=0)
    assert report["weights"]["layout"] == "timm" and report["weights"]["loaded"] > 300
    assert report["weights"]["adapted"]  # 1-channel frames
    with pytest.warns(UserWarning, match="random initialisation"):
        load_registry().build("classifier", spec).fit(train, None, seed=0)


@pytest.mark.parametrize("size", [33, 65])
def test_same_features_as_the_reference_efficientnet_pytorch(size):
    """lukemelas' efficientnet_pytorch (installed with the dev extras): its real state
    dict loads completely, and the features agree. At odd sizes before every stride-2
    convolution (33, 65, 225 px) its TensorFlow 'same' padding is symmetric, like ours."""
    reference = pytest.importorskip("efficientnet_pytorch")
    torch.manual_seed(0)
    ref = reference.EfficientNet.from_name("efficientnet-b0", image_size=size).eval()
    with torch.no_grad():  # non-trivial BatchNorm statistics
        for mod in ref.modules():
            if isinstance(mod, torch.nn.BatchNorm2d):
                mod.running_mean.uniform_(-0.1, 0.1)
                mod.running_var.uniform_(0.5, 1.5)
    ours = _model(seed=1)
    report = load_weights(ours, ref.state_dict())
    assert report.layout == "lukemelas" and not report.missing
    assert report.unused == ["_fc.bias", "_fc.weight"]
    x = torch.rand(2, 3, size, size)
    with torch.no_grad():
        expected = ref.extract_features(x).mean((2, 3))
        assert torch.allclose(ours(x), expected, atol=1e-5)
