"""Recording a bus to a log: python-can's virtual bus in, a .blf/.asc out, read back."""

from __future__ import annotations

import threading
import time
import uuid

import can
import numpy as np
import pytest

from tactbench.can.bus import open_bus
from tactbench.can.codec import TaxelMap
from tactbench.can.logs import read_log
from tactbench.can.record import record
from tactbench.can.simulate import SimSample, play, traffic

IDS = np.array([0, 1, 2, 3, 16, 17])


def sample(n: int = 5) -> SimSample:
    values = np.arange(n * IDS.size, dtype=np.float32).reshape(n, IDS.size) * 97
    return SimSample(values, 0.02 * np.arange(n))


def send_later(channel: str, samples: list[SimSample], delay: float = 0.2) -> threading.Thread:
    """Play ``samples`` (no taxel map, no markers) on ``channel`` after ``delay`` s."""
    def send():
        time.sleep(delay)  # the recorder is receiving by then
        with can.Bus(interface="virtual", channel=channel) as bus:
            play(bus, traffic(samples, TaxelMap(IDS), announce=False), speed=0)

    thread = threading.Thread(target=send, daemon=True)
    thread.start()
    return thread


@pytest.fixture
def channel():
    return f"rec-{uuid.uuid4().hex[:8]}"  # a private virtual bus per test


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_record_writes_the_bus_between_markers_with_the_taxel_map(tmp_path, channel, suffix):
    out = tmp_path / f"rec{suffix}"
    calls = []
    with open_bus("virtual", channel) as bus:
        sender = send_later(channel, [sample()])
        result = record(bus, out, idle_timeout=0.5, label={"label": "Twist", "user": "u7"},
                        taxel_ids=IDS, progress=lambda done, total, **info: calls.append(done))
        sender.join()
    assert result.stopped == "idle" and result.label == "Twist"
    assert result.messages == 5 * 2  # module 0 (4 slots) and module 1: one message each
    assert result.meta_messages > 2 and 0 < result.bus_load_measured < 1
    assert calls and calls[-1] == result.messages  # the last report is the final count
    log = read_log(out)
    assert log.taxel_source == "announced"
    np.testing.assert_array_equal(log.taxel_ids, IDS)
    [seg] = log.labelled
    assert seg.info == {"label": "Twist", "user": "u7"}
    np.testing.assert_array_equal(seg.values, sample().values)


def test_record_stops_at_max_messages_and_at_duration(tmp_path, channel):
    with open_bus("virtual", channel) as bus:
        sender = send_later(channel, [sample(20)], delay=0.1)
        result = record(bus, tmp_path / "some.blf", max_messages=7, duration=5)
        sender.join()
    assert result.stopped == "max_messages" and result.messages == 7
    with open_bus("virtual", f"{channel}-quiet") as bus:
        start = time.monotonic()
        result = record(bus, tmp_path / "empty.asc", duration=0.2)
    assert result.stopped == "duration" and result.messages == 0
    assert 0.2 <= time.monotonic() - start < 2
    assert result.to_dict()["out"] == str(tmp_path / "empty.asc")


def test_a_bus_that_cannot_open_is_one_clear_error():
    with pytest.raises(ValueError, match="cannot open no-such-interface channel 'x'"):
        open_bus("no-such-interface", "x")
