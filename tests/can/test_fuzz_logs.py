"""Fuzz: CAN logs and live CAN frames, mutated from real traffic the tests make.

- Logs (``.asc`` and ``.blf``, written by tactbench's own writer from a small simulated
  dataset) with bytes flipped, cut, duplicated or deleted, and ``.asc`` lines dropped,
  duplicated or with a field replaced: every reader (``read_log``, the dataset it
  becomes, the replay sensor) gives a result or one :class:`TactbenchError` line, under
  a memory cap, and the file is unchanged.
- Live frames (random and mutated python-can messages, hostile meta frames, objects
  that only look like messages) fed to the assembler, to the meta assembler and to the
  ``cyskin-can`` sensor on a virtual bus: nothing escapes at all; broken traffic is
  counted.
"""

from __future__ import annotations

import hashlib
import math
import tempfile
import threading
import uuid
from pathlib import Path

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.can.assembler import SweepAssembler
from tactbench.can.codec import TaxelMap
from tactbench.can.logs import read_log, segment_messages, write_log
from tactbench.can.meta import (
    LABEL_END,
    LABEL_START,
    TAXEL_MAP,
    MetaAssembler,
    is_meta,
    meta_id,
    taxel_map_messages,
)
from tactbench.can.simulate import SimSample, schedule_messages, traffic
from tactbench.errors import BudgetError, TactbenchError

CAP_MIB = 200
IDS = np.array([m * 16 + s for m in (2, 3) for s in range(11)])  # 22 taxels, 6 messages
FUZZ = dict(deadline=None, derandomize=True,
            suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def sim_samples() -> list[SimSample]:
    rng = np.random.default_rng(8)
    return [SimSample(rng.integers(0, 65536, (n, IDS.size)).astype(np.float32),
                      0.1 * np.arange(n), {"label": label, "user": "u1", "repetition": k})
            for k, (label, n) in enumerate([("Grasp", 4), ("Pull", 3), ("Grasp", 3)])]


def real_messages() -> list:
    return list(schedule_messages(traffic(sim_samples(), TaxelMap(IDS)), t0=1.7e9))


def _written(suffix: str) -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"base{suffix}"
        write_log(path, real_messages())
        return path.read_bytes()


BASE = {suffix: _written(suffix) for suffix in (".asc", ".blf")}


def test_the_base_logs_read_back():
    with tempfile.TemporaryDirectory() as tmp:
        for suffix, data in BASE.items():
            path = Path(tmp) / f"b{suffix}"
            path.write_bytes(data)
            assert [s.label for s in read_log(path).labelled] == ["Grasp", "Pull", "Grasp"]


# ------------------------------------------------------------------------------ logs

@st.composite
def mutated_bytes(draw, suffix: str) -> bytes:
    data = bytearray(BASE[suffix])
    for _ in range(draw(st.integers(1, 4))):
        if not data:
            break
        op = draw(st.sampled_from(["flip", "byte", "cut", "duplicate", "delete"]))
        i = draw(st.integers(0, len(data) - 1))
        if op == "flip":
            data[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "byte":
            data[i] = draw(st.integers(0, 255))
        elif op == "cut":
            del data[i:]
        else:
            j = min(len(data), i + draw(st.integers(1, 300)))
            if op == "duplicate":
                data[j:j] = data[i:j]
            else:
                del data[i:j]
    return bytes(data)


ASC_FIELDS = st.sampled_from(["9" * 30, "-1", "1e999", "nan", "x", "", "Rx", "Tx", "d", "8",
                              "64", "FF", "1D" + "F" * 6 + "x", "-3.5", "0.000000", "Start"])


@st.composite
def mutated_asc(draw) -> bytes:
    lines = BASE[".asc"].decode().splitlines()
    for _ in range(draw(st.integers(1, 5))):
        k = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["drop", "duplicate", "field", "swap"]))
        if op == "drop":
            del lines[k]
        elif op == "duplicate":
            lines.insert(k, lines[k])
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[k], lines[j] = lines[j], lines[k]
        else:
            toks = lines[k].split(" ")
            toks[draw(st.integers(0, len(toks) - 1))] = draw(ASC_FIELDS)
            lines[k] = " ".join(toks)
    return ("\n".join(lines) + "\n").encode()


