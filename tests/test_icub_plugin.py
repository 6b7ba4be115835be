"""The iCub grasp dataset plugin in plugins/tactbench-icub: its reader on generated files in
the format (several classes, varied lengths, malformed cases), its registration, and the
real folder when it is beside the checkout."""

from __future__ import annotations

import importlib.metadata
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.errors import BudgetError, InputError, MissingFileError
from tactbench.plugins import load_registry

SRC = Path(__file__).resolve().parents[1] / "plugins" / "tactbench-icub" / "src"
try:  # the reader is tested from the source tree even when the plugin is not installed
    import tactbench_icub.reader as reader
except ImportError:
    sys.path.insert(0, str(SRC))
    import tactbench_icub.reader as reader


@pytest.fixture(scope="module")
def installed():
    try:
        importlib.metadata.distribution("tactbench-icub")
    except importlib.metadata.PackageNotFoundError:
        if os.environ.get("CI"):
            pytest.fail("tactbench-icub is not installed; CI installs it with "
                        "'pip install -e plugins/tactbench-icub'")
        pytest.skip("tactbench-icub not installed (pip install -e plugins/tactbench-icub)")


def _slice_lines(joints, readings) -> list[str]:
    """The 7 lines of one time slice; ``readings`` (5, 12), 8-bit, lower = more pressure."""
    readings = np.asarray(readings, dtype=float)
    lines = [" ".join(f"{j:g}" for j in joints) + " ",
             " ".join(f"{255 - r.min():.1f}" for r in readings)]
    lines += [" ".join(f"{v:.1f}" for v in row) for row in readings]
    return lines


def grasp_text(n_slices: int, *, seed: int = 0, press: float = 0.0, crlf: bool = False) -> str:
    """A grasp file of ``n_slices`` slices; ``press`` lowers the thumb's readings."""
    rng = np.random.default_rng(seed)
    lines = ["-10000"]
    for t in range(n_slices):
        readings = rng.integers(238, 250, size=(5, 12)).astype(float)
        readings[0] -= press * t
        joints = rng.random(9) * 90
        lines += _slice_lines(joints, readings.clip(0, 255))
    end = "\r\n" if crlf else "\n"
    return end.join(lines) + end


def write(folder: Path, name: str, text: str | bytes) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


# ------------------------------------------------------------------------------ reading


def test_a_file_becomes_pressure_per_slice(tmp_path):
    readings = np.full((5, 12), 240.0)
    readings[1, 3] = 100.0  # index finger, taxel 3, pressed hard
    joints = [20.5, 80.6, 13.4, 0.5, 39.6, 67.4, 35.9, 55.5, 4.0]
    text = "\n".join(["-10000", *_slice_lines(joints, readings),
                      *_slice_lines(joints, np.full((5, 12), 250.0))]) + "\n"
    path = write(tmp_path, "book_3.txt", text)
    rec = reader.read_icub_file(path)
    assert rec.values.shape == (2, 60) and rec.values.dtype == np.float32
    assert rec.values[0, 12 + 3] == 155.0  # 255 − 100
    assert rec.values[0, 0] == 15.0 and (rec.values[1] == 5.0).all()
    assert rec.taxel_ids.tolist() == list(range(60))
    assert rec.timestamps.tolist() == [0.0, 1.0]
    with_joints = reader.read_icub_file(path, joints=True)
    assert with_joints.values.shape == (2, 69)
    assert with_joints.values[0, 60:] == pytest.approx(joints)
    assert with_joints.taxel_ids[60:].tolist() == list(range(107, 116))


def test_windows_line_endings_and_blank_lines_read_alike(tmp_path):
    plain = reader.read_icub_file(write(tmp_path, "a_1.txt", grasp_text(3)))
    crlf = reader.read_icub_file(write(tmp_path, "b_1.txt", grasp_text(3, crlf=True)))
    blanks = reader.read_icub_file(write(tmp_path, "c_1.txt",
                                         grasp_text(3).replace("\n", "\n\n")))
    np.testing.assert_array_equal(plain.values, crlf.values)
    np.testing.assert_array_equal(plain.values, blanks.values)


