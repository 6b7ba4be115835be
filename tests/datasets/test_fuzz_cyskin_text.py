"""Fuzz: mutated CySkin text files give a recording or one TactbenchError, nothing else.

The inputs are real files the test writes (``write_cyskin_text`` of a small recording),
mutated the way a damaged or hostile file would be: lines dropped or duplicated, fields
replaced by huge, negative, non-numeric or overlong values, bytes flipped, the file cut.
Each read runs under a memory cap and must leave the file as it was.
"""

from __future__ import annotations

import hashlib
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.data.recording import Recording
from tactbench.datasets.cyskin_text import read_cyskin_folder, read_cyskin_text, write_cyskin_text
from tactbench.errors import TactbenchError

CAP_MIB = 200
SETTINGS = settings(max_examples=120, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])


def _original() -> bytes:
    rng = np.random.default_rng(11)
    values = rng.integers(0, 20000, (6, 12)).astype(np.float32)
    values[2, 3] = np.nan
    values[4, 1] = 12.5
    rec = Recording(values, np.cumsum(rng.uniform(0.09, 0.11, 6)), 56560 + np.arange(12))
    with tempfile.TemporaryDirectory() as tmp:
        write_cyskin_text(rec, Path(tmp) / "r.txt")
        return (Path(tmp) / "r.txt").read_bytes()


ORIGINAL = _original()
LINES = ORIGINAL.decode().splitlines()

FIELDS = st.sampled_from([
    "9" * 23, "-" + "9" * 23, "9" * 5000, "1e999", "-1e999", "1e300", "-1", "-0", "nan", "inf",
    "-inf", "0x10", "1_000", "abc", "", "  ", "\t", "1.5", "+7", "٣", "\x00", "1e-400", "-5e38",
])


@st.composite
def mutated(draw) -> bytes:
    lines = list(LINES)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["drop", "duplicate", "field", "header", "append", "swap"]))
        if not lines:
            break
        k = 0 if op == "header" else draw(st.integers(0, len(lines) - 1))
        if op == "drop":
            del lines[k]
        elif op == "duplicate":
            lines.insert(k, lines[k])
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[k], lines[j] = lines[j], lines[k]
        elif op == "append":
            lines[k] += " " + draw(FIELDS)
        else:
            toks = lines[k].split(" ")
            toks[draw(st.integers(0, len(toks) - 1))] = draw(FIELDS)
            lines[k] = " ".join(toks)
    data = bytearray(("\n".join(lines) + "\n").encode("utf-8"))
    for _ in range(draw(st.integers(0, 3))):  # flipped bytes
        if data:
            data[draw(st.integers(0, len(data) - 1))] ^= 1 << draw(st.integers(0, 7))
    if draw(st.booleans()):  # cut
        data = data[:draw(st.integers(0, len(data)))]
    return bytes(data)


def _read_checked(path: Path, memory_cap, read=read_cyskin_text):
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    try:
        with memory_cap(CAP_MIB):
            result = read(path)
    except TactbenchError as exc:
        text = str(exc)
        assert text and "\n" not in text, text
        result = None
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest  # the input is unchanged
    return result


def _check_recording(rec: Recording) -> None:
    assert rec.values.dtype == np.float32 and rec.values.ndim == 2
    assert not np.isinf(rec.values).any()
    assert rec.timestamps.shape == (rec.n_frames,) and np.isfinite(rec.timestamps).all()
    assert (np.diff(rec.timestamps) >= 0).all()
    assert rec.taxel_ids.shape == (rec.n_taxels,) and (rec.taxel_ids >= 0).all()


@SETTINGS
@given(data=mutated())
def test_mutated_files_read_or_fail_with_one_line(tmp_path, memory_cap, data):
    path = tmp_path / "m.txt"
    path.write_bytes(data)
    rec = _read_checked(path, memory_cap)
    if rec is not None:
        _check_recording(rec)


@SETTINGS
@given(data=st.binary(max_size=300))
def test_random_bytes(tmp_path, memory_cap, data):
    path = tmp_path / "b.txt"
    path.write_bytes(data)
    rec = _read_checked(path, memory_cap)
    if rec is not None:
        _check_recording(rec)


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=mutated())
def test_a_mutated_file_in_a_folder(tmp_path, memory_cap, data):
    root = tmp_path / "ds"
    for cls in ("0_finger", "1_finger"):
        (root / cls).mkdir(parents=True, exist_ok=True)
        (root / cls / "a.txt").write_bytes(ORIGINAL)
    (root / "1_finger" / "b.txt").write_bytes(data)
    ds = _read_checked(root / "1_finger" / "b.txt", memory_cap,
                       read=lambda _: read_cyskin_folder(root))
    for name in ("0_finger", "1_finger"):
        assert (root / name / "a.txt").read_bytes() == ORIGINAL
    if ds is not None:
        assert len(ds) == 3 and ds.classes == ("0_finger", "1_finger")


@pytest.mark.parametrize("n_ids, row, n_rows, message", [
    (100_000, "0 0 5", 1, "line 2: truncated"),  # many ids, a short row
    (30_000, "0 0 5", 30_000, "line 2: truncated"),  # the case, smaller
    (3, " ".join(["7"] * 200_000), 2, "line 2: too many values"),  # one huge row
])
def test_hostile_shapes_stay_under_the_cap(tmp_path, memory_cap, n_ids, row, n_rows, message):
    """Refused from their row lengths, never allocated (75 GiB for 100 000 × 100 000)."""
    path = tmp_path / "h.txt"
    path.write_text(" ".join(map(str, range(n_ids))) + "\n" + (row + "\n") * n_rows)
    with memory_cap(CAP_MIB), pytest.raises(TactbenchError, match=message):
        read_cyskin_text(path)
