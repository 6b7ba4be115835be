"""Fuzz: mutated model files (bytes flipped or truncated, the safetensors header or the
tactbench header JSON edited) only ever raise tactbench's own error, stay under a memory
cap and leave the file as it was; a file that still loads predicts exactly as the
original did (nothing corrupt is used silently)."""

from __future__ import annotations

import json
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.classifiers.io import load_model
from tactbench.errors import TactbenchError
from tactbench.fuzzing import json_mutation as _json_mutation
from tactbench.fuzzing import json_values
from tactbench.integrity import hash_file
from tactbench.plugins import load_registry

REGISTRY = load_registry()
FUZZ = settings(max_examples=60, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
CAP_MIB = 200

JSON_VALUES = json_values(["F32", "F16", "I64", "BF16", "U8", "small-cnn-lstm", "logreg"])


def json_mutation(doc):
    return _json_mutation(doc, values=JSON_VALUES, at_most=1)


def _split(data: bytes) -> tuple[dict, bytes]:
    """A safetensors file: its header JSON and its data buffer."""
    (n,) = struct.unpack("<Q", data[:8])
    return json.loads(data[8:8 + n]), data[8 + n:]


def _join(header: dict, buffer: bytes) -> bytes:
    text = json.dumps(header).encode()
    text += b" " * (-len(text) % 8)
    return struct.pack("<Q", len(text)) + text + buffer


@pytest.fixture(scope="module")
def models(tmp_path_factory, one_torch_thread):
    """Real model files written by tactbench: logreg on taxel vectors and a tiny
    small-cnn-lstm on images, with the windows to compare predictions on."""
    from tactbench.data.windows import training_windows

    rng = np.random.default_rng(0)
    folder = tmp_path_factory.mktemp("fuzz-models")
    out = {}
    for name, spec, frame in [
            ("logreg", "logreg", (6,)),
            ("cnn", "small-cnn-lstm:epochs=1,windows_per_epoch=0,input_size=8,width=2,"
                    "layers=1,hidden=4,fc=4", (1, 8, 8))]:
        seqs = [rng.random((4, *frame), dtype=np.float32) + label for label in (0, 1) * 3]
        clf = REGISTRY.build("classifier", spec, classes=2)
        clf.fit(training_windows(seqs, np.array([0, 1] * 3), 2), None, seed=0, device="cpu",
                progress=None)
        windows = np.stack([s[:2] for s in seqs])
        path = clf.save(folder / f"{name}.safetensors",
                        {"classes": ["a", "b"], "L": 2, "cell": name})
        out[name] = (path, clf.predict_proba(windows), windows)
    return out


def _check_read(path: Path, expected: np.ndarray, windows: np.ndarray, memory_cap) -> None:
    before = hash_file(path)
    with memory_cap(CAP_MIB):
        try:
            clf, _ = load_model(path, registry=REGISTRY)
        except TactbenchError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc), str(exc)
        else:
            assert np.array_equal(clf.predict_proba(windows), expected)
    assert hash_file(path) == before


@FUZZ
@given(which=st.sampled_from(["logreg", "cnn"]),
       flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                      max_size=8),
       cut=st.one_of(st.none(), st.floats(0, 1, exclude_max=True)))
def test_model_bytes_flipped_or_truncated(models, memory_cap, which, flips, cut):
    path, expected, windows = models[which]
    data = bytearray(path.read_bytes())
    for where, mask in flips:
        data[int(where * len(data))] ^= mask
    if cut is not None:
        data = data[:int(cut * len(data))]
    with tempfile.TemporaryDirectory() as root:
        bad = Path(root) / "m.safetensors"
        bad.write_bytes(bytes(data))
        _check_read(bad, expected, windows, memory_cap)


@FUZZ
@given(which=st.sampled_from(["logreg", "cnn"]), data=st.data())
def test_tactbench_header_mutated(models, memory_cap, which, data):
    path, expected, windows = models[which]
    header, buffer = _split(path.read_bytes())
    ours = json.loads(header["__metadata__"]["tactbench"])
    header["__metadata__"]["tactbench"] = json.dumps(data.draw(json_mutation(ours)))
    with tempfile.TemporaryDirectory() as root:
        bad = Path(root) / "m.safetensors"
        bad.write_bytes(_join(header, buffer))
        _check_read(bad, expected, windows, memory_cap)


@FUZZ
@given(which=st.sampled_from(["logreg", "cnn"]), data=st.data())
def test_safetensors_header_mutated(models, memory_cap, which, data):
    """Tensor names, dtypes, shapes and offsets edited (the data left as it is)."""
    path, expected, windows = models[which]
    header, buffer = _split(path.read_bytes())
    meta = header.pop("__metadata__")
    header = data.draw(json_mutation(header))
    if isinstance(header, dict):
        header["__metadata__"] = meta
    with tempfile.TemporaryDirectory() as root:
        bad = Path(root) / "m.safetensors"
        bad.write_bytes(_join(header, buffer))
        _check_read(bad, expected, windows, memory_cap)


def test_the_fuzzed_files_themselves_load(models):
    for path, expected, windows in models.values():
        clf, meta = load_model(path, registry=REGISTRY)
        assert np.array_equal(clf.predict_proba(windows), expected)
        assert meta["classes"] == ["a", "b"]
