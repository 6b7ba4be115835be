"""Sweep assembly: complete sweeps at once, loss/duplicates/reordering counted, never a crash."""

from __future__ import annotations

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.can.assembler import SweepAssembler
from tactbench.can.codec import FrameFormat, TaxelMap, encode_sweep

IDS = np.array([m * 16 + s for m in (0, 1, 7) for s in range(11)])  # 33 taxels, 9 messages
TAXELS = TaxelMap(IDS)


def sweeps(n: int, seed: int = 0, start: int = 0) -> tuple[np.ndarray, list[list]]:
    """``n`` random sweeps and their messages (timestamps 0.1 s apart)."""
    values = np.random.default_rng(seed).integers(0, 65536, (n, IDS.size)).astype(np.float32)
    msgs = [encode_sweep(values[k], TAXELS, start + k, timestamp=0.1 * k) for k in range(n)]
    return values, msgs


def test_each_sweep_is_emitted_by_its_last_message():
    values, msgs = sweeps(3)
    asm = SweepAssembler(TAXELS)
    for k, batch in enumerate(msgs):
        outs = [asm.feed(m) for m in batch]
        assert all(o == [] for o in outs[:-1])
        [sweep] = outs[-1]
        assert sweep.complete and sweep.sequence == k and sweep.timestamp == pytest.approx(0.1 * k)
        np.testing.assert_array_equal(sweep.values, values[k])
    assert asm.stats.complete_sweeps == 3 and asm.stats.accepted == 27
    assert asm.flush() == []


def test_counter_wraps_around_without_a_gap():
    values, msgs = sweeps(4, start=254)
    asm = SweepAssembler(TAXELS)
    out = list(asm.feed_all(m for batch in msgs for m in batch))
    assert [s.sequence for s in out] == [254, 255, 256, 257]
    assert [s.counter for s in out] == [254, 255, 0, 1]
    assert asm.stats.lost_sweeps == 0


@pytest.mark.parametrize("rule, expected", [("hold", "previous"), ("nan", np.nan), ("zero", 0.0)])
def test_lost_message_follows_the_missing_rule(rule, expected):
    values, msgs = sweeps(3)
    lost = msgs[1].pop(4)  # one message of sweep 1 never arrives
    cols = TAXELS.chunk_taxels(TAXELS.chunk_index[((lost.arbitration_id >> 12) & 0xFFF,
                                                    (lost.arbitration_id >> 8) & 0xF)])
    asm = SweepAssembler(TAXELS, missing=rule)
    out = list(asm.feed_all(m for batch in msgs for m in batch))
    assert [s.sequence for s in out] == [0, 1, 2]
    s1 = out[1]
    assert not s1.complete and s1.missing == cols.size
    others = np.setdiff1d(np.arange(IDS.size), cols)
    np.testing.assert_array_equal(s1.values[others], values[1][others])
    want = values[0][cols] if expected == "previous" else np.full(cols.size, expected)
    np.testing.assert_array_equal(s1.values[cols], want)
    assert asm.stats.lost_messages == 1 and asm.stats.incomplete_sweeps == 1


def test_hold_is_nan_before_a_taxel_was_ever_seen():
    _, msgs = sweeps(2)
    msgs[0].pop(0)
    out = list(SweepAssembler(TAXELS).feed_all(m for b in msgs for m in b))
    assert np.isnan(out[0].values).sum() == out[0].missing > 0
    assert out[1].complete


def test_duplicates_and_reordering_are_counted_and_harmless():
    values, msgs = sweeps(2)
    stream = msgs[0][:5] + msgs[1][:2] + msgs[0][5:] + [msgs[0][2]] + msgs[1][2:] + [msgs[1][0]]
    asm = SweepAssembler(TAXELS)
    out = list(asm.feed_all(stream))
    assert [s.complete for s in out] == [True, True]
    for s, v in zip(out, values):
        np.testing.assert_array_equal(s.values, v)
    assert asm.stats.out_of_order == 4  # the rest of sweep 0 after sweep 1 began
    assert asm.stats.duplicates == 2
    assert asm.stats.late == 0


def test_a_lost_sweep_is_counted():
    _, msgs = sweeps(4)
    del msgs[2]
    asm = SweepAssembler(TAXELS)
    out = list(asm.feed_all(m for b in msgs for m in b))
    assert [s.sequence for s in out] == [0, 1, 3]
    assert asm.stats.lost_sweeps == 1


def test_late_message_for_an_emitted_sweep_is_dropped():
    values, msgs = sweeps(3)
    late = msgs[0].pop()
    asm = SweepAssembler(TAXELS, window=1)
    out = list(asm.feed_all([m for b in msgs for m in b] + [late]))
    assert [s.sequence for s in out] == [0, 1, 2]
    assert asm.stats.late == 1


def test_a_counter_restart_is_followed():
    values, msgs = sweeps(6)
    restarted = [encode_sweep(values[k], TAXELS, k - 3, timestamp=0.1 * k) for k in range(3, 6)]
    asm = SweepAssembler(TAXELS)
    out = list(asm.feed_all([m for b in msgs[:3] + restarted for m in b]))
    # Sweeps 0-2; the restarted counter's first sweep is noticed only at its last
    # message, so it comes out incomplete; then the next sweeps are whole again.
    assert [s.sequence for s in out] == [0, 1, 2, 3, 4, 5]
    assert not out[3].complete
    np.testing.assert_array_equal(out[4].values, values[4])
    np.testing.assert_array_equal(out[5].values, values[5])
    assert asm.stats.resyncs == 1
    assert asm.stats.late + asm.stats.duplicates == TAXELS.n_messages - 1


