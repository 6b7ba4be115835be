"""Dataset: validation, accessors, vectors, images and the content hash."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from tactbench.data.dataset import Dataset
from tactbench.data.layout import TaxelLayout
from tactbench.data.recording import Recording, Sample


def test_dataset_accessors(make_dataset):
    ds = make_dataset()
    assert len(ds) == 6 and ds.labels.dtype == np.int64
    assert ds.labels.tolist() == [0, 1, 2, 0, 1, 2]
    assert ds.users == ["u0", "u1"] * 3
    assert ds.n_taxels == 16 and ds[0].source == "s0"


def test_dataset_validation(make_dataset):
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


def test_vectors_read_missing_as_zero_and_images_fill_them(make_dataset, grid_layout):
    ds = make_dataset()
    values = ds[0].recording.values.copy()
    values[0, 5] = np.nan
    rec = Recording(values, ds[0].recording.timestamps, ds[0].recording.taxel_ids)
    nds = Dataset("n", [Sample(rec, 0)], ("a",), grid_layout())
    assert nds.vectors()[0][0, 5] == 0
    img = nds.images(pixel_mm=2.0)[0]
    assert np.all(np.isfinite(img))


def test_images_are_float32_in_unit_range(make_dataset):
    ds = make_dataset()
    imgs = ds.images(pixel_mm=2.0, method="gaussian")
    h, w = ds.imager(2.0, "gaussian").shape
    for img, s in zip(imgs, ds):
        assert img.dtype == np.float32 and img.shape == (s.recording.n_frames, h, w)
        assert img.min() >= 0 and img.max() <= 1


def test_a_chunk_of_samples_is_imaged_as_in_the_whole_dataset(make_dataset):
    ds = make_dataset()
    whole, vectors = ds.images(pixel_mm=2.0), ds.vectors()
    assert ds.image_shape(2.0) == whole[0].shape[1:]
    for got, i in zip(ds.images(pixel_mm=2.0, indices=range(2, 5)), range(2, 5)):
        np.testing.assert_array_equal(got, whole[i])
    for got, i in zip(ds.vectors(indices=[4, 1]), [4, 1]):
        np.testing.assert_array_equal(got, vectors[i])


def test_images_without_a_layout_say_so(make_dataset):
    ds = make_dataset(layout=False)
    with pytest.raises(ValueError, match="dataset 'tiny' has no taxel layout"):
        ds.images()


def test_layout_in_another_order_is_matched_by_id(make_dataset, grid_layout):
    ds = make_dataset()
    lay = grid_layout()
    order = np.random.default_rng(3).permutation(16)
    shuffled = TaxelLayout(ids=lay.ids[order], positions=lay.positions[order], name="shuffled")
    ds2 = Dataset("tiny", ds.samples, ds.classes, shuffled, "fixed")
    assert np.allclose(ds2.images(pixel_mm=2.0)[0], ds.images(pixel_mm=2.0)[0], atol=1e-6)


# -------------------------------------------------------------- content hash


def test_content_hash_tracks_content_not_name(make_dataset):
    ds = make_dataset()
    h = ds.content_hash()
    assert len(h) == 64 and ds.content_hash() is h  # cached
    assert Dataset("renamed", ds.samples, ds.classes, ds.layout, "fixed").content_hash() == h
    assert make_dataset(seed=1).content_hash() != h
    assert Dataset("tiny", ds.samples, ("a", "b", "z"), ds.layout, "fixed").content_hash() != h
    assert Dataset("tiny", ds.samples, ds.classes, None, "fixed").content_hash() != h


def test_content_hash_is_stable_across_processes(tmp_path, make_dataset):
    ds = make_dataset()
    ds.save(tmp_path / "d")
    code = ("from tactbench.data.dataset import Dataset; "
            f"print(Dataset.load({str(tmp_path / 'd')!r}, verify=False).content_hash())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={"PYTHONHASHSEED": "123", "PATH": ""})
    assert out.stdout.strip() == ds.content_hash()
