"""Model files: written atomically, read back exactly, with the metadata live use needs."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.classifiers.io import (
    ModelFileError,
    live_metadata,
    load_model,
    read_header,
    save_model,
)
from tactbench.plugins import load_registry

REGISTRY = load_registry()


@pytest.fixture(scope="module")
def fitted():
    """logreg on 2-class taxel-vector windows (B, L=2, N=5)."""
    from tactbench.data.windows import training_windows

    rng = np.random.default_rng(0)
    seqs = [rng.random((4, 5), dtype=np.float32) + label for label in (0, 1) * 4]
    clf = REGISTRY.build("classifier", "logreg", classes=2)
    clf.fit(training_windows(seqs, np.array([0, 1] * 4), 2), None, seed=0, device="cpu",
            progress=None)
    return clf, np.stack([s[:2] for s in seqs])


def test_save_replaces_the_file_atomically_and_leaves_nothing_beside(fitted, tmp_path):
    clf, windows = fitted
    path = tmp_path / "models" / "m.safetensors"
    save_model(clf, path, {"run": 1})
    save_model(clf, path, {"run": 2})  # over an existing file
    assert [p.name for p in path.parent.iterdir()] == ["m.safetensors"]
    back, meta = load_model(path, registry=REGISTRY)
    assert meta == {"run": 2} and read_header(path)["classifier"] == "logreg"
    np.testing.assert_allclose(back.predict_proba(windows), clf.predict_proba(windows),
                               atol=1e-6)


def test_metadata_that_is_not_json_is_refused_before_anything_is_written(fitted, tmp_path):
    clf, _ = fitted
    with pytest.raises(ValueError, match="JSON-serialisable"):
        save_model(clf, tmp_path / "m.safetensors", {"bad": object()})
    assert list(tmp_path.iterdir()) == []


def test_live_metadata_without_a_layout():
    from tactbench.data.dataset import Dataset
    from tactbench.data.recording import Recording, Sample

    rec = Recording(np.ones((3, 2), np.float32), 0.1 * np.arange(3), [4, 9])
    dataset = Dataset("flat", [Sample(rec, 0)], ("touch",), normalisation="fixed:scale=100")
    meta = live_metadata(dataset, encoder="raw", L=2, pixel_mm=1.5, method="nearest")
    assert "layout" not in meta and meta["L"] == 2
    assert meta["taxel_ids"] == [4, 9] and meta["classes"] == ["touch"]
    assert meta["imaging"] == {"pixel_mm": 1.5, "method": "nearest"}
    assert meta["normalisation"]["scale"] == 100.0


# ----------------------------------------------------------------- verification on read


def _rewrite(src, dst, *, header=None, tensors=None, resign=True):
    """Copy a model file through ``header(h)`` / ``tensors(t)`` edits; ``resign`` records
    the checksum of the edited content (a consistent file), else the old one stays."""
    import json

    from safetensors import safe_open
    from safetensors.torch import save_file

    from tactbench.classifiers.io import payload_digest

    with safe_open(str(src), framework="pt") as f:
        h = json.loads(f.metadata()["tactbench"])
        t = {k: f.get_tensor(k).clone() for k in f.keys()}
    if header is not None:
        header(h)
    if tensors is not None:
        tensors(t)
    if resign and isinstance(h.get("checksum"), dict):
        h["checksum"]["digest"] = payload_digest(h, t)
    save_file(t, str(dst), metadata={"tactbench": json.dumps(h)})
    return dst


def _one_line_model_error(path, match):
    from tactbench.classifiers.io import ModelFileError
    from tactbench.errors import CorruptArtefactError

    with pytest.raises(ModelFileError, match=match) as info:
        load_model(path, registry=REGISTRY)
    assert isinstance(info.value, CorruptArtefactError)
    assert info.value.artefact == str(path) and "\n" not in str(info.value)
    return info.value


def test_the_header_records_what_the_model_is_and_a_checksum(fitted, tmp_path):
    from tactbench import __version__
    from tactbench.classifiers.io import verify_model

    clf, _ = fitted
    path = save_model(clf, tmp_path / "m.safetensors", {"classes": ["a", "b"], "cell": "k1"})
    h = read_header(path)
    assert h["version"] == 3 and h["classifier"] == "logreg"
    assert h["classes"] == ["a", "b"] and h["cell"] == "k1" and h["tactbench"] == __version__
    assert h["config"]["n_classes"] == 2 and h["config"]["frame_shape"] == [5]
    assert h["config"]["L"] == 2
    assert h["checksum"]["algorithm"] == "sha256" and len(h["checksum"]["digest"]) == 64
    assert verify_model(path, registry=REGISTRY) is None


def test_a_flipped_byte_in_the_tensors_is_refused(fitted, tmp_path):
    clf, _ = fitted
    path = save_model(clf, tmp_path / "m.safetensors")
    data = bytearray(path.read_bytes())
    data[-3] ^= 0x10  # inside the last tensor's bytes: still a valid safetensors file
    path.write_bytes(bytes(data))
    _one_line_model_error(path, "checksum .* does not match the recorded")


def test_an_edited_header_field_is_refused(fitted, tmp_path):
    clf, _ = fitted
    good = save_model(clf, tmp_path / "good.safetensors", {"classes": ["a", "b"]})

    def relabel(h):
        h["metadata"]["classes"] = ["b", "a"]
        h["classes"] = ["b", "a"]

    _one_line_model_error(_rewrite(good, tmp_path / "m.safetensors", header=relabel,
                                   resign=False), "checksum")


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_nan_or_infinite_tensors_are_refused_even_with_a_matching_checksum(fitted, tmp_path,
                                                                           value):
    clf, _ = fitted
    good = save_model(clf, tmp_path / "good.safetensors")

    def poison(t):
        t["weight"][0, 0] = value

    err = _one_line_model_error(_rewrite(good, tmp_path / "m.safetensors", tensors=poison),
                                "tensor 'weight' holds 1 NaN or infinite value")
    assert "checksum" not in str(err)


def test_class_names_must_be_as_many_as_the_network_outputs(fitted, tmp_path):
    clf, _ = fitted
    with pytest.raises(ValueError, match="names 3 classes, the classifier has 2 outputs"):
        save_model(clf, tmp_path / "m.safetensors", {"classes": ["a", "b", "c"]})
    assert list(tmp_path.iterdir()) == []
    good = save_model(clf, tmp_path / "good.safetensors", {"classes": ["a", "b"]})

    def three(h):
        h["metadata"]["classes"] = h["classes"] = ["a", "b", "c"]

    _one_line_model_error(_rewrite(good, tmp_path / "c.safetensors", header=three),
                          "lists 3 classes, but the network has 2 outputs")


def _as_format_1(h):
    """What save_model wrote before checksums: version 1, no classes/cell/checksum."""
    h["version"] = 1
    for key in ("checksum", "classes", "cell"):
        h.pop(key)


def test_a_format_1_file_is_refused_unless_the_caller_trusts_it(fitted, tmp_path):
    from tactbench.classifiers.io import UnverifiedModelWarning

    clf, windows = fitted
    good = save_model(clf, tmp_path / "good.safetensors", {"classes": ["a", "b"]})
    old = _rewrite(good, tmp_path / "old.safetensors", header=_as_format_1)
    _one_line_model_error(old, r"format 1 has no checksum and cannot be verified; retrain "
                               r"it, or, if you trust it, read it with load_model\(path, "
                               r"allow_unverified=True\) and save it again")
    with pytest.warns(UnverifiedModelWarning, match="has no checksum"):
        back, meta = load_model(old, registry=REGISTRY, allow_unverified=True)
    assert meta == {"classes": ["a", "b"]}
    np.testing.assert_allclose(back.predict_proba(windows), clf.predict_proba(windows),
                               atol=1e-6)
    resaved = save_model(back, tmp_path / "resaved.safetensors", meta)
    assert load_model(resaved, registry=REGISTRY)[1] == meta


def test_a_trusted_format_1_file_still_gets_every_other_check(fitted, tmp_path):
    from tactbench.classifiers.io import UnverifiedModelWarning

    clf, _ = fitted
    good = save_model(clf, tmp_path / "good.safetensors", {"classes": ["a", "b"]})

    def three(h):
        _as_format_1(h)
        h["metadata"]["classes"] = ["a", "b", "c"]

    def nan(t):
        t["bias"][1] = float("nan")

    for path, match in [
            (_rewrite(good, tmp_path / "c.safetensors", header=three), "lists 3 classes"),
            (_rewrite(good, tmp_path / "n.safetensors", header=_as_format_1, tensors=nan),
             "tensor 'bias' holds 1 NaN")]:
        with pytest.warns(UnverifiedModelWarning), pytest.raises(ModelFileError, match=match):
            load_model(path, registry=REGISTRY, allow_unverified=True)


def test_options_asking_for_a_huge_network_are_refused_before_it_is_built(tmp_path,
                                                                          one_torch_thread):
    """A corrupt ``hidden`` in a file without a checksum: the network is first restored on
    torch's meta device (no memory), so the 160 GB LSTM is never allocated."""
    from tactbench.classifiers.io import UnverifiedModelWarning
    from tactbench.data.windows import training_windows

    rng = np.random.default_rng(0)
    seqs = [rng.random((3, 1, 8, 8), dtype=np.float32) + label for label in (0, 1) * 2]
    clf = REGISTRY.build("classifier", "small-cnn-lstm:epochs=1,windows_per_epoch=0,"
                                       "input_size=8,width=2,layers=1,hidden=4,fc=4", classes=2)
    clf.fit(training_windows(seqs, np.array([0, 1] * 2), 2), None, seed=0, device="cpu",
            progress=None)
    good = save_model(clf, tmp_path / "good.safetensors")

    def huge(h):
        _as_format_1(h)
        h["config"]["options"]["hidden"] = 100_000

    with pytest.warns(UnverifiedModelWarning), pytest.raises(
            ModelFileError, match=r"does not match classifier 'small-cnn-lstm'.*"
                                  r"lstm.weight_hh_l0 \(16, 4\) vs \(400000, 100000\)"):
        load_model(_rewrite(good, tmp_path / "h.safetensors", header=huge),
                   registry=REGISTRY, allow_unverified=True)


