"""Bus load per sweep: frame bit counts and the share of the bus a layout takes."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.can.busload import bus_load, cyskin_like_ids, frame_bits
from tactbench.can.codec import FrameFormat, TaxelMap


def forearm_ids(n: int = 1558) -> np.ndarray:
    return np.array([m * 16 + s for m in range(n // 11 + 1) for s in range(11)])[:n]


def test_cyskin_like_ids_fill_slots_0_to_10_of_each_module():
    np.testing.assert_array_equal(cyskin_like_ids(1558), forearm_ids())
    assert cyskin_like_ids(13).tolist() == [*range(11), 16, 17]
    with pytest.raises(ValueError, match="number of taxels"):
        cyskin_like_ids(0)


def test_classic_frame_lengths_follow_iso_11898():
    # 8-byte frames: 111 bits (11-bit id) and 131 bits (29-bit id), interframe space included.
    assert frame_bits(8, extended=False) == 111
    assert frame_bits(8, extended=True) == 131
    assert frame_bits(0, extended=False) == 47
    # Worst-case stuffing: one bit per four after the first, over SOF..CRC.
    assert frame_bits(8, extended=False, worst_case=True) == 111 + (34 + 64 - 1) // 4
    with pytest.raises(ValueError, match="at most 8 bytes"):
        frame_bits(9, extended=False)


def test_fd_data_phase_runs_at_the_data_bitrate():
    slow = frame_bits(32, extended=True, fd=True, bitrate=1e6, data_bitrate=1e6)
    fast = frame_bits(32, extended=True, fd=True, bitrate=1e6, data_bitrate=5e6)
    assert fast < slow / 2
    assert frame_bits(32, extended=True, fd=True) > frame_bits(8, extended=True)


def test_forearm_at_10_hz_is_about_half_a_classic_megabit_bus():
    load = bus_load(TaxelMap(forearm_ids()), bitrate=1_000_000, rate_hz=10)
    assert load.messages_per_sweep == 425
    assert load.payload_bytes_per_sweep == 1558 * 2  # absent slot 11 is never sent
    assert 0.45 < load.load < 0.6 and load.load < load.load_worst < 0.7
    assert load.fits
    assert load.messages_per_second == 4250
    assert "425 messages/sweep" in load.describe() and "53 %" in load.describe()


def test_load_scales_with_rate_and_bitrate():
    taxels = TaxelMap(forearm_ids())
    base = bus_load(taxels)
    assert bus_load(taxels, rate_hz=20).load == pytest.approx(2 * base.load)
    assert bus_load(taxels, bitrate=500_000).load == pytest.approx(2 * base.load)
    too_much = bus_load(taxels, bitrate=500_000, rate_hz=20)
    assert not too_much.fits and "NOT fit" in too_much.describe()


def test_can_fd_needs_fewer_messages_and_less_of_the_bus():
    fd = bus_load(TaxelMap(forearm_ids(), FrameFormat(fd=True)), data_bitrate=5_000_000)
    assert fd.messages_per_sweep == 142
    assert fd.load < 0.2
    assert fd.to_dict()["data_bitrate"] == 5e6


def test_bad_rates_are_refused():
    with pytest.raises(ValueError, match="> 0"):
        bus_load(TaxelMap([1]), rate_hz=0)
