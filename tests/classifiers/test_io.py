"""Model files: written atomically, read back exactly, with the metadata live use needs."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.classifiers.io import live_metadata, load_model, read_header, save_model
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
    meta = live_metadata(dataset, encoder="raw", length=2, pixel_mm=1.5, method="nearest")
    assert "layout" not in meta
    assert meta["taxel_ids"] == [4, 9] and meta["classes"] == ["touch"]
    assert meta["imaging"] == {"pixel_mm": 1.5, "method": "nearest"}
    assert meta["normalisation"]["scale"] == 100.0
