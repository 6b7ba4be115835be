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
    (dict(labels=np.array([0, 1, 2, 0, 1, 2], dtype=object)),
     "member 'labels' holds Python objects, which would need allow_pickle"),
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
    with pytest.raises(ValueError, match="not a valid .npz file"):
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


# ------------------------------------------------------------------ hostile folders


def _load_error(folder, match):
    """Load ``folder``; the error must be a TactbenchError in one line naming a file."""
    from tactbench.errors import TactbenchError

    with pytest.raises(TactbenchError, match=match) as info:
        Dataset.load(folder)
    text = str(info.value)
    assert "\n" not in text and ("arrays.npz" in text or "manifest.json" in text), text
    return info.value


def _npy_bytes(header: dict, payload: bytes) -> bytes:
    """An .npy file with any header (``descr``, ``fortran_order``, ``shape``)."""
    import io

    from numpy.lib import format as npy

    buf = io.BytesIO()
    npy.write_array_header_1_0(buf, header)
    return buf.getvalue() + payload


def _with_members(folder, **members):
    """Rewrite arrays.npz with members replaced or added: name → .npy bytes, stored
    deflated."""
    import zipfile

    path = folder / "arrays.npz"
    with zipfile.ZipFile(path) as z:
        old = {i.filename: z.read(i) for i in z.infolist()}
    old.update({f"{k}.npy": v for k, v in members.items()})
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, data in old.items():
            z.writestr(name, data)


def test_random_bytes_are_not_a_valid_npz(tmp_path, make_dataset):
    folder, _ = _saved(tmp_path, make_dataset)
    (folder / "arrays.npz").write_bytes(np.random.default_rng(0).bytes(4096))
    _load_error(folder, "arrays.npz: not a valid .npz file")


def test_a_member_claiming_a_huge_shape_is_refused_before_allocating(tmp_path, make_dataset,
                                                                     memory_cap):
    folder, _ = _saved(tmp_path, make_dataset)
    huge = _npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (20_000_000_000,)},
                      b"\0" * 64)
    _with_members(folder, timestamps=huge)
    with memory_cap(50):
        _load_error(folder, r"member 'timestamps' claims shape \(20000000000,\) float64 "
                            r"\(149.0 GiB\), but holds 64 B")


def test_arrays_above_the_memory_budget_are_refused(tmp_path, make_dataset, monkeypatch):
    from tactbench.errors import BudgetError

    rec = Recording(np.ones((300, 1000), np.float32), 0.1 * np.arange(300), np.arange(1000))
    folder = Dataset("big", [Sample(rec, 0)], ("a",)).save(tmp_path / "big")
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "1")
    err = _load_error(folder, r"reading .*arrays.npz \(6 arrays\) would need about 1.7 MiB, "
                              r"more than the memory budget of 1.0 MiB; set "
                              r"TACTBENCH_MEMORY_MIB")
    assert isinstance(err, BudgetError)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "8")
    assert Dataset.load(folder).n_taxels == 1000


def test_an_extra_member_is_never_decompressed(tmp_path, make_dataset, memory_cap):
    """64 MiB of zeros deflate to 64 KiB: reading the member would show in the cap."""
    import zipfile

    folder, _ = _saved(tmp_path, make_dataset)
    expected = Dataset.load(folder).content_hash()
    zeros = np.zeros(8 << 20, np.float64)
    with zipfile.ZipFile(folder / "arrays.npz", "a", compression=zipfile.ZIP_DEFLATED) as z:
        with z.open("extra.npy", "w", force_zip64=True) as f:
            np.lib.format.write_array(f, zeros)
        z.writestr("notes.txt", "not an array")
    del zeros
    assert (folder / "arrays.npz").stat().st_size < 1 << 20
    with memory_cap(20):
        assert Dataset.load(folder).content_hash() == expected