def test_malformed_traffic_is_counted_by_reason():
    good = encode_sweep(np.ones(IDS.size), TAXELS, 0)
    junk = [
        can.Message(is_error_frame=True),
        can.Message(arbitration_id=good[0].arbitration_id, is_remote_frame=True),
        can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x01"),
        can.Message(arbitration_id=(0x1C << 24) | (9 << 12), data=bytes(8)),  # module 9
        can.Message(arbitration_id=(0x1C << 24) | (1 << 12) | (0xC << 8), data=bytes(8)),
        can.Message(arbitration_id=good[0].arbitration_id, data=b"\x00\x01\x02"),
        can.Message(arbitration_id=good[0].arbitration_id, data=b""),
        object(),
    ]
    asm = SweepAssembler(TAXELS)
    out = list(asm.feed_all(junk + good))
    assert len(out) == 1 and out[0].complete
    assert dict(asm.stats.rejected) == {"error_frame": 1, "remote_frame": 1, "foreign_id": 1,
                                        "unknown_module": 1, "unknown_slots": 1,
                                        "bad_length": 3}


def test_options_are_checked():
    with pytest.raises(ValueError, match="missing must be"):
        SweepAssembler(TAXELS, missing="guess")
    with pytest.raises(ValueError, match="window"):
        SweepAssembler(TAXELS, window=0)


# ------------------------------------------------------------------ fuzzing

garbage = st.builds(
    can.Message,
    arbitration_id=st.one_of(st.integers(0, 0x7FF),
                             st.integers(0, 0x1FFFFFFF),
                             st.integers(0, 0xFFFFF).map(lambda x: (0x1C << 24) | x)),
    is_extended_id=st.booleans(),
    is_remote_frame=st.booleans(),
    is_error_frame=st.booleans(),
    is_fd=st.booleans(),
    data=st.binary(max_size=64),
    timestamp=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.just(0.0)),
)


def _check_stats(asm: SweepAssembler) -> None:
    s = asm.stats
    assert s.messages == s.accepted + s.duplicates + s.late + sum(s.rejected.values())
    assert s.sweeps == s.complete_sweeps + s.incomplete_sweeps


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(garbage, max_size=60), st.sampled_from(["hold", "nan", "zero"]))
def test_fuzz_garbage_never_crashes(messages, rule):
    asm = SweepAssembler(TAXELS, missing=rule)
    out = list(asm.feed_all(messages))
    for s in out:
        assert s.values.shape == IDS.shape and s.values.dtype == np.float32
    assert [s.sequence for s in out] == sorted({s.sequence for s in out})
    _check_stats(asm)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(1, 6), seed=st.integers(0, 2**16), data=st.data())
def test_fuzz_damaged_stream(n, seed, data):
    """Drop, duplicate, swap neighbours and inject garbage: whatever arrives is right."""
    values, msgs = sweeps(n, seed=seed, start=seed % 256)
    stream = []
    dropped = set()
    for k, batch in enumerate(msgs):
        for j, m in enumerate(batch):
            if data.draw(st.integers(0, 9), label="drop?") == 0:
                dropped.add(k)
                continue
            stream.append((k, m))
            if data.draw(st.integers(0, 9), label="dup?") == 0:
                stream.append((k, m))
    # Local reordering: swap some disjoint pairs of neighbours.
    i = 0
    while i < len(stream) - 1:
        if data.draw(st.integers(0, 5), label="swap?") == 0:
            stream[i], stream[i + 1] = stream[i + 1], stream[i]
            i += 1
        i += 1
    junk = data.draw(st.lists(st.tuples(st.integers(0, len(stream)), garbage), max_size=10))
    messages = [m for _, m in stream]
    for pos, msg in sorted(junk, key=lambda t: -t[0]):
        if msg.is_error_frame or msg.is_remote_frame or (msg.arbitration_id >> 24) != 0x1C:
            messages.insert(pos, msg)

    asm = SweepAssembler(TAXELS, missing="nan")
    out = list(asm.feed_all(messages))
    _check_stats(asm)
    seqs = [s.sequence for s in out]
    assert seqs == sorted(set(seqs))
    start = seed % 256
    for s in out:
        k = s.sequence - start
        assert 0 <= k < n
        got = ~np.isnan(s.values)
        # Every value that arrived is exactly the one sent.
        np.testing.assert_array_equal(s.values[got], values[k][got])
        if k not in dropped:
            assert s.complete
    # A sweep none of whose messages were dropped is never lost.
    assert {k for k in range(n) if k not in dropped} <= {s.sequence - start for s in out}


def test_fd_and_standard_formats_assemble_too():
    for fmt in (FrameFormat(fd=True), FrameFormat(ids="standard", byteorder="little")):
        taxels = TaxelMap(IDS, fmt)
        values = np.arange(IDS.size, dtype=np.float32) * 1000
        out = list(SweepAssembler(taxels).feed_all(encode_sweep(values, taxels, 3)))
        assert len(out) == 1 and out[0].complete
        np.testing.assert_array_equal(out[0].values, values)