def test_a_folder_is_a_dataset_of_objects_and_trials(tmp_path):
    folder = tmp_path / "icub" / "iCubGraspDataset"
    lengths = {("teddy", 1): 4, ("teddy", 2): 9, ("teddy", 10): 6, ("can", 1): 12,
               ("can", 2): 5, ("none", 1): 7, ("none", 2): 4, ("full_coke", 1): 8}
    for (obj, trial), n in lengths.items():
        write(folder, f"{obj}_{trial}.txt", grasp_text(n, seed=trial))
    ds = reader.read_icub_folder(tmp_path / "icub")  # the parent of iCubGraspDataset/ works
    assert ds.classes == ("can", "none", "teddy")  # sorted; full_coke left out
    assert "left out: full_coke" in ds.description
    got = {(ds.classes[s.label], s.repetition): s.recording.n_frames for s in ds}
    assert got == {k: v for k, v in lengths.items() if k[0] != "full_coke"}
    assert {s.user for s in ds} == {""} and ds.layout is None
    assert [s.source for s in ds][:3] == ["can_1.txt", "can_2.txt", "none_1.txt"]
    assert ds.normalisation.spec == reader.NORMALISATION
    every = reader.read_icub_folder(folder, full_coke=True, joints=True)
    assert "full_coke" in every.classes and every.n_taxels == 69 and len(every) == 8
    teddy = [s.repetition for s in every if every.classes[s.label] == "teddy"]
    assert teddy == [1, 2, 10]  # trials in number order, not text order


def test_the_registered_dataset_loads_through_the_registry(installed, tmp_path):
    folder = tmp_path / "grasps"
    for obj in ("bottle", "bear"):
        for trial in (1, 2, 3):
            write(folder, f"{obj}_{trial}.txt", grasp_text(5, seed=trial))
    from tactbench.datasets.loading import load_dataset

    ds = load_dataset(f"icub-grasp:path={folder},joints=true")
    assert ds.classes == ("bear", "bottle") and ds.n_taxels == 69 and len(ds) == 6
    assert ds.vectors()[0].shape == (5, 69)  # normalised taxel vectors, as the runner uses
    comp = next(c for c in load_registry().components("dataset") if c.name == "icub-grasp")
    assert comp.distribution == "tactbench-icub"


def test_classes_are_learnable_end_to_end(installed, tmp_path):
    """Generated grasps where one object presses the thumb harder over time: the runner's
    path (load, split, windows, a classifier) tells them apart."""
    from tactbench.datasets.loading import load_dataset

    folder = tmp_path / "grasps"
    for trial in range(1, 9):
        write(folder, f"soft_{trial}.txt", grasp_text(6 + trial % 3, seed=trial))
        write(folder, f"hard_{trial}.txt", grasp_text(6 + trial % 2, seed=50 + trial,
                                                      press=25))
    ds = load_dataset(f"icub-grasp:path={folder}")
    from tactbench.data.windows import test_windows, training_windows

    x = ds.vectors()
    labels = ds.labels
    train = training_windows(x[::2], labels[::2], 4)
    test = test_windows(x[1::2], labels[1::2], 4)
    clf = load_registry().build("classifier", "logreg")
    clf.fit(train, None, seed=0, device="cpu", progress=None)
    assert (clf.predict(test) == test.labels).mean() == 1.0


# ------------------------------------------------------------------------ bad input


GOOD = grasp_text(2).splitlines()  # line 1: -10000; lines 2-8 and 9-15: two slices


def _with(line: int, text: str) -> str:
    lines = list(GOOD)
    lines[line - 1] = text
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("content, message", [
    ("", "empty file"),
    ("-10000\n\n", "no time slice"),
    ("\n".join(GOOD[:12]) + "\n", "line 12: the file ends inside a time slice"),
    (_with(3, "1 2 3 4 5 6 7 8 9"), "line 3: expected 5 per-finger maxima"),
    (_with(4, " ".join(["240"] * 11)), "line 4: expected 12 taxel readings of the thumb"),
    (_with(2, "1 2 3 4 5 6 7 8 nine"), "line 2: value 9 'nine' is not a number"),
    (_with(7, " ".join(["nan"] * 12)), "line 7: value 1 is 'nan', not a finite number"),
    (_with(8, " ".join(["240"] * 11 + ["300"])), "line 8: reading 300 .* outside 0–255"),
    (_with(5, " ".join(["-1"] * 12)), "line 5: reading -1 .* outside 0–255"),
    (_with(11, "-10000"), "line 11: '-10000' inside a time slice"),
    (b"-10000\n\xff\xfe 1 2\n", "line 2: not ASCII"),
])
def test_malformed_files_are_one_line_naming_file_and_line(tmp_path, content, message):
    path = write(tmp_path, "bear_1.txt", content)
    with pytest.raises(InputError, match=message) as info:
        reader.read_icub_file(path)
    text = str(info.value)
    assert text.startswith(str(path)) and "\n" not in text