def test_duplicate_and_malformed_members(tmp_path, make_dataset):
    import zipfile

    folder, _ = _saved(tmp_path, make_dataset)
    with zipfile.ZipFile(folder / "arrays.npz", "a") as z:
        with pytest.warns(UserWarning, match="Duplicate name"):
            z.writestr("labels.npy", b"\x93NUMPY")
    _load_error(folder, "member 'labels.npy' appears twice")
    folder, _ = _saved(tmp_path / "2", make_dataset)
    _with_members(folder, labels=b"\x93NUMPY\x01\x00garbage")
    _load_error(folder, "member 'labels' is not a valid .npy array")
    folder, _ = _saved(tmp_path / "3", make_dataset)
    # a header that says 6 int64 labels over 6 bytes of data
    _with_members(folder, labels=_npy_bytes({"descr": "<i8", "fortran_order": False,
                                             "shape": (6,)}, b"\0" * 6))
    _load_error(folder, r"member 'labels' claims shape \(6,\) int64 \(48 B\), but holds 6 B")


@pytest.mark.parametrize("change, message", [
    ({"layout": "grid"}, "field 'layout' must be object or null, got str"),
    ({"layout": ["grid"]}, "field 'layout' must be object or null, got list"),
    ({"layout": {"name": 3}}, r"field 'layout' must be null or \{\"name\": string\}"),
    ({"layout": {"name": "g", "x": 1}}, r"field 'layout' must be null or"),
    ({"description": 5}, "field 'description' must be string, got int"),
    ({"values_dtype": ["uint16"]}, "field 'values_dtype' must be string, got list"),
    ({"values_dtype": "int8"}, "'values_dtype' must be one of uint16, float32, got 'int8'"),
    ({"values_dtype": "float32"}, "'values' is uint16, the manifest says float32"),
    ({"n_frames": 0}, "field 'n_frames' must be ≥ 1"),
    ({"n_samples": -1}, "field 'n_samples' must be ≥ 1"),
    ({"schema_version": True}, "schema_version True is not supported"),
    ({"classes": "abc"}, "field 'classes' must be a list"),
    ({"users": None}, "field 'users' must be a list, got NoneType"),
    ({"content_hash": 12}, "field 'content_hash' must be a str"),
])
def test_manifest_fields_of_the_wrong_type_are_one_line(tmp_path, make_dataset, change,
                                                        message):
    folder, manifest = _saved(tmp_path, make_dataset)
    (folder / "manifest.json").write_text(json.dumps({**manifest, **change}))
    _load_error(folder, message)


def test_a_manifest_naming_a_layout_needs_the_layout_arrays(tmp_path, make_dataset):
    folder = make_dataset(layout=False).save(tmp_path / "d")
    manifest = json.loads((folder / "manifest.json").read_text())
    (folder / "manifest.json").write_text(json.dumps({**manifest, "layout": {"name": "g"}}))
    _load_error(folder, "the manifest names a layout, but there is no 'layout_ids' array")


def test_a_deeply_nested_manifest_is_one_line(tmp_path, make_dataset):
    folder, _ = _saved(tmp_path, make_dataset)
    (folder / "manifest.json").write_text("[" * 100_000 + "]" * 100_000)
    _load_error(folder, "manifest.json: not valid JSON")


@pytest.mark.parametrize("field, value, message", [
    (6, 109, "not a valid .npz file"),  # "version needed to extract" 10.9: NotImplementedError
    (8, 1, "cannot read the arrays .*encrypted"),  # the "encrypted" flag: RuntimeError
])
def test_zip_directory_fields_flipped(tmp_path, make_dataset, field, value, message):
    """Found by the fuzz suite: zipfile raises NotImplementedError / RuntimeError on these."""
    import struct

    folder, _ = _saved(tmp_path, make_dataset)
    data = bytearray((folder / "arrays.npz").read_bytes())
    for start in range(len(data)):  # every central-directory entry
        if data[start:start + 4] == b"PK\x01\x02":
            struct.pack_into("<H", data, start + field, value)
    (folder / "arrays.npz").write_bytes(bytes(data))
    _load_error(folder, message)