def read_everything(path: Path, memory_cap) -> None:
    """Every reader of a log: nothing but one TactbenchError line, the file unchanged."""
    from tactbench.sensors.replay import Replay

    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    for read in (lambda: read_log(path).summary(), lambda: read_log(path).to_dataset(),
                 lambda: list(Replay(str(path)).frames())):
        try:
            with memory_cap(CAP_MIB):
                read()
        except TactbenchError as exc:
            text = str(exc)
            assert str(path) in text and "\n" not in text, text
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest


@settings(max_examples=30, **FUZZ)
@given(data=mutated_bytes(".blf"))
def test_mutated_blf(tmp_path, memory_cap, data):
    path = tmp_path / "m.blf"
    path.write_bytes(data)
    read_everything(path, memory_cap)


@settings(max_examples=30, **FUZZ)
@given(data=mutated_bytes(".asc"))
def test_mutated_asc_bytes(tmp_path, memory_cap, data):
    path = tmp_path / "m.asc"
    path.write_bytes(data)
    read_everything(path, memory_cap)


@settings(max_examples=30, **FUZZ)
@given(data=mutated_asc())
def test_mutated_asc_lines(tmp_path, memory_cap, data):
    path = tmp_path / "m.asc"
    path.write_bytes(data)
    read_everything(path, memory_cap)


def test_a_few_messages_cannot_make_a_log_reader_allocate_without_bound(tmp_path, memory_cap,
                                                                        monkeypatch):
    """A 16 384-taxel announcement, then one message per sweep: 300 messages (30 kB of
    .asc) hold 300 sweeps × 16 384 taxels (20 MB, twice that while stacked; 65 536
    taxels and 3 MB of log would be 8 GB). Refused under the budget, below the cap."""
    ids = np.arange(1024 * 16)
    msgs = taxel_map_messages(ids, 0)
    msgs += [can.Message(arbitration_id=(0x1C << 24) | (5 << 12) | (k % 256), data=bytes(8),
                         is_extended_id=True, timestamp=0.01 * k) for k in range(300)]
    path = tmp_path / "wide.asc"
    write_log(path, msgs)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "4")
    with memory_cap(CAP_MIB), pytest.raises(BudgetError, match=r"wide.asc: assembling more "
                                                               r"than \d+ sweeps of 16384"):
        read_log(path)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "0.1")  # 100 kB: not even the messages
    with pytest.raises(BudgetError, match=r"wide.asc: more than \d+ messages"):
        read_log(path)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "100")
    assert read_log(path).summary()["sweeps"] == 300


# ---------------------------------------------------------------------- live frames

def _message(arbitration_id: int, extended: bool, data: bytes, flags: int, t: float):
    return can.Message(arbitration_id=arbitration_id, is_extended_id=extended, data=data,
                       is_fd=bool(flags & 1), is_error_frame=bool(flags & 2),
                       is_remote_frame=bool(flags & 4), timestamp=t, check=False)


RANDOM_MESSAGES = st.builds(
    _message,
    st.one_of(st.integers(0, (1 << 29) - 1),
              st.integers(0, 0xFFFFF).map(lambda low: (0x1C << 24) | low),  # CySkin data ids
              st.integers(0, 0xFFFFF).map(lambda low: (0x1D << 24) | low)),  # meta ids
    st.booleans(), st.binary(max_size=64), st.integers(0, 7),
    st.floats(allow_nan=True, allow_infinity=True))

NOT_MESSAGES = st.sampled_from([None, 5, "frame", b"\x00" * 8, object(), [1, 2], {"id": 1}])

HOSTILE_META = st.sampled_from([
    b"[" * 16_000, b'{"label":"G","repetition":1e999}', b'{"label":"G","repetition":[1]}',
    b'{"label":' + b"[" * 3000, b"\xff\xfe", b"{}", b"", b'{"label":"G"}' * 200, bytes(13),
])


@st.composite
def meta_frames(draw) -> list:
    """A meta message of any kind with a hostile payload, parts possibly lost or swapped."""
    payload = draw(HOSTILE_META)
    kind = draw(st.sampled_from([LABEL_START, LABEL_END, TAXEL_MAP, 0, 7, 15]))
    seq = draw(st.integers(0, 255))
    parts = [payload[i:i + 8] for i in range(0, len(payload), 8)] or [b""]
    msgs = [can.Message(arbitration_id=meta_id(kind, i % 2048, i == len(parts) - 1, seq),
                        is_extended_id=True, data=part, timestamp=0.0)
            for i, part in enumerate(parts)]
    if len(msgs) > 1 and draw(st.booleans()):
        del msgs[draw(st.integers(0, len(msgs) - 1))]
    return msgs


