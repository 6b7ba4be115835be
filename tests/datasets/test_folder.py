"""Folders of arrays: grids and taxel vectors from ROOT/<class>/<recording>.{npy,npz,csv}."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.data.dataset import Dataset
from tactbench.data.layout import TaxelLayout
from tactbench.data.layout_io import write_layout_csv
from tactbench.datasets.folder import FolderDataset, read_folder
from tactbench.datasets.loading import detect_format, load_dataset
from tactbench.errors import BudgetError, InputError, MissingFileError, TactbenchError

CLASSES = ("tap", "stroke", "press")
USERS = ("ana", "ben", "cai", "dee")


def make_grids(root, *, rows=6, cols=5, users=USERS, reps=2, seed=0, fmt="npy"):
    """Generated grid recordings of varied lengths; returns {relative path: array}."""
    rng = np.random.default_rng(seed)
    made = {}
    for ci, cls in enumerate(CLASSES):
        (root / cls).mkdir(parents=True, exist_ok=True)
        for user in users:
            for rep in range(reps):
                t = int(rng.integers(4, 9))
                arr = rng.integers(0, 1000, size=(t, rows, cols)).astype(np.uint16)
                arr[:, ci % rows, :] += 20  # a little class structure
                rel = f"{cls}/{user}_{rep}.{fmt}"
                if fmt == "npy":
                    np.save(root / rel, arr)
                elif fmt == "npz":
                    np.savez(root / rel, values=arr, timestamps=np.arange(t) * 0.05 + 3.0)
                else:
                    write_csv(root / rel, arr.reshape(t, -1), times=np.arange(t) * 0.05)
                made[rel] = arr
    return made


def write_csv(path, rows, *, times=None, header=True):
    lines = []
    if header:
        lines.append(",".join((["t"] if times is not None else [])
                              + [f"c{k}" for k in range(rows.shape[1])]))
    for k, row in enumerate(rows):
        lines.append(",".join(([f"{times[k]:.3f}"] if times is not None else [])
                              + [str(v) for v in row]))
    path.write_text("\n".join(lines) + "\n")


# ------------------------------------------------------------------------ reading


def test_grid_folder_reads_classes_users_lengths_and_its_own_layout(tmp_path):
    made = make_grids(tmp_path / "d")
    ds = read_folder(tmp_path / "d", users="prefix", pitch_mm=8)
    assert ds.classes == ("press", "stroke", "tap")  # natural order of the folder names
    assert len(ds) == len(made) == 24
    assert ds.layout.name == "grid-6x5" and ds.layout.n_taxels == 30
    assert sorted(set(ds.users)) == list(USERS)
    for s in ds.samples:
        arr = made[s.source]
        assert ds.classes[s.label] == s.source.split("/")[0]
        assert s.user == s.source.split("/")[1].split("_")[0]
        np.testing.assert_array_equal(s.recording.values, arr.reshape(len(arr), -1))
        np.testing.assert_allclose(s.recording.timestamps, np.arange(len(arr)) / 10.0)
    assert sorted({s.repetition for s in ds.samples}) == [1, 2]
    # one pixel per cell at pixel_mm == pitch_mm: the grid is the image
    images = ds.images(8.0, indices=[0])[0]
    assert images.shape[1:] == (6, 5)


def test_npz_and_csv_hold_the_same_data_as_npy(tmp_path):
    make_grids(tmp_path / "a")
    make_grids(tmp_path / "b", fmt="npz")
    make_grids(tmp_path / "c", fmt="csv")
    a = read_folder(tmp_path / "a", users="prefix")
    b = read_folder(tmp_path / "b", users="prefix")
    c = read_folder(tmp_path / "c", users="prefix", timestamp_column="t", grid="6x5")
    for x, y in zip(a.samples, b.samples):
        np.testing.assert_array_equal(x.recording.values, y.recording.values)
    for x, y in zip(a.samples, c.samples):
        np.testing.assert_array_equal(x.recording.values, y.recording.values)
    # timestamps from the files (made to start at 0), not from the rate
    np.testing.assert_allclose(b.samples[0].recording.timestamps,
                               np.arange(b.samples[0].recording.n_frames) * 0.05)
    assert b.summary()["frame_rate_hz"] == c.summary()["frame_rate_hz"] == 20.0
    assert c.layout.name == "grid-6x5"


def test_taxel_vectors_without_and_with_a_layout(tmp_path):
    root = tmp_path / "v"
    for cls in CLASSES:
        (root / cls).mkdir(parents=True)
        for k in range(2):
            np.save(root / cls / f"r{k}.npy", np.full((3 + k, 7), k, dtype=np.float32))
    ds = read_folder(root, rate=50)
    assert ds.layout is None and ds.n_taxels == 7
    np.testing.assert_array_equal(ds.taxel_ids, np.arange(7))
    np.testing.assert_allclose(ds.samples[1].recording.timestamps, [0, 0.02, 0.04, 0.06])
    assert ds.users == [""] * 6 and "50 Hz" in ds.description
    lay = TaxelLayout(ids=np.arange(100, 107), positions=np.c_[np.arange(7.0), np.zeros(7)])
    write_layout_csv(lay, tmp_path / "layout.csv")
    with_layout = read_folder(root, layout=tmp_path / "layout.csv")
    np.testing.assert_array_equal(with_layout.taxel_ids, np.arange(100, 107))
    assert with_layout.layout.n_taxels == 7
    write_layout_csv(TaxelLayout(ids=np.arange(5), positions=np.c_[np.arange(5.0), np.zeros(5)]),
                     tmp_path / "small.csv")
    with pytest.raises(InputError, match=r"7 taxels per frame, but layout .*small.csv has 5"):
        read_folder(root, layout=tmp_path / "small.csv")


def test_users_from_a_csv_file_folders_or_nothing(tmp_path):
    make_grids(tmp_path / "d", reps=1)
    rows = ["recording,user,class"] + [f"{c}/{u}_0.npy,P{i},{c}" for c in CLASSES
                                       for i, u in enumerate(USERS)]
    (tmp_path / "d" / "users.csv").write_text("\n".join(rows) + "\n")
    ds = read_folder(tmp_path / "d")  # ROOT/users.csv is picked up by default
    assert sorted(set(ds.users)) == ["P0", "P1", "P2", "P3"]
    rows[3] = rows[3].replace(",tap", ",press") if ",tap" in rows[3] else \
        rows[3].rsplit(",", 1)[0] + ",tap"
    (tmp_path / "d" / "users.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match=r"users.csv, line 4: class .* does not match the "
                                         r"folder of"):
        read_folder(tmp_path / "d")
    (tmp_path / "d" / "users.csv").write_text("recording,user\ntap/ana_0,P0\n")
    with pytest.raises(InputError, match=r"press/ana_0.npy: not listed in"):
        read_folder(tmp_path / "d")
    nested = tmp_path / "n" / "tap" / "zoe"
    nested.mkdir(parents=True)
    np.save(nested / "a.npy", np.ones((2, 3, 3)))
    assert read_folder(tmp_path / "n", users="folder").users == ["zoe"]
    with pytest.raises(InputError, match=r"recordings sit directly in their class folder"):
        read_folder(tmp_path / "n")
    np.save(tmp_path / "n" / "tap" / "nouser.npy", np.ones((2, 3, 3)))
    with pytest.raises(InputError, match=r"nouser.npy: with users=folder"):
        read_folder(tmp_path / "n", users="folder")


def test_normalisation_from_the_data_the_range_or_a_spec(tmp_path):
    make_grids(tmp_path / "d", reps=1)
    auto = read_folder(tmp_path / "d")
    top = max(float(s.recording.values.max()) for s in auto.samples)
    assert auto.normalisation.spec == f"fixed:offset=0,scale={top:g}"
    assert read_folder(tmp_path / "d", vmax=1023).normalisation.spec == "fixed:offset=0,scale=1023"
    assert read_folder(tmp_path / "d", vmin=10, vmax=20).normalisation.spec == \
        "fixed:offset=10,scale=10"
    assert read_folder(tmp_path / "d", normalisation="baseline").normalisation.kind == "baseline"
    with pytest.raises(InputError, match="vmax .* must be greater than vmin"):
        read_folder(tmp_path / "d", vmin=5, vmax=5)


def test_classes_option_orders_and_checks_the_folders(tmp_path):
    make_grids(tmp_path / "d", reps=1)
    assert read_folder(tmp_path / "d", classes="tap;stroke;press").classes == CLASSES
    with pytest.raises(InputError, match=r"d/press: folder 'press' is not among classes="):
        read_folder(tmp_path / "d", classes="tap;stroke")
    with pytest.raises(InputError, match=r"class 'wave' \(from classes=\) has no folder"):
        read_folder(tmp_path / "d", classes="tap;stroke;press;wave")


# ---------------------------------------------------------------------- bad input


def _bad_tree(tmp_path):
    root = tmp_path / "bad"
    for cls in ("a", "b"):
        (root / cls).mkdir(parents=True)
        np.save(root / cls / "x.npy", np.ones((3, 4, 4)))
    return root


@pytest.mark.parametrize("make, message", [
    (lambda r: np.save(r / "b" / "y.npy", np.array([np.ones((2, 2)), np.ones((3, 3))],
                                                   dtype=object), allow_pickle=True),
     r"b/y.npy: the file holds Python objects \(a ragged array"),
    (lambda r: np.save(r / "b" / "y.npy", np.ones((3, 5, 5))),
     r"b/y.npy: frames of a 5×5 grid, but .*a/x.npy \(the first recording\) has frames of "
     r"a 4×4 grid"),
    (lambda r: (r / "c").mkdir(), r"bad/c: empty class folder"),
    (lambda r: (r / "b" / "y.npy").write_bytes(b"PK\x03\x04 not an array"),
     r"b/y.npy: the file is not a valid .npy array"),
    (lambda r: (r / "b" / "y.npz").write_bytes(np.random.default_rng(0).bytes(300)),
     r"b/y.npz: not a valid .npz file \(not a zip archive"),
    (lambda r: (r / "b" / "y.csv").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe"),
     r"b/y.csv: not a text CSV file"),
    (lambda r: (r / "b" / "y.csv").write_text("1,2,3\n4,5\n"),
     r"b/y.csv, line 2: 2 fields, expected 3 \(as the first row; rows of different lengths"),
    (lambda r: (r / "b" / "y.csv").write_text("1,2,3\n4,x,6\n"),
     r"b/y.csv, line 2: column 1 is 'x', not a number"),
    (lambda r: np.save(r / "stray.npy", np.ones((3, 4, 4))),
     r"stray.npy: a recording outside any class folder"),
    (lambda r: np.save(r / "b" / "y.npy", np.ones((0, 4, 4))), r"b/y.npy: no frames"),
    (lambda r: np.save(r / "b" / "y.npy", np.ones(4)), r"b/y.npy: array of shape \(4,\)"),
    (lambda r: np.save(r / "b" / "y.npy", np.full((2, 4, 4), np.inf)),
     r"b/y.npy: recording has infinite values"),
    (lambda r: np.save(r / "b" / "y.npy", np.array(["a", "b"])), r"holds <U1 values"),
])
def test_each_mistake_is_one_line_naming_the_file(tmp_path, make, message):
    root = _bad_tree(tmp_path)
    make(root)
    with pytest.raises(InputError, match=message):
        read_folder(root)


def test_truncated_and_oversized_arrays_are_refused_from_their_header(tmp_path, monkeypatch,
                                                                      memory_cap):
    root = _bad_tree(tmp_path)
    np.save(root / "b" / "y.npy", np.ones((50, 4, 4)))
    data = (root / "b" / "y.npy").read_bytes()
    (root / "b" / "y.npy").write_bytes(data[:-100])
    with pytest.raises(InputError, match=r"y.npy: the file is truncated: its header says "
                                         r"50×4×4 float64"):
        read_folder(root)
    # a member claiming 2e10 floats in a small npz: refused before anything is read
    header = data[:data.index(b"\n") + 1].replace(b"(50, 4, 4)", b"(20000000000, 4, 4)")
    with zipfile.ZipFile(root / "b" / "y.npz", "w") as zf:
        zf.writestr("values.npy", header + b"\x00" * 64)
    (root / "b" / "y.npy").unlink()
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "1024")
    with memory_cap(50), pytest.raises(BudgetError, match=r"y.npz .* would need about .*TiB, "
                                                          r"more than the memory budget"):
        read_folder(root)


def test_npz_reads_only_its_defined_members(tmp_path, memory_cap):
    root = _bad_tree(tmp_path)
    (root / "b" / "x.npy").unlink()
    big = np.zeros(40_000_000, dtype=np.uint8)  # 40 MB, compresses to ~40 KB
    np.savez_compressed(root / "b" / "y.npz", values=np.ones((3, 4, 4)), extra=big)
    del big
    with memory_cap(20):
        ds = read_folder(root)
    assert len(ds) == 2
    np.savez(root / "b" / "y.npz", first=np.ones((3, 4, 4)), second=np.ones((3, 4, 4)))
    with pytest.raises(InputError, match=r"y.npz: .npz needs a member 'values'"):
        read_folder(root)


def test_missing_root_or_a_file_as_root(tmp_path):
    with pytest.raises(MissingFileError, match="no such folder"):
        read_folder(tmp_path / "nope")
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        read_folder(tmp_path / "f")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no class folders"):
        read_folder(tmp_path / "empty")


def test_users_prefix_needs_the_separator(tmp_path):
    root = _bad_tree(tmp_path)
    with pytest.raises(InputError, match=r"a/x.npy: users=prefix needs file names like "
                                         r"USER_REST.npy"):
        read_folder(root, users="prefix")
    np.save(root / "b" / "x-y.npy", np.ones((3, 4, 4)))
    (root / "a" / "x.npy").rename(root / "a" / "u1-1.npy")
    (root / "b" / "x.npy").rename(root / "b" / "u2-1.npy")
    assert read_folder(root, users="prefix", users_sep="-").users == ["u1", "u2", "x"]


# ---------------------------------------------------------------- the Dataset contract


def test_registered_reader_path_detection_and_import_round_trip(tmp_path):
    make_grids(tmp_path / "d", fmt="npz")
    direct = read_folder(tmp_path / "d", users="prefix", pitch_mm=7)
    from tactbench.plugins import load_registry

    source = load_registry().build("dataset", f"folder:path={tmp_path / 'd'},users=prefix,"
                                              f"pitch_mm=7")
    assert isinstance(source, FolderDataset)
    assert source.load().content_hash() == direct.content_hash()
    assert detect_format(tmp_path / "d") == "folder"
    assert load_dataset(tmp_path / "d").content_hash() == read_folder(tmp_path / "d") \
        .content_hash()

    out = tmp_path / "imported"
    res = CliRunner().invoke(cli, ["data", "import", str(tmp_path / "d"), "--format",
                                   "folder:users=prefix,pitch_mm=7", "--out", str(out)])
    assert res.exit_code == 0, res.output
    back = Dataset.load(out)
    assert back.content_hash() == direct.content_hash()
    assert back.users == direct.users and back.layout.name == "grid-6x5"
    assert direct.content_hash()[:16] in res.output
    # a second import never overwrites what is there
    manifest = (out / "manifest.json").read_bytes()
    again = CliRunner().invoke(cli, ["data", "import", str(tmp_path / "d"), "--out", str(out)])
    assert again.exit_code == 2 and "already holds a tactbench dataset" in again.output
    assert (out / "manifest.json").read_bytes() == manifest


def test_import_of_any_readable_source_and_its_errors(tmp_path):
    from tactbench.datasets.cost import read_cost_csv, write_cost_csv
    from tactbench.datasets.synthetic_forearm import generate

    src = generate(users=2, positions=1, repetitions=1, seed=1)
    src.save(tmp_path / "syn")
    res = CliRunner().invoke(cli, ["data", "import", str(tmp_path / "syn"),
                                   "--out", str(tmp_path / "copy")])
    assert res.exit_code == 0, res.output
    assert Dataset.load(tmp_path / "copy").content_hash() == src.content_hash()

    grid = TaxelLayout.grid(8, 8, 10.0)
    from tactbench.data.recording import Recording, Sample

    rec = Recording(np.arange(128, dtype=np.float32).reshape(2, 64), [0.0, 0.1], grid.ids)
    write_cost_csv(Dataset("c", [Sample(rec, 0, user="s1", position="gentle")], ["pat"], grid,
                           "fixed:scale=1023"), tmp_path / "cost.csv")
    res = CliRunner().invoke(cli, ["data", "import", str(tmp_path / "cost.csv"), "--format",
                                   "cost:pitch_mm=10", "--out", str(tmp_path / "cost-ds")])
    assert res.exit_code == 0, res.output
    assert Dataset.load(tmp_path / "cost-ds").content_hash() == \
        read_cost_csv(tmp_path / "cost.csv").content_hash()

    for args, message in [
        ([str(tmp_path / "nope"), "--out", str(tmp_path / "o")], "nope: no such file or folder"),
        ([str(tmp_path / "syn"), "--format", "folder:path=x", "--out", str(tmp_path / "o")],
         "give the path as SRC"),
        ([str(tmp_path / "cost.csv"), "--out", str(tmp_path / "cost.csv")],
         "overlaps the input"),
        ([str(tmp_path / "syn"), "--out", str(tmp_path / "cost.csv")],
         "is a file, not a folder"),
    ]:
        res = CliRunner().invoke(cli, ["data", "import", *args])
        assert res.exit_code == 2 and message in res.output, res.output
        assert "Traceback" not in res.output
    assert not (tmp_path / "o").exists()


def test_every_reader_error_is_a_tactbench_error(tmp_path):
    root = _bad_tree(tmp_path)
    (root / "a" / "x.npy").write_bytes(b"\x93NUMPY\x01\x00garbage")
    with pytest.raises(TactbenchError):
        read_folder(root)


# ------------------------------------------------------------------- end to end


@pytest.mark.usefixtures("one_torch_thread")
def test_generated_grids_and_vectors_run_with_no_python(tmp_path, monkeypatch):
    """The issue's done-when: a grid folder runs with farneback + logreg, split by users;
    the same data as (T, N) vectors runs with taxel-lstm."""
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    made = make_grids(tmp_path / "grids", rows=8, cols=8, reps=2)
    for rel, arr in made.items():
        (tmp_path / "vectors" / rel).parent.mkdir(parents=True, exist_ok=True)
        np.save(tmp_path / "vectors" / rel, arr.reshape(len(arr), -1))
    runs = [("grids", "farneback", "logreg"), ("vectors", "raw",
                                              "taxel-lstm:epochs=1,windows_per_epoch=32")]
    for folder, encoder, classifier in runs:
        out = tmp_path / f"out-{folder}"
        res = CliRunner().invoke(cli, [
            "run", "--dataset", f"folder:path={tmp_path / folder},users=prefix",
            "--encoder", encoder, "--classifier", classifier, "-L", "3", "--seed", "0",
            "--split", "users", "--threads", "1", "--out", str(out), "--json", "--no-plots"],
            catch_exceptions=False)
        assert res.exit_code == 0, res.output
        doc = json.loads(res.stdout)
        assert doc["failed"] == [] and doc["meta"]["computed"] == 1
        row = doc["summary"][0]
        assert row["encoder"] == encoder and 0.0 <= row["accuracy_mean"] <= 1.0
