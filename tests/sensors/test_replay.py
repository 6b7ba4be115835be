"""Sensor ``replay``: a recorded sample played back as timestamped frames."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tactbench.contracts import Sensor
from tactbench.data.recording import Dataset, Frame, Recording, Sample
from tactbench.datasets.cyskin_text import write_cyskin_text
from tactbench.plugins import load_registry
from tactbench.sensors.replay import Replay


@pytest.fixture
def saved(tmp_path):
    samples = []
    for k in range(3):
        values = np.arange(12, dtype=np.float32).reshape(4, 3) + 100 * k
        samples.append(Sample(Recording(values, np.arange(4) * 0.05, [7, 8, 9]), 0))
    Dataset("r", samples, ("a",)).save(tmp_path / "d")
    return tmp_path / "d"


def test_plays_a_dataset_sample(saved):
    with Replay(str(saved), sample=2) as sensor:
        assert isinstance(sensor, Sensor)
        assert sensor.taxel_ids.tolist() == [7, 8, 9]
        frames = list(sensor.frames())
    assert len(frames) == 4 and all(isinstance(f, Frame) for f in frames)
    ts, values = frames[1]
    assert ts == pytest.approx(0.05) and values.dtype == np.float32
    assert values.tolist() == [203, 204, 205]


def test_built_from_the_registry_with_options(saved):
    sensor = load_registry().build("sensor", "replay:sample=1", path=str(saved))
    assert [f.values[0] for f in sensor.frames()] == [100, 103, 106, 109]


def test_plays_a_cyskin_text_file(tmp_path):
    rec = Recording(np.array([[1, 2], [3, 4]]), [0.0, 0.1], [16, 17])
    write_cyskin_text(rec, tmp_path / "s.txt")
    frames = list(Replay(str(tmp_path / "s.txt")).frames())
    assert [f.values.tolist() for f in frames] == [[1, 2], [3, 4]]


def test_realtime_pacing(saved):
    start = time.monotonic()
    frames = list(Replay(str(saved), realtime=True).frames())
    elapsed = time.monotonic() - start
    assert len(frames) == 4 and elapsed >= 0.15 - 0.01  # last frame at 0.15 s
    start = time.monotonic()
    list(Replay(str(saved)).frames())
    assert time.monotonic() - start < 0.1


def test_close_stops_the_stream_and_loop_continues_time(saved):
    sensor = Replay(str(saved), loop=True)
    stream = sensor.frames()
    frames = [next(stream) for _ in range(9)]
    stamps = [f.timestamp for f in frames]
    assert np.all(np.diff(stamps) > 0)  # time keeps going across loops
    sensor.close()
    assert list(stream) == []


def test_bad_sample_index(saved):
    with pytest.raises(ValueError, match="sample 3 is out of range: .* has 3 samples"):
        Replay(str(saved), sample=3)


def test_frames_are_copies(saved):
    sensor = Replay(str(saved))
    first = next(sensor.frames())
    first.values[:] = -1
    assert next(sensor.frames()).values[0] == 0