def _as_format_2(h):
    """What save_model wrote before format 3: ``length`` for L, option ``normalize``."""
    h["version"] = 2
    h["config"]["length"] = h["config"].pop("L")
    h["metadata"]["length"] = h["metadata"].pop("L")
    if "normalisation" in h["config"]["options"]:
        h["config"]["options"]["normalize"] = h["config"]["options"].pop("normalisation")


def test_a_format_2_file_is_verified_as_written_then_read_as_format_3(tmp_path,
                                                                      one_torch_thread):
    """The one documented migration (docs/classifiers.md): the checksum covers the old
    header; the caller sees ``L`` and ``normalisation``. An edited old header is refused."""
    from tactbench.data.windows import training_windows

    rng = np.random.default_rng(0)
    seqs = [rng.random((3, 1, 8, 8), dtype=np.float32) + label for label in (0, 1) * 2]
    clf = REGISTRY.build("classifier", "small-cnn-lstm:epochs=1,windows_per_epoch=0,"
                                       "input_size=8,width=2,layers=1,hidden=4,fc=4",
                         classes=2)
    clf.fit(training_windows(seqs, np.array([0, 1] * 2), 2), None, seed=0, device="cpu",
            progress=None)
    good = save_model(clf, tmp_path / "good.safetensors", {"L": 2, "classes": ["a", "b"]})
    old = _rewrite(good, tmp_path / "old.safetensors", header=_as_format_2)
    h = read_header(old)
    assert h["version"] == 2 and h["config"]["length"] == 2 and "L" not in h["config"]
    back, meta = load_model(old, registry=REGISTRY)
    assert meta == {"L": 2, "classes": ["a", "b"]}
    assert back.L == 2 and back.normalisation == "data"
    x = np.stack([s[:2] for s in seqs])
    np.testing.assert_allclose(back.predict_proba(x), clf.predict_proba(x), atol=1e-6)
    assert read_header(save_model(back, tmp_path / "new.safetensors", meta))["version"] == 3

    def edited(h):
        _as_format_2(h)
        h["metadata"]["length"] = 3

    _one_line_model_error(_rewrite(good, tmp_path / "e.safetensors", header=edited,
                                   resign=False), "checksum")
    _one_line_model_error(_rewrite(good, tmp_path / "m.safetensors", header=edited),
                          "metadata 'L' 3 differs from the network's window length 2")


