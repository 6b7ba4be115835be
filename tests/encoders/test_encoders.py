"""Built-in encoders: registered, conformant, options checked, shared flow conventions."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tactbench.cli import cli
from tactbench.encoders.base import check_sequence
from tactbench.encoders.flow import FlowEncoder, flow_to_channels
from tactbench.encoders.evaluation.conformance import (
    conformance_cases,
    contact_sequence,
    run_check,
)
from tactbench.plugins import load_registry

BUILTINS = ("raw", "frame-diff", "farneback", "lucas-kanade", "kornia-flow", "dis", "tvl1")
FLOW = ("farneback", "lucas-kanade", "kornia-flow", "dis", "tvl1")


@pytest.fixture(scope="module")
def registry():
    return load_registry()


def test_every_builtin_is_registered_with_its_requirements(registry):
    names = set(registry.names("encoder"))
    assert set(BUILTINS) <= names
    for name in FLOW:
        comp = registry.get("encoder", name)
        assert comp.plugin == "tactbench.encoders" and "cv2" in comp.requires


@pytest.mark.parametrize("encoder, check", conformance_cases(BUILTINS))
def test_builtin_conformance(encoder, check):
    run_check(encoder, check)


@pytest.mark.parametrize("spec, message", [
    ("farneback:pyr_scale=1.5", "pyr_scale"), ("farneback:poly_n=6", "poly_n"),
    ("farneback:margin=-1", "margin"), ("lucas-kanade:winsize=2", "winsize"),
    ("lucas-kanade:step=0", "step"), ("kornia-flow:device=tpu", "device"),
    ("kornia-flow:window=0", "window"), ("dis:preset=slow", "preset"),
    ("tvl1:warps=0", "warps"), ("farneback:max_flow=0", "max_flow"),
    ("dis:min_magnitude=-1", "min_magnitude"), ("tvl1:downscale=1.5", "downscale"),
])
def test_bad_options_are_refused_by_name(registry, spec, message):
    with pytest.raises(ValueError, match=message):
        registry.build("encoder", spec)


@pytest.mark.parametrize("name", FLOW)
def test_flow_metadata_records_scale_and_options(registry, name):
    enc = registry.build("encoder", f"{name}:max_flow=4,downscale=2")
    meta = enc.metadata()
    json.dumps(meta)
    assert meta["magnitude_scale_px_per_frame"] == 4.0
    assert meta["options"]["downscale"] == 2 and meta["version"] == enc.version
    assert meta["channels"] == ["pressure", "magnitude", "direction"]


# ----------------------------------------------------------------------------- conventions


def test_direction_maps_image_angles_to_turns():
    # right, down, left, up and the diagonal down-left, in image coordinates (y down)
    vectors = [(1, 0, 0.0), (0, 1, 0.25), (-1, 0, 0.5), (0, -1, 0.75), (-1, 1, 0.375)]
    flow = np.array([[[[u, v] for u, v, _ in vectors]]], dtype=np.float32)  # (1, 1, 5, 2)
    seq = np.zeros((1, 1, 5), np.float32)
    out = flow_to_channels(seq, flow, max_flow=2.0, min_magnitude=0.05)
    np.testing.assert_allclose(out[0, 2, 0], [t for *_, t in vectors], atol=1e-4)
    np.testing.assert_allclose(out[0, 1, 0, :4], 0.5, atol=1e-6)


def test_magnitude_is_clipped_and_slow_motion_has_no_direction():
    flow = np.array([[[[100.0, 0.0], [0.0, -0.01], [-1e-7, -1e-9], [0.0, 0.0]]]], np.float32)
    out = flow_to_channels(np.zeros((1, 1, 4), np.float32), flow, max_flow=8.0,
                           min_magnitude=0.05)
    assert out[0, 1, 0, 0] == 1.0                       # clipped, not wrapped
    assert out[0, 2, 0, 1] == 0.0                       # below the threshold
    assert 0.0 <= out[0, 2, 0, 2] < 1.0 and out[0, 2, 0, 3] == 0.0
    assert np.isfinite(out).all()


def test_direction_just_below_a_full_turn_is_never_one():
    # an angle a hair below 2π rounds to 1.0 in float32: it must wrap to 0
    flow = np.array([[[[1.0, -1e-9]]]], np.float32)
    out = flow_to_channels(np.zeros((1, 1, 1), np.float32), flow, max_flow=8.0,
                           min_magnitude=0.0)
    assert 0.0 <= out[0, 2, 0, 0] < 1.0


@pytest.mark.parametrize("name", ["farneback", "dis", "kornia-flow"])
def test_coarser_grid_keeps_input_pixel_units(registry, name):
    seq = contact_sequence((64, 64), 3, shift=3.0, angle=0.0, sigma=5.0)
    flow = registry.build("encoder", f"{name}:downscale=2").flow(seq[1:2], seq[2:3])
    mask = np.minimum(seq[1], seq[2]) > 0.3
    assert flow.shape == (1, 64, 64, 2)
    assert np.median(flow[0, ..., 0][mask]) == pytest.approx(3.0, rel=0.25)
    assert abs(np.median(flow[0, ..., 1][mask])) < 0.5


def test_dis_pads_images_below_its_minimum(registry):
    out = registry.build("encoder", "dis").encode(contact_sequence((9, 7), 3, shift=1.0))
    assert out.shape == (3, 3, 9, 7) and np.isfinite(out).all()


def test_farneback_border_margin_removes_motion_between_identical_frames(registry):
    # A contact touching the border: OpenCV alone reports motion between two
    # identical frames; the encoder's edge margin removes it.
    frame = contact_sequence((40, 40), 1, sigma=40 / 6, seed=1)
    pair = np.repeat(frame, 2, axis=0)
    raw_cv = registry.build("encoder", "farneback:margin=0").flow(pair[:1], pair[1:])
    fixed = registry.build("encoder", "farneback").flow(pair[:1], pair[1:])
    assert np.abs(raw_cv).max() > 0.05
    assert np.abs(fixed).max() < 1e-3


def test_flow_encoder_rejects_non_finite_flow():
    class Broken(FlowEncoder):
        name = "broken"

        def _flow(self, prev, curr):
            return np.full((*prev.shape, 2), np.nan, np.float32)

    with pytest.raises(FloatingPointError, match="broken"):
        Broken().encode(np.zeros((2, 8, 8), np.float32))


# ----------------------------------------------------------------------------- input policy


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hnp.arrays(dtype=st.sampled_from([np.uint8, np.uint16, np.float16, np.float32,
                                         np.float64]),
                  shape=hnp.array_shapes(min_dims=3, max_dims=3, min_side=1, max_side=5)))
def test_input_policy_accepts_or_refuses_clearly(arr):
    finite = np.isfinite(arr.astype(np.float64)).all() if arr.dtype.kind == "f" else True
    if arr.dtype.kind == "u":
        out = check_sequence(arr)
        np.testing.assert_allclose(out, arr / np.iinfo(arr.dtype).max, rtol=1e-6)
    elif not finite:
        with pytest.raises(ValueError, match="non-finite"):
            check_sequence(arr)
        return
    elif arr.size and (arr.min() < -1e-6 or arr.max() > 1 + 1e-6):
        with pytest.raises(ValueError, match=r"\[0, 1\]"):
            check_sequence(arr)
        return
    else:
        out = check_sequence(arr)
        np.testing.assert_allclose(out, np.clip(arr.astype(np.float32), 0, 1))
    assert out.dtype == np.float32 and out.shape == arr.shape
    assert out.min() >= 0.0 and out.max() <= 1.0


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(shape=st.tuples(st.integers(1, 4), st.integers(1, 12), st.integers(1, 12)),
       seed=st.integers(0, 2 ** 16), bad=st.sampled_from([np.nan, np.inf, -np.inf, 1.5, -0.5]))
def test_every_encoder_refuses_a_single_bad_value(registry, shape, seed, bad):
    rng = np.random.default_rng(seed)
    seq = rng.uniform(0, 1, size=shape).astype(np.float32)
    seq[tuple(rng.integers(0, s) for s in shape)] = bad
    for name in ("raw", "frame-diff", "farneback", "dis", "lucas-kanade"):
        with pytest.raises(ValueError):
            registry.build("encoder", name).encode(seq)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(shape=st.tuples(st.integers(1, 3), st.integers(1, 20), st.integers(1, 20)),
       seed=st.integers(0, 2 ** 16))
def test_flow_outputs_are_finite_and_in_range_for_any_valid_input(registry, shape, seed):
    seq = np.random.default_rng(seed).uniform(0, 1, size=shape).astype(np.float32)
    for name in ("farneback", "dis", "lucas-kanade", "kornia-flow"):
        out = registry.build("encoder", name).encode(seq)
        assert out.shape == (shape[0], 3, *shape[1:])
        assert np.isfinite(out).all() and out.min() >= 0.0 and out.max() <= 1.0
        np.testing.assert_array_equal(out[:, 0], seq)


# ----------------------------------------------------------------------------- CLI


def test_encode_command_writes_array_and_metadata(tmp_path):
    seq = contact_sequence((24, 24), 4, shift=1.0)
    np.save(tmp_path / "seq.npy", (seq * 255).round().astype(np.uint8))
    result = CliRunner().invoke(cli, ["encode", "--encoder", "farneback:winsize=9,levels=2",
                                      "--input", str(tmp_path / "seq.npy"),
                                      "--out", str(tmp_path / "o" / "enc.npy"), "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    out = np.load(tmp_path / "o" / "enc.npy")
    assert out.shape == (4, 3, 24, 24) and out.dtype == np.float32
    meta = json.loads((tmp_path / "o" / "enc.json").read_text())
    assert meta["options"]["winsize"] == 9 and meta["options"]["levels"] == 2
    assert meta["input_dtype"] == "uint8" and doc["output_shape"] == [4, 3, 24, 24]
    assert meta["magnitude_scale_px_per_frame"] == 8.0


@pytest.mark.parametrize("array, message", [
    (np.zeros((3, 4)), "shape"), (np.full((2, 3, 3), np.nan), "non-finite"),
    (np.full((2, 3, 3), 7.0), r"\[0, 1\]"),
])
def test_encode_command_names_the_file_and_the_problem(tmp_path, array, message):
    np.save(tmp_path / "bad.npy", array)
    result = CliRunner().invoke(cli, ["encode", "-e", "raw", "-i", str(tmp_path / "bad.npy"),
                                      "-o", str(tmp_path / "out.npy")])
    assert result.exit_code != 0
    assert "bad.npy" in result.output
    assert any(w in result.output for w in message.replace("\\", "").split("|"))


def test_lucas_kanade_grid_interpolation_keeps_the_motion(registry):
    seq = contact_sequence((48, 48), 2, shift=2.0, angle=0.5 * np.pi, sigma=5.0)
    mask = np.minimum(seq[0], seq[1]) > 0.3
    for step in (1, 3):
        flow = registry.build("encoder", f"lucas-kanade:step={step}").flow(seq[:1], seq[1:])
        assert np.median(flow[0, ..., 1][mask]) == pytest.approx(2.0, rel=0.15)
        assert abs(np.median(flow[0, ..., 0][mask])) < 0.2


def test_blank_skin_has_no_flow_for_lucas_kanade(registry):
    # textureless windows (OpenCV status 0) get zero flow, not OpenCV's guess
    seq = np.zeros((3, 32, 32), np.float32)
    seq[1:, 10:14, 10:14] = 0.8
    flow = registry.build("encoder", "lucas-kanade").flow(seq[1:2], seq[2:3])
    assert not flow.any()
