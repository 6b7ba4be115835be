"""``tactbench encode``: a bad input or output is one line, exit 2, before encoding."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli


@pytest.fixture
def sequence(tmp_path):
    path = tmp_path / "seq.npy"
    np.save(path, np.zeros((4, 8, 8), np.float32))
    return path


def _refused(args) -> str:
    result = CliRunner().invoke(cli, ["encode", *args])
    assert result.exit_code == 2, result.output
    lines = [x for x in result.output.splitlines() if x.startswith("Error: ")]
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    return lines[0]


def test_an_out_under_a_file_is_refused_before_encoding(tmp_path, sequence):
    (tmp_path / "f").write_text("mine")
    line = _refused(["-e", "raw", "-i", str(sequence), "-o", str(tmp_path / "f" / "e.npy")])
    assert line == f"Error: --out {tmp_path / 'f' / 'e.npy'} cannot be written: " \
                   f"{tmp_path / 'f'} is a file, not a folder"
    assert (tmp_path / "f").read_text() == "mine"


def test_an_out_that_cannot_be_written_is_refused_before_encoding(tmp_path, sequence,
                                                                  monkeypatch):
    import errno
    import tempfile

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    line = _refused(["-e", "raw", "-i", str(sequence), "-o", str(tmp_path / "e.npy")])
    assert "cannot be written: Read-only file system" in line
    assert not (tmp_path / "e.npy").exists()


def _header(shape, dtype) -> bytes:
    import io

    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False,
                                               "shape": shape})
    return buf.getvalue()  # (magic string included)


@pytest.mark.parametrize("shape, match", [
    ((20_000_000_000, 8, 8), "truncated: its header says shape (20000000000, 8, 8) float32"),
    ((4, 8, 8), "truncated: its header says shape (4, 8, 8) float32 (1024 bytes) and the "
                "file holds 16"),
])
def test_a_header_claiming_more_than_the_file_holds_is_refused_before_reading(
        tmp_path, shape, match, memory_cap):
    path = tmp_path / "claim.npy"
    path.write_bytes(_header(shape, "<f4") + b"\0" * 16)
    with memory_cap(16):
        line = _refused(["-e", "raw", "-i", str(path), "-o", str(tmp_path / "e.npy")])
    assert f"{path}: {match}" in line


def test_an_input_whose_encoding_exceeds_the_budget_is_refused(tmp_path, monkeypatch):
    path = tmp_path / "big.npy"
    np.save(path, np.zeros((64, 128, 128), np.uint8))  # 1 MiB; farneback: 3 channels
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "8")
    line = _refused(["-e", "farneback", "-i", str(path), "-o", str(tmp_path / "e.npy")])
    assert f"encoding {path} (64 frames of 128×128 px into 3 channels) would need about " \
           f"17.0 MiB, more than the memory budget of 8.0 MiB" in line
    assert not (tmp_path / "e.npy").exists()


@pytest.mark.parametrize("content, match", [
    (b"\x93NUMPY garbage", "not a readable .npy array"),
    (b"PK\x03\x04 rest of a zip", "holds several arrays (.npz)"),
    (_header((2, 2, 2), "|O") + b"\0" * 64, "holds Python objects, not numbers"),
    (_header((8,), "<f4") + b"\0" * 32, "expected a (T, H, W) sequence, got shape (8,)"),
])
def test_a_bad_npy_file_is_one_line(tmp_path, content, match):
    path = tmp_path / "bad.npy"
    path.write_bytes(content)
    assert match in _refused(["-e", "raw", "-i", str(path), "-o", str(tmp_path / "e.npy")])


def test_a_good_sequence_still_encodes(tmp_path, sequence):
    result = CliRunner().invoke(cli, ["encode", "-e", "raw", "-i", str(sequence), "-o",
                                      str(tmp_path / "new" / "e.npy")])
    assert result.exit_code == 0, result.output
    assert np.load(tmp_path / "new" / "e.npy").shape == (4, 1, 8, 8)