@st.composite
def mutated_stream(draw) -> list:
    """Real traffic, damaged: messages dropped, duplicated, moved or bit-flipped, with
    random messages, hostile meta frames and non-messages mixed in."""
    msgs = real_messages()
    for _ in range(draw(st.integers(0, 12))):
        k = draw(st.integers(0, len(msgs) - 1))
        op = draw(st.sampled_from(["drop", "duplicate", "move", "flip-id", "flip-data",
                                   "random", "meta", "object"]))
        if op.startswith("flip") and not isinstance(msgs[k], can.Message):
            continue
        if op == "drop":
            del msgs[k]
        elif op == "duplicate":
            msgs.insert(k, msgs[k])
        elif op == "move":
            msgs.insert(draw(st.integers(0, len(msgs))), msgs.pop(k))
        elif op == "flip-id":
            m = msgs[k]
            msgs[k] = _message(m.arbitration_id ^ (1 << draw(st.integers(0, 28))),
                               m.is_extended_id, bytes(m.data), 0, m.timestamp)
        elif op == "flip-data" and len(msgs[k].data):
            data = bytearray(msgs[k].data)
            data[draw(st.integers(0, len(data) - 1))] ^= 1 << draw(st.integers(0, 7))
            msgs[k] = _message(msgs[k].arbitration_id, True, bytes(data), 0, msgs[k].timestamp)
        elif op == "random":
            msgs[k:k] = draw(st.lists(RANDOM_MESSAGES, max_size=5))
        elif op == "meta":
            msgs[k:k] = draw(meta_frames())
        elif op == "object":
            msgs.insert(k, draw(NOT_MESSAGES))
    return msgs


def _check_stats(stats) -> None:
    assert stats.messages == (stats.accepted + stats.duplicates + stats.late
                              + sum(stats.rejected.values()))


@settings(max_examples=150, **FUZZ)
@given(msgs=mutated_stream())
def test_damaged_live_traffic_never_raises(msgs, memory_cap):
    taxels = TaxelMap(IDS)
    with memory_cap(CAP_MIB):
        segments, stats, broken = segment_messages(msgs, taxels)  # meta + assembler
        asm = SweepAssembler(taxels, missing="nan")
        sweeps = list(asm.feed_all(msgs))
    _check_stats(stats)
    _check_stats(asm.stats)
    assert all(s.values.shape == (IDS.size,) and s.values.dtype == np.float32 for s in sweeps)
    assert all(math.isfinite(s.timestamp) for s in sweeps)
    assert broken >= 0 and all(seg.values.shape[1:] == (IDS.size,) for seg in segments)


@settings(max_examples=150, **FUZZ)
@given(msgs=st.lists(st.one_of(RANDOM_MESSAGES, NOT_MESSAGES), max_size=60),
       frames=st.lists(meta_frames(), max_size=4))
def test_random_frames_never_raise(msgs, frames):
    meta = MetaAssembler()
    asm = SweepAssembler(TaxelMap(IDS), window=3)
    for msg in msgs + [m for f in frames for m in f]:
        if is_meta(msg):
            meta.feed(msg)
        asm.feed(msg)
        meta.feed(msg)  # even a message that is not meta: counted as broken, or ignored
    asm.flush()
    _check_stats(asm.stats)


@settings(max_examples=6, **FUZZ)
@given(msgs=mutated_stream())
def test_the_cyskin_can_sensor_reads_damaged_traffic(msgs):
    """The same damaged streams on a virtual bus: the sensor yields sweeps, never raises."""
    from tactbench.sensors.cyskin_can import CySkinCAN

    channel = f"fuzz-{uuid.uuid4().hex[:8]}"
    nested = [can.Message(arbitration_id=meta_id(LABEL_START, i, i == 1999, 99), data=b"[" * 8,
                          is_extended_id=True) for i in range(2000)]  # 16 000 '['
    sendable = nested + [m for m in msgs if isinstance(m, can.Message)]
    with CySkinCAN(channel=channel, taxel_ids="32-42;48-58", idle_timeout=0.3,
                   flush_after=0.05) as sensor:
        def send():
            with can.Bus(interface="virtual", channel=channel) as bus:
                for m in sendable:
                    bus.send(m)

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        sweeps = list(sensor.frames())
        sender.join()
        _check_stats(sensor.stats)
        assert sensor._meta.broken >= 1
    assert sensor.stats.messages <= len(sendable)
    assert all(s.values.shape == (IDS.size,) for s in sweeps)