@pytest.mark.parametrize("files, message", [
    ({"bear_1.txt": GOOD, "notes.txt": GOOD}, "notes.txt: not named <object>_<trial>.txt"),
    ({"bear_1.txt": GOOD, "bear_01.txt": GOOD}, "trial 1 of 'bear' is also"),
    ({"full_coke_1.txt": GOOD}, "only full_coke files"),
    ({}, "no <object>_<trial>.txt grasp files"),
])
def test_malformed_folders(tmp_path, files, message):
    folder = tmp_path / "set"
    folder.mkdir()
    for name, lines in files.items():
        write(folder, name, "\n".join(lines) + "\n")
    with pytest.raises(InputError, match=message):
        reader.read_icub_folder(folder)


def test_missing_paths_and_bad_options(tmp_path):
    with pytest.raises(MissingFileError, match="no such folder"):
        reader.read_icub_folder(tmp_path / "absent")
    with pytest.raises(InputError, match="not a folder"):
        reader.read_icub_folder(write(tmp_path, "bear_1.txt", grasp_text(1)))
    with pytest.raises(InputError, match="joints must be true or false"):
        reader.ICubGrasp(path=str(tmp_path), joints="yes")
    with pytest.raises(InputError, match="needs path=FOLDER"):
        reader.ICubGrasp()


def test_files_beyond_the_memory_budget_are_refused_before_reading(tmp_path, monkeypatch):
    path = write(tmp_path / "set", "bear_1.txt", grasp_text(40))  # about 13 KiB
    reader.read_icub_folder(tmp_path / "set")
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "0.02")  # 20 KiB: not 4 × the file
    with pytest.raises(BudgetError, match=f"reading {path}"):
        reader.read_icub_file(path)
    with pytest.raises(BudgetError):
        reader.read_icub_folder(tmp_path / "set")


def test_the_cli_says_one_line_and_exits_2(installed, tmp_path):
    write(tmp_path / "set", "bear_1.txt", _with(4, "240 240"))
    result = CliRunner().invoke(cli, ["run", "--dataset", f"icub-grasp:path={tmp_path / 'set'}",
                                      "--encoder", "raw", "--classifier", "logreg",
                                      "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1 and "bear_1.txt, line 4" in lines[0]


# ---------------------------------------------------------------------- the real set


def test_the_real_dataset_has_the_readme_s_classes_and_counts(shared_data):
    folder = shared_data / "icub-grasp"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    ds = reader.read_icub_folder(folder)
    counts = ds.summary()["samples_per_class"]
    # README: 9 objects plus "none", 20-22 trials each; full_coke (27) left out.
    assert len(counts) == 10 and "full_coke" not in counts
    assert counts == {"blue_bear": 20, "book": 20, "empty_coke": 21,
                      "empty_vitamin_water": 20, "full_vitamin_water": 20, "lotion": 20,
                      "med_coke": 20, "med_vitamin_water": 20, "monkey_toy": 20, "none": 22}
    lengths = ds.lengths()
    assert lengths.min() >= 4 and lengths.max() <= 24  # 4-24 slices, per the README
    values = np.concatenate([s.recording.values for s in ds])
    assert ds.n_taxels == 60 and values.min() >= 0 and values.max() <= 255
    assert np.median(values) < 20  # pressure = 255 − reading: at rest it is small
    every = reader.read_icub_folder(folder, full_coke=True)
    assert every.summary()["samples_per_class"]["full_coke"] == 27


def test_a_taxel_vector_classifier_learns_the_real_objects(shared_data):
    """Not a benchmark: the real set, read by the plugin, is learnable at all."""
    folder = shared_data / "icub-grasp"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    from tactbench.data.windows import test_windows, training_windows

    ds = reader.read_icub_folder(folder)
    x, labels = ds.vectors(), ds.labels
    train = training_windows(x[::2], labels[::2], 5)
    test = test_windows(x[1::2], labels[1::2], 5)
    clf = load_registry().build("classifier", "logreg")
    clf.fit(train, None, seed=0, device="cpu", progress=None)
    assert (clf.predict(test) == test.labels).mean() > 0.5  # chance: 0.1