@pytest.mark.parametrize("edit, message", [
    (lambda h: h.pop("checksum"), "has no checksum"),
    (lambda h: h["checksum"].update(algorithm="md5"), "checksum algorithm 'md5'"),
    (lambda h: h["config"].update(n_classes="2"), "'config.n_classes' must be a positive"),
    (lambda h: h["config"].update(frame_shape=[]), "'config.frame_shape' must be a list"),
    (lambda h: h["config"].update(L=0), "'config.L' must be a positive"),
    (lambda h: h.update(metadata=[1]), "'metadata' must be an object"),
    (lambda h: h.update(classes="ab"), "'classes' must be a list of names"),
    (lambda h: h.update(version=True), "'version' must be a positive integer"),
    (lambda h: h.update(classifier=7), "'classifier' must be a classifier name"),
    (lambda h: h["metadata"].update(L=9), "metadata 'L' 9 differs"),
    (lambda h: h["metadata"].update(taxel_ids=[1, 2]), "names 2 taxels, but the network "
                                                       "takes vectors of 5 values"),
    (lambda h: h["metadata"].update(taxel_ids=[]), "names 0 taxels"),
])
def test_header_fields_of_the_wrong_type_or_value_are_one_line(fitted, tmp_path, edit, message):
    clf, _ = fitted
    good = save_model(clf, tmp_path / "good.safetensors")
    _one_line_model_error(_rewrite(good, tmp_path / "m.safetensors", header=edit), message)


