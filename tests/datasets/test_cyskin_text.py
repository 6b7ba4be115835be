"""The CySkin acquisition text format: reading, writing, folders, bad input, real data."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.recording import Recording
from tactbench.datasets.cyskin_text import (
    CySkinText,
    read_cyskin_folder,
    read_cyskin_text,
    write_cyskin_text,
)
from tactbench.errors import BudgetError, InputError

HEADER = "56560 56561 56562"


def write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_reads_the_format(tmp_path):
    path = write(tmp_path / "s.txt", f"{HEADER}\n0 0.000000 38 135 0 \n1 0.100177 35 75 12 \n")
    rec = read_cyskin_text(path)
    assert rec.taxel_ids.tolist() == [56560, 56561, 56562]
    assert rec.values.dtype == np.float32 and rec.values.tolist() == [[38, 135, 0], [35, 75, 12]]
    assert rec.timestamps.tolist() == [0.0, 0.100177]


def test_write_and_read_back_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    values = rng.integers(0, 20000, (30, 50)).astype(np.float32)
    values[3, 4] = 12.5  # fractional values survive too
    values[5, 6] = np.nan  # and missing readings
    rec = Recording(values, np.cumsum(rng.uniform(0.09, 0.11, 30)), np.arange(50) + 16)
    write_cyskin_text(rec, tmp_path / "r.txt")
    back = read_cyskin_text(tmp_path / "r.txt")
    assert np.array_equal(back.values, rec.values, equal_nan=True)
    assert np.array_equal(back.timestamps, rec.timestamps)
    assert np.array_equal(back.taxel_ids, rec.taxel_ids)


@pytest.mark.parametrize("text, message", [
    ("", "empty file"),
    ("\n\n", "empty file"),
    ("\n1 2 3\n0 0 1 2 3\n", "line 1: empty header"),
    ("frame timestamp a b\n0 0 1 2\n",
     r"line 1, field 1: the header must list integer taxel ids, found 'frame'"),
    ("1 2 2\n0 0 1 2 3\n", r"line 1, field 3: duplicate taxel id 2 \(also field 2\)"),
    ("1 2 3\n", "no frames after the header"),
    ("1 2 3\n0 0 1 2 3\n1 0.1 1 2\n", "line 3: truncated or ragged row: expected 5 fields"),
    ("1 2 3\n0 0 1 2 3\n\n1 0.1 1 2 3\n", "line 3: truncated or ragged row: .* got 0"),
    ("1 2 3\n0 0 1 2 3 4\n", "line 2: too many values"),
    ("1 2 3\n0 0 1 x 3\n", r"line 2, field 4: 'x' is not a number"),
    ("1 2 3\n0 0 1 inf 3\n", "line 2, field 4: taxel 2 reads 'inf'; infinite values"),
    ("1 2 3\n0 0.2 1 2 3\n1 0.1 1 2 3\n",
     "line 3, field 2: timestamp 0.100000 s goes backwards"),
    ("1 2 3\n0.5 0 1 2 3\n", "line 2, field 1: frame index '0.5' is not an integer"),
    ("1 2 3\n0 nan 1 2 3\n", "line 2, field 2: timestamp 'nan' is not finite"),
    # hostile values: one line each, naming the field (OverflowError / inf before)
    ("12345678901234567890123 2 3\n0 0 1 2 3\n",
     "line 1, field 1: taxel id '12345678901234567890123' is out of range"),
    ("1 -2 3\n0 0 1 2 3\n", "line 1, field 2: taxel id '-2' is out of range"),
    ("1 2 " + "9" * 5000 + "\n0 0 1 2 3\n", "line 1, field 3: taxel id '9999.*…' is out of"),
    ("1 2 3\n0 0 1 2 1e300\n", "line 2, field 5: taxel 3 reads '1e300'; out of range"),
])
def test_bad_files(tmp_path, text, message):
    path = write(tmp_path / "bad.txt", text)
    with pytest.raises(InputError, match=message) as info:
        read_cyskin_text(path)
    assert "bad.txt" in str(info.value) and "\n" not in str(info.value)


def test_many_ids_and_short_rows_are_refused_before_allocating(tmp_path, memory_cap):
    """1.2 MB: 100 000 ids and 100 000 short rows. The old reader allocated the
    rows × ids matrix (75 GiB) before it looked at a row."""
    ids = " ".join(str(k) for k in range(100_000))
    path = write(tmp_path / "wide.txt", ids + "\n" + "0 0 1\n" * 100_000)
    with memory_cap(64), pytest.raises(InputError, match=r"wide.txt, line 2: truncated .*"
                                                         r"expected 100002 fields"):
        read_cyskin_text(path)


def test_a_file_beyond_the_memory_budget_is_refused(tmp_path, monkeypatch, memory_cap):
    """Well-formed, but ids × rows above the budget: one line, nothing allocated."""
    n, rows = 2000, 300  # 2.4 MB of float32 values
    ids = " ".join(str(k) for k in range(n))
    row = " ".join(["0"] * n)
    path = write(tmp_path / "big.txt",
                 ids + "\n" + "".join(f"{k} {k / 10} {row}\n" for k in range(rows)))
    assert read_cyskin_text(path).values.shape == (rows, n)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "1")
    with memory_cap(16), pytest.raises(BudgetError, match=r"big.txt: 300 frames × 2000 "
                                                          r"taxels would need about"):
        read_cyskin_text(path)
    # a folder counts what its earlier files hold
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "3")
    write(tmp_path / "ds" / "a" / "1.txt", path.read_text())
    write(tmp_path / "ds" / "a" / "2.txt", path.read_text())
    assert read_cyskin_text(tmp_path / "ds" / "a" / "2.txt").n_frames == rows
    with pytest.raises(BudgetError, match=r"2.txt: 300 frames"):
        read_cyskin_folder(tmp_path / "ds")


def test_the_cli_prints_one_line_and_exits_2(tmp_path):
    from click.testing import CliRunner

    from tactbench.cli import cli

    path = write(tmp_path / "c" / "bad.txt", "12345678901234567890123 2\n0 0 1 2\n")
    res = CliRunner().invoke(cli, ["data", "info", str(path)])
    assert res.exit_code == 2, res.output
    [line] = res.output.strip().splitlines()
    assert line.startswith("Error: ") and "line 1, field 1: taxel id" in line


def test_binary_file_and_missing_file(tmp_path):
    path = tmp_path / "bin.txt"
    path.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ValueError, match="not a CySkin text file"):
        read_cyskin_text(path)
    with pytest.raises(FileNotFoundError):
        read_cyskin_text(tmp_path / "absent.txt")


def test_nan_is_a_missing_reading(tmp_path):
    rec = read_cyskin_text(write(tmp_path / "n.txt", "1 2\n0 0 5 nan\n"))
    assert np.isnan(rec.values[0, 1])


def _folder(tmp_path):
    root = tmp_path / "fingers"
    for cls, n in (("1_finger", 2), ("0_finger", 3)):
        for k in range(n):
            write(root / cls / f"sample_{k + 1:02d}.txt",
                  f"{HEADER}\n0 0 {k} 1 2\n1 0.1 {k} 3 4\n2 0.2 0 0 {k}\n")
    return root


def test_a_folder_of_class_folders_is_a_dataset(tmp_path):
    ds = read_cyskin_folder(_folder(tmp_path))
    assert ds.name == "fingers" and ds.classes == ("0_finger", "1_finger")
    assert ds.labels.tolist() == [0, 0, 0, 1, 1]
    assert ds.sources[0] == "0_finger/sample_01.txt"
    assert ds.repetitions.tolist() == [1, 2, 3, 1, 2]
    assert ds.layout is None
    assert CySkinText(path=str(tmp_path / "fingers")).load().content_hash() == ds.content_hash()


def test_a_single_file_is_a_one_sample_dataset(tmp_path):
    ds = read_cyskin_folder(_folder(tmp_path) / "1_finger" / "sample_02.txt")
    assert len(ds) == 1 and ds.classes == ("1_finger",)


def test_folder_errors(tmp_path):
    root = _folder(tmp_path)
    write(root / "1_finger" / "sample_09.txt", "1 2 3\n0 0 1 2 3\n")
    with pytest.raises(ValueError, match=r"sample_09.txt: its taxel ids differ"):
        read_cyskin_folder(root)
    (tmp_path / "nothing").mkdir()
    with pytest.raises(ValueError, match="no CySkin text files"):
        read_cyskin_folder(tmp_path / "nothing")


def test_all_373_real_recordings_load(shared_data):
    ds = read_cyskin_folder(shared_data / "cyskin-fingers")
    assert len(ds) == 373
    assert ds.classes == tuple(f"{k}_finger" for k in range(6))
    assert np.bincount(ds.labels).tolist() == [41, 51, 70, 70, 70, 71]
    assert {s.recording.values.shape for s in ds} == {(30, 716)}
    assert ds.layout is None
    # the README: 60 modules, slots 0–11, non-negative values up to about 20000
    modules, slots = np.divmod(ds.taxel_ids, 16)
    assert len(np.unique(modules)) == 60 and slots.max() <= 11
    peak = max(float(s.recording.values.max()) for s in ds)
    assert min(float(s.recording.values.min()) for s in ds) >= 0 and 10000 < peak < 70000
    vec = ds.vectors()
    assert all(v.min() >= 0 and v.max() <= 1 for v in vec)


def test_real_recordings_round_trip_exactly(shared_data, tmp_path):
    src = shared_data / "cyskin-fingers" / "3_finger" / "sample_05.txt"
    rec = read_cyskin_text(src)
    write_cyskin_text(rec, tmp_path / "copy.txt")
    back = read_cyskin_text(tmp_path / "copy.txt")
    assert np.array_equal(back.values, rec.values)
    assert np.array_equal(back.timestamps, rec.timestamps)
    assert np.array_equal(back.taxel_ids, rec.taxel_ids)
