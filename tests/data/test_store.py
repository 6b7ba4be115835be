"""The dataset store: save/load round trip, atomic writes, and load errors that name the file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample


@pytest.mark.parametrize("layout", [True, False])
def test_save_and_load_round_trip(tmp_path, layout, make_dataset):
    ds = make_dataset(layout=layout)
    ds.save(tmp_path / "d")
    back = Dataset.load(tmp_path / "d")
    assert back.content_hash() == ds.content_hash()
    assert back.name == "tiny" and back.classes == ds.classes
    assert back.users == ds.users and back.sources == ds.sources
    for a, b in zip(ds, back):
        assert np.array_equal(a.recording.values, b.recording.values)
        assert np.array_equal(a.recording.timestamps, b.recording.timestamps)
    assert (back.layout is None) == (not layout)
    manifest = json.loads((tmp_path / "d" / "manifest.json").read_text())
    assert manifest["schema_version"] == 1 and manifest["values_dtype"] == "uint16"


def test_fractional_and_missing_values_are_stored_as_float(tmp_path):
    rec = Recording(np.array([[0.5, np.nan], [1.25, 2.0]]), [0, 0.1], [1, 2])
    ds = Dataset("f", [Sample(rec, 0)], ("a",))
    back = Dataset.load(ds.save(tmp_path / "f"))
    assert np.array_equal(back[0].recording.values, rec.values, equal_nan=True)


def _saved(tmp_path, make_dataset):
    folder = make_dataset().save(tmp_path / "d")
    return folder, json.loads((folder / "manifest.json").read_text())


def _rewrite(folder, **changes):
    arrays = dict(np.load(folder / "arrays.npz"))
    arrays.update(changes)
    for key, value in list(arrays.items()):
        if value is None:
            del arrays[key]
    np.savez(folder / "arrays.npz", **arrays)


def test_load_errors_name_the_file_and_problem(tmp_path, make_dataset):
    with pytest.raises(FileNotFoundError):
        Dataset.load(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="not a tactbench dataset folder"):
        Dataset.load(tmp_path / "empty")
    folder, manifest = _saved(tmp_path, make_dataset)
    for change, message in [
        ({"schema_version": 99}, "schema_version 99 is not supported"),
        ({"format": "other"}, "'format' is 'other'"),
        ({"users": ["u"]}, "'users' must list 6 strings"),
        ({"n_samples": "6"}, "field 'n_samples' must be a int"),
    ]:
        (folder / "manifest.json").write_text(json.dumps({**manifest, **change}))
        with pytest.raises(ValueError, match=message) as info:
            Dataset.load(folder)
        assert "manifest.json" in str(info.value)
    (folder / "manifest.json").write_text("{not json")
    with pytest.raises(ValueError, match="manifest.json: not valid JSON"):
        Dataset.load(folder)


@pytest.mark.parametrize("change, message", [
    (dict(values=None), "array 'values' is missing"),
    (dict(labels=np.array([0, 1, 2, 0, 1, 7])), "sample 5 has label 7, but there are 3"),
    (dict(offsets=np.array([0, 3, 2, 9, 12, 15, 100])), "'offsets' must rise strictly"),
    (dict(taxel_ids=np.zeros(16, np.int64)), "duplicate taxel ids"),
    (dict(values=np.zeros((5, 16), np.float32)), "'values' has shape"),
    (dict(timestamps=np.full(1, 0.0)), "'timestamps' has 1 entries"),
    (dict(users=np.array(["x"], dtype=object)), "allow_pickle"),
])
def test_bad_arrays(tmp_path, change, message, make_dataset):
    folder, manifest = _saved(tmp_path, make_dataset)
    if "offsets" in change:
        change["offsets"][-1] = manifest["n_frames"]
    _rewrite(folder, **change)
    with pytest.raises(ValueError, match=message) as info:
        Dataset.load(folder)
    assert "arrays.npz" in str(info.value) or "manifest.json" in str(info.value)


def test_timestamps_going_backwards_in_a_file(tmp_path, make_dataset):
    folder, _ = _saved(tmp_path, make_dataset)
    ts = np.load(folder / "arrays.npz")["timestamps"].copy()
    ts[1] = -5
    _rewrite(folder, timestamps=ts)
    with pytest.raises(ValueError, match="sample 0: timestamps go backwards"):
        Dataset.load(folder)


def test_edited_values_fail_the_hash_check(tmp_path, make_dataset):
    folder, _ = _saved(tmp_path, make_dataset)
    values = np.load(folder / "arrays.npz")["values"].copy()
    values[0, 0] += 1
    _rewrite(folder, values=values)
    with pytest.raises(ValueError, match="does not match the manifest"):
        Dataset.load(folder)
    assert len(Dataset.load(folder, verify=False)) == 6


def test_truncated_arrays_file(tmp_path, make_dataset):
    folder, _ = _saved(tmp_path, make_dataset)
    data = (folder / "arrays.npz").read_bytes()
    (folder / "arrays.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="cannot read the arrays"):
        Dataset.load(folder)


def test_layout_with_3d_positions_and_normals_survives_the_store(tmp_path):
    from tactbench.datasets.forearm import cyskin_forearm

    layout = cyskin_forearm(40, circumference_mm=80, length_mm=60)
    rec = Recording(np.zeros((2, 40)), [0.0, 0.1], layout.ids)
    back = Dataset.load(Dataset("f", [Sample(rec, 0)], ("a",), layout).save(tmp_path / "f"))
    assert back.layout.name == layout.name and back.layout.bounds == layout.bounds
    for key in ("ids", "positions", "positions_3d", "normals"):
        assert np.array_equal(getattr(back.layout, key), getattr(layout, key))
    keys = set(np.load(tmp_path / "f" / "arrays.npz").files)
    assert {"layout_ids", "layout_positions", "layout_bounds", "layout_positions_3d",
            "layout_normals"} <= keys


def test_bad_layout_arrays_name_the_file(tmp_path, make_dataset):
    folder, _ = _saved(tmp_path, make_dataset)
    _rewrite(folder, layout_positions=np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"arrays.npz: layout: .*positions must be") as info:
        Dataset.load(folder)
    assert "\n" not in str(info.value)


def test_saving_again_replaces_the_files_and_leaves_no_temporary_files(tmp_path, make_dataset):
    folder = make_dataset().save(tmp_path / "d")
    other = make_dataset(seed=1)
    other.save(folder)
    assert sorted(p.name for p in folder.iterdir()) == ["arrays.npz", "manifest.json"]
    assert Dataset.load(folder).content_hash() == other.content_hash()