@pytest.mark.parametrize("keep", [0, 7, 8, 100, -1])
def test_a_truncated_file_is_one_line(fitted, tmp_path, keep):
    clf, _ = fitted
    path = save_model(clf, tmp_path / "m.safetensors")
    data = path.read_bytes()
    path.write_bytes(data[:keep] if keep >= 0 else data[:keep])
    _one_line_model_error(path, "corrupt|truncated")


def test_the_error_survives_pickling_to_another_process():
    import pickle

    from tactbench.errors import CorruptArtefactError

    err = pickle.loads(pickle.dumps(ModelFileError("m.safetensors", "checksum differs")))
    assert isinstance(err, CorruptArtefactError) and str(err) == "m.safetensors: checksum differs"
    assert (err.artefact, err.problem) == ("m.safetensors", "checksum differs")


def test_vectors_of_several_values_per_taxel_read_back(tmp_path):
    """An encoder of taxel vectors may give C values per taxel (frame-diff: 2N): the
    model's metadata names the N taxels, and the file reads back (it was refused as
    damaged, so a rerun with --save-models retrained it every time)."""
    from tactbench.data.windows import training_windows

    rng = np.random.default_rng(0)
    seqs = [rng.random((4, 6), dtype=np.float32) + label for label in (0, 1) * 4]
    clf = REGISTRY.build("classifier", "logreg", classes=2)
    clf.fit(training_windows(seqs, np.array([0, 1] * 4), 2), None, seed=0, device="cpu",
            progress=None)
    path = save_model(clf, tmp_path / "m.safetensors", {"taxel_ids": [3, 7, 11]})
    back, meta = load_model(path, registry=REGISTRY)
    assert meta["taxel_ids"] == [3, 7, 11] and back.frame_shape == (6,)
    bad = save_model(clf, tmp_path / "bad.safetensors", {"taxel_ids": [3, 7, 11, 12]})
    _one_line_model_error(bad, "names 4 taxels, but the network takes vectors of 6 values")
