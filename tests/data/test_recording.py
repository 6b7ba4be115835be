"""Recording, Sample, Dataset: validation, normalisation, images, hash, on-disk format."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from tactbench.data.layout import TaxelLayout
from tactbench.data.recording import Dataset, Frame, Normalisation, Recording, Sample


def grid_layout(n_side=4, pitch=7.5):
    yy, xx = np.mgrid[0:n_side, 0:n_side]
    pos = np.column_stack([xx.ravel(), yy.ravel()]) * pitch
    return TaxelLayout(ids=np.arange(n_side * n_side) + 100, positions=pos, name="grid")


def make_dataset(n_samples=6, n_taxels=16, layout=True, seed=0, normalisation="fixed"):
    rng = np.random.default_rng(seed)
    ids = np.arange(n_taxels) + 100
    samples = []
    for k in range(n_samples):
        t = int(rng.integers(3, 8))
        values = rng.integers(0, 60000, (t, n_taxels)).astype(np.float32)
        rec = Recording(values, np.arange(t) * 0.1, ids)
        samples.append(Sample(rec, k % 3, user=f"u{k % 2}", position="front",
                              repetition=k // 3, source=f"s{k}"))
    return Dataset("tiny", samples, ("a", "b", "c"),
                   grid_layout() if layout else None, normalisation)


# ---------------------------------------------------------------- recordings


def test_recording_converts_and_iterates():
    rec = Recording(np.arange(6).reshape(3, 2), [0.0, 0.1, 0.2], np.array([5, 6], np.int32))
    assert rec.values.dtype == np.float32 and rec.timestamps.dtype == np.float64
    assert rec.taxel_ids.dtype == np.int64
    assert (rec.n_frames, rec.n_taxels) == (3, 2) and rec.duration == pytest.approx(0.2)
    frames = list(rec.frames())
    assert isinstance(frames[1], Frame) and frames[1].timestamp == pytest.approx(0.1)
    ts, values = frames[2]  # frames are (timestamp, values) tuples too
    assert values.tolist() == [4, 5]


@pytest.mark.parametrize("kwargs, message", [
    (dict(values=np.zeros(3), timestamps=[0], taxel_ids=[1]), "shape \\(T, N\\)"),
    (dict(values=np.zeros((0, 2)), timestamps=[], taxel_ids=[1, 2]), "T, N ≥ 1"),
    (dict(values=np.zeros((2, 2)), timestamps=[0.0], taxel_ids=[1, 2]), "timestamps must have"),
    (dict(values=np.zeros((2, 2)), timestamps=[0.1, 0.0], taxel_ids=[1, 2]), "go backwards"),
    (dict(values=np.zeros((2, 2)), timestamps=[0, np.nan], taxel_ids=[1, 2]), "finite"),
    (dict(values=np.zeros((2, 2)), timestamps=[0, 1], taxel_ids=[1, 1]), "duplicate taxel"),
    (dict(values=np.zeros((2, 2)), timestamps=[0, 1], taxel_ids=[1.5, 2]), "integers"),
    (dict(values=np.array([[0, np.inf], [0, 0]]), timestamps=[0, 1], taxel_ids=[1, 2]),
     "infinite values .first at frame 0, taxel column 1"),
])
def test_bad_recordings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Recording(**kwargs)


def test_nan_marks_a_missing_reading():
    rec = Recording(np.array([[1, np.nan]]), [0.0], [1, 2])
    assert np.isnan(rec.values[0, 1])


# ------------------------------------------------------------------ datasets


def test_dataset_accessors():
    ds = make_dataset()
    assert len(ds) == 6 and ds.labels.dtype == np.int64
    assert ds.labels.tolist() == [0, 1, 2, 0, 1, 2]
    assert ds.users == ["u0", "u1"] * 3
    assert ds.n_taxels == 16 and ds[0].source == "s0"


def test_dataset_validation():
    ds = make_dataset()
    bad_label = Sample(ds[0].recording, 3)
    with pytest.raises(ValueError, match="label 3, expected 0..2"):
        Dataset("x", [bad_label], ("a", "b", "c"))
    other = Sample(Recording(np.zeros((2, 3)), [0, 1], [1, 2, 3]), 0, source="odd.txt")
    with pytest.raises(ValueError, match=r"sample 1 \(odd.txt\) has different taxel ids"):
        Dataset("x", [ds[0], other], ("a",))
    with pytest.raises(ValueError, match="duplicate class names"):
        Dataset("x", [ds[0]], ("a", "a"))
    with pytest.raises(ValueError, match="no samples"):
        Dataset("x", [], ("a",))
    lay = TaxelLayout(ids=[100, 101, 102], positions=[[0, 0], [1, 0], [0, 1]], name="small")
    with pytest.raises(ValueError,
                       match="13 taxel id.s. of the dataset 'x' are not in layout small"):
        Dataset("x", [ds[0]], ("a",), layout=lay)


def test_fixed_normalisation_maps_the_16_bit_range():
    ds = make_dataset()
    vec = ds.vectors()
    assert all(v.dtype == np.float32 and v.shape == s.recording.values.shape
               for v, s in zip(vec, ds))
    assert np.allclose(vec[0], ds[0].recording.values / 65535)
    assert min(v.min() for v in vec) >= 0 and max(v.max() for v in vec) <= 1


def test_baseline_normalisation_removes_each_taxels_rest_value():
    ids = np.arange(3)
    base = np.array([1000, 2000, 3000], np.float32)
    rest = np.tile(base, (20, 1))
    pressed = rest.copy()
    pressed[10:, 1] += 5000  # taxel 1 pressed in half the frames
    ds = Dataset("b", [Sample(Recording(rest, np.arange(20) * .1, ids), 0),
                       Sample(Recording(pressed, np.arange(20) * .1, ids), 0)], ("a",),
                 normalisation="baseline:low=5,high=99")
    offset, scale = ds.normalisation_params()
    assert np.allclose(offset, base) and scale == pytest.approx(5000)
    vec = ds.vectors()
    assert np.all(vec[0] == 0) and vec[1][15, 1] == pytest.approx(1.0)


def test_normalisation_specs():
    assert Normalisation.parse("fixed").spec == "fixed:offset=0,scale=65535"
    assert Normalisation.parse("fixed:scale=1023").options == (("offset", 0.0), ("scale", 1023.0))
    with pytest.raises(ValueError, match="unknown normalisation 'zscore'"):
        Normalisation.parse("zscore")
    with pytest.raises(ValueError, match="has no option 'high'"):
        Normalisation.parse("fixed:high=3")
    with pytest.raises(ValueError, match="0 ≤ low < high ≤ 100"):
        Normalisation.parse("baseline:low=50,high=10")


def test_vectors_read_missing_as_zero_and_images_fill_them():
    ds = make_dataset()
    values = ds[0].recording.values.copy()
    values[0, 5] = np.nan
    rec = Recording(values, ds[0].recording.timestamps, ds[0].recording.taxel_ids)
    nds = Dataset("n", [Sample(rec, 0)], ("a",), grid_layout())
    assert nds.vectors()[0][0, 5] == 0
    img = nds.images(pixel_mm=2.0)[0]
    assert np.all(np.isfinite(img))


def test_images_are_float32_in_unit_range():
    ds = make_dataset()
    imgs = ds.images(pixel_mm=2.0, method="gaussian")
    h, w = ds.imager(2.0, "gaussian").shape
    for img, s in zip(imgs, ds):
        assert img.dtype == np.float32 and img.shape == (s.recording.n_frames, h, w)
        assert img.min() >= 0 and img.max() <= 1


def test_images_without_a_layout_say_so():
    ds = make_dataset(layout=False)
    with pytest.raises(ValueError, match="dataset 'tiny' has no taxel layout"):
        ds.images()


def test_layout_in_another_order_is_matched_by_id():
    ds = make_dataset()
    lay = grid_layout()
    order = np.random.default_rng(3).permutation(16)
    shuffled = TaxelLayout(ids=lay.ids[order], positions=lay.positions[order], name="shuffled")
    ds2 = Dataset("tiny", ds.samples, ds.classes, shuffled, "fixed")
    assert np.allclose(ds2.images(pixel_mm=2.0)[0], ds.images(pixel_mm=2.0)[0], atol=1e-6)


# -------------------------------------------------------------- content hash


def test_content_hash_tracks_content_not_name():
    ds = make_dataset()
    h = ds.content_hash()
    assert len(h) == 64 and ds.content_hash() is h  # cached
    assert Dataset("renamed", ds.samples, ds.classes, ds.layout, "fixed").content_hash() == h
    assert make_dataset(seed=1).content_hash() != h
    assert Dataset("tiny", ds.samples, ("a", "b", "z"), ds.layout, "fixed").content_hash() != h
    assert Dataset("tiny", ds.samples, ds.classes, None, "fixed").content_hash() != h


def test_content_hash_is_stable_across_processes(tmp_path):
    ds = make_dataset()
    ds.save(tmp_path / "d")
    code = ("from tactbench.data.recording import Dataset; "
            f"print(Dataset.load({str(tmp_path / 'd')!r}, verify=False).content_hash())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={"PYTHONHASHSEED": "123", "PATH": ""})
    assert out.stdout.strip() == ds.content_hash()


# ------------------------------------------------------------------- on disk


@pytest.mark.parametrize("layout", [True, False])
def test_save_and_load_round_trip(tmp_path, layout):
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


def _saved(tmp_path):
    folder = make_dataset().save(tmp_path / "d")
    return folder, json.loads((folder / "manifest.json").read_text())


def _rewrite(folder, **changes):
    arrays = dict(np.load(folder / "arrays.npz"))
    arrays.update(changes)
    for key, value in list(arrays.items()):
        if value is None:
            del arrays[key]
    np.savez(folder / "arrays.npz", **arrays)


def test_load_errors_name_the_file_and_problem(tmp_path):
    with pytest.raises(FileNotFoundError):
        Dataset.load(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="not a tactbench dataset folder"):
        Dataset.load(tmp_path / "empty")
    folder, manifest = _saved(tmp_path)
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
def test_bad_arrays(tmp_path, change, message):
    folder, manifest = _saved(tmp_path)
    if "offsets" in change:
        change["offsets"][-1] = manifest["n_frames"]
    _rewrite(folder, **change)
    with pytest.raises(ValueError, match=message) as info:
        Dataset.load(folder)
    assert "arrays.npz" in str(info.value) or "manifest.json" in str(info.value)


def test_timestamps_going_backwards_in_a_file(tmp_path):
    folder, _ = _saved(tmp_path)
    ts = np.load(folder / "arrays.npz")["timestamps"].copy()
    ts[1] = -5
    _rewrite(folder, timestamps=ts)
    with pytest.raises(ValueError, match="sample 0: timestamps go backwards"):
        Dataset.load(folder)


def test_edited_values_fail_the_hash_check(tmp_path):
    folder, _ = _saved(tmp_path)
    values = np.load(folder / "arrays.npz")["values"].copy()
    values[0, 0] += 1
    _rewrite(folder, values=values)
    with pytest.raises(ValueError, match="does not match the manifest"):
        Dataset.load(folder)
    assert len(Dataset.load(folder, verify=False)) == 6


def test_truncated_arrays_file(tmp_path):
    folder, _ = _saved(tmp_path)
    data = (folder / "arrays.npz").read_bytes()
    (folder / "arrays.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="cannot read the arrays"):
        Dataset.load(folder)
