"""The CySkin CAN frame format: ids, payloads, exact 16-bit round trip, configuration."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactbench.can.codec import (
    FrameFormat,
    TaxelMap,
    decode_message,
    dequantize,
    encode_payloads,
    encode_sweep,
    quantize,
)

FORMATS = [FrameFormat(), FrameFormat(ids="standard"), FrameFormat(fd=True),
           FrameFormat(ids="standard", fd=True, byteorder="little", base_id=0x200)]


def forearm_ids(n: int = 1558) -> np.ndarray:
    """CySkin-like ids: modules of 11 taxels in slots 0–10."""
    return np.array([m * 16 + s for m in range(n // 11 + 1) for s in range(11)])[:n]


def test_default_format_packs_four_values_per_classic_frame():
    taxels = TaxelMap([0, 1, 2, 3, 4, 5, 16 * 3 + 9])
    assert [(c.module, c.slot_offset) for c in taxels.chunks] == [(0, 0), (0, 4), (3, 8)]
    counts = np.array([1, 2, 3, 4, 0xABCD, 6, 7], dtype=np.uint16)
    payloads = encode_payloads(counts, taxels, counter=300)  # counter wraps at 256
    arb, body = payloads[0]
    assert arb == (0x1C << 24) | (0 << 12) | (0 << 8) | 44
    assert body == bytes([0, 1, 0, 2, 0, 3, 0, 4])
    assert payloads[1] == ((0x1C << 24) | (4 << 8) | 44, bytes([0xAB, 0xCD, 0, 6]))
    # Slot 9 of module 3: slot 8 is absent (sent as 0), trailing slots are not sent.
    assert payloads[2] == ((0x1C << 24) | (3 << 12) | (8 << 8) | 44, bytes([0, 0, 0, 7]))


def test_standard_ids_carry_counter_and_slot_offset_in_the_payload():
    fmt = FrameFormat(ids="standard", base_id=0x300, byteorder="little")
    taxels = TaxelMap([16 * 2 + 3, 16 * 2 + 4], fmt)
    [(arb, body)] = encode_payloads(np.array([0x0102, 0x0304], np.uint16), taxels, 7)
    assert arb == 0x302
    assert body == bytes([7, 3, 0x02, 0x01, 0x04, 0x03])


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f"{f.ids}-fd{int(f.fd)}-{f.byteorder}")
def test_every_16_bit_value_round_trips_exactly(fmt):
    ids = forearm_ids(300)
    taxels = TaxelMap(ids, fmt)
    rng = np.random.default_rng(1)
    values = rng.integers(0, 65536, ids.size).astype(np.float32)
    values[:2] = [0, 65535]
    got = np.full(ids.size, -1.0, np.float32)
    for msg in encode_sweep(values, taxels, counter=9):
        assert msg.dlc <= (64 if fmt.fd else 8)
        d = decode_message(msg, taxels)
        assert not isinstance(d, str), d
        assert d.counter == 9
        got[taxels.chunk_taxels(d.chunk)] = dequantize(d.values)
    np.testing.assert_array_equal(got, values)


def test_messages_per_sweep_for_a_forearm():
    ids = forearm_ids()
    assert TaxelMap(ids).n_messages == 425  # 3 per full module of 11 taxels
    assert TaxelMap(ids, FrameFormat(fd=True)).n_messages == 142  # one per module
    assert TaxelMap(ids, FrameFormat(ids="standard")).n_messages == 567  # 3 values each


def test_quantize_rounds_clips_and_zeroes_nan():
    q = quantize([0.4, 0.6, -5, 70000, np.nan, 123])
    assert q.dtype == np.uint16
    assert q.tolist() == [0, 1, 0, 65535, 0, 123]


def test_module_map_renumbers_bus_modules():
    fmt = FrameFormat.from_spec("ids=standard,base_id=0x100")
    fmt = FrameFormat.from_options({**fmt.to_dict(), "module_map": {"5": 40}})
    taxels = TaxelMap([40 * 16 + 1], fmt)
    [msg] = encode_sweep([77], taxels, 0)
    assert msg.arbitration_id == 0x105 and not msg.is_extended_id
    d = decode_message(msg, taxels)
    assert d.values.tolist() == [77]


def test_format_from_spec_and_json(tmp_path):
    fmt = FrameFormat.from_spec("prefix=0x1a,fd=true,byteorder=little")
    assert (fmt.prefix, fmt.fd, fmt.byteorder) == (0x1A, True, "little")
    path = tmp_path / "bus.json"
    path.write_text(json.dumps(fmt.to_dict()))
    assert FrameFormat.from_json(path) == fmt
    assert FrameFormat.from_spec("") == FrameFormat()


@pytest.mark.parametrize("spec, words", [
    ("ids=weird", "ids must be"), ("prefix=40", "prefix must be 0..31"),
    ("fd=maybe", "true or false"), ("colour=red", "unknown frame format option"),
    ("prefix", "expected key=value"), ("base_id=zz", "must be an integer"),
])
def test_bad_format_options_say_what_is_wrong(spec, words):
    with pytest.raises(ValueError, match=words):
        FrameFormat.from_spec(spec)


def test_bad_json_names_the_file(tmp_path):
    path = tmp_path / "bus.json"
    path.write_text("{nope")
    with pytest.raises(ValueError, match="bus.json"):
        FrameFormat.from_json(path)


@pytest.mark.parametrize("ids, words", [
    ([], "non-empty"), ([1, 1], "unique"), ([-3], "≥ 0"), ([1.5], "integers"),
])
def test_bad_taxel_ids_are_refused(ids, words):
    with pytest.raises(ValueError, match=words):
        TaxelMap(np.array(ids))


def test_module_too_large_for_standard_ids():
    with pytest.raises(ValueError, match="does not fit"):
        TaxelMap([0x700 * 16], FrameFormat(ids="standard", base_id=0x100))


@settings(max_examples=60, deadline=None)
@given(ids=st.sets(st.integers(0, 0x6FF * 16 + 15), min_size=1, max_size=40),
       seed=st.integers(0, 2**32 - 1), counter=st.integers(0, 10_000),
       fmt=st.sampled_from(FORMATS[:3]))
def test_round_trip_for_any_layout(ids, seed, counter, fmt):
    ids = np.array(sorted(ids))
    taxels = TaxelMap(ids, fmt)
    values = np.random.default_rng(seed).integers(0, 65536, ids.size).astype(np.uint16)
    got = np.zeros(ids.size, np.uint16)
    seen = 0
    for msg in encode_sweep(values, taxels, counter):
        d = decode_message(msg, taxels)
        assert d.counter == counter % 256
        got[taxels.chunk_taxels(d.chunk)] = d.values
        seen += len(d.values)
    assert seen == ids.size
    np.testing.assert_array_equal(got, values)
