"""Checksums and the one .npy header reader."""

from __future__ import annotations

import io

import numpy as np
import pytest

from tactbench.integrity import (
    NPY_HEADER_MAX,
    hash_bytes,
    hash_chunks,
    hash_file,
    read_npy_header,
)


def _npy(arr) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def test_hashes_of_a_file_its_bytes_and_its_chunks_agree(tmp_path):
    data = np.random.default_rng(0).bytes(3_000_000)
    (tmp_path / "f").write_bytes(data)
    whole = hash_bytes(data)
    assert hash_file(tmp_path / "f") == whole == hash_chunks([data[:7], data[7:]])
    assert hash_file(tmp_path / "f", length=10) == hash_bytes(data[:10])


def test_a_sound_header_leaves_the_stream_at_the_data():
    raw = _npy(np.arange(12, dtype="<i2").reshape(3, 4))
    fh = io.BytesIO(raw)
    assert read_npy_header(fh) == ((3, 4), False, np.dtype("<i2"))
    assert fh.read() == np.arange(12, dtype="<i2").tobytes()


@pytest.mark.parametrize("damage, reason", [
    (lambda b: b[:5], "no .npy magic string"),
    (lambda b: b[:6] + b"\x07\x00" + b[8:], "npy format version 7.0 is not read"),
    # version byte flipped to 2.0: the length field now reads 4 bytes, far too many
    (lambda b: b[:6] + b"\x02\x00" + b[8:], "a header of .* bytes"),
    (lambda b: b[:40], "cut short in its header"),
    (lambda b: b.replace(b"'shape': (3, 4)", b"'shape': (-3, 4)"), "shape"),
    (lambda b: b.replace(b"{'descr'", b"{'desc("), "Error"),
])
def test_every_damaged_header_is_a_value_error_with_its_reason(damage, reason):
    with pytest.raises(ValueError, match=reason):
        read_npy_header(io.BytesIO(damage(_npy(np.zeros((3, 4))))))


def test_a_longer_header_than_allowed_is_refused_before_it_is_read():
    raw = _npy(np.zeros(2))
    huge = raw[:8] + (100).to_bytes(2, "little") + raw[10:]
    with pytest.raises(ValueError, match="at most 64"):
        read_npy_header(io.BytesIO(huge), max_header=64)
    with pytest.raises(ValueError, match=f"at most {NPY_HEADER_MAX}"):
        read_npy_header(io.BytesIO(b"\x93NUMPY\x02\x00" + (1 << 30).to_bytes(4, "little")))
