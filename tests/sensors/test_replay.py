"""Sensor ``replay``: a recorded sample played back as timestamped frames."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tactbench.contracts import SENSOR
from tactbench.data.dataset import Dataset
from tactbench.data.recording import Frame, Recording, Sample
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
        assert SENSOR.problems(sensor) == []
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


# ------------------------------------------------------------------ CAN logs

LOG_IDS = np.array([0, 1, 3, 4, 5, 16, 17, 18])


def log_samples():
    from tactbench.can.simulate import SimSample

    rng = np.random.default_rng(1)
    return [SimSample(rng.integers(0, 65536, (n, LOG_IDS.size)).astype(np.float32),
                      0.05 * np.arange(n), {"label": label, "user": "u1"})
            for label, n in [("Grasp", 4), ("Pull", 3)]]


@pytest.fixture
def can_log(tmp_path):
    """Two labelled samples (4 + 3 sweeps, 50 ms apart) as CySkin traffic in a .blf."""
    from tactbench.can.codec import TaxelMap
    from tactbench.can.simulate import write_samples

    path = tmp_path / "run.blf"
    write_samples(path, log_samples(), TaxelMap(LOG_IDS), gap_s=0.1, t0=100.0)
    return path


def test_the_registered_replay_sensor_plays_every_sweep_of_a_can_log(can_log):
    sensor = load_registry().build("sensor", "replay", path=str(can_log))
    with sensor:
        assert SENSOR.problems(sensor) == []
        np.testing.assert_array_equal(sensor.taxel_ids, LOG_IDS)  # announced in the log
        frames = list(sensor.frames())
    originals = log_samples()
    np.testing.assert_array_equal(np.stack([f.values for f in frames]),
                                  np.concatenate([s.values for s in originals]))
    assert all(f.values.dtype == np.float32 for f in frames)
    assert [f.label for f in frames] == ["Grasp"] * 4 + ["Pull"] * 3  # from the markers
    assert [f.missing for f in frames] == [0] * 7
    assert [f.sequence for f in frames] == list(range(7))
    stamps = np.array([f.timestamp for f in frames])
    np.testing.assert_allclose(stamps[:4] - stamps[0], 0.05 * np.arange(4), atol=2e-6)
    assert (np.diff(stamps) > 0).all()


def test_a_can_log_sample_and_given_taxel_ids(can_log):
    sensor = load_registry().build("sensor", "replay:sample=1,taxel_ids=0-1;3-5;16-18",
                                   path=str(can_log))
    frames = list(sensor.frames())
    np.testing.assert_array_equal(np.stack([f.values for f in frames]), log_samples()[1].values)
    assert {f.label for f in frames} == {"Pull"}
    with pytest.raises(ValueError, match="sample 2 is out of range: .* has 2 samples"):
        Replay(str(can_log), sample=2)


def test_a_can_log_counts_the_taxels_of_lost_messages(tmp_path):
    """A sweep with a lost message comes out with those taxels held and counted."""
    from tactbench.can.codec import TaxelMap, encode_sweep
    from tactbench.can.logs import write_log

    taxels = TaxelMap(LOG_IDS)  # module 0: 5 taxels in 2 messages, module 1: 3 in 1
    values = np.arange(3 * LOG_IDS.size, dtype=np.float32).reshape(3, LOG_IDS.size)
    sweeps = [encode_sweep(values[k], taxels, k, timestamp=0.1 * k) for k in range(3)]
    sweeps[1].pop(0)  # the first message of sweep 1: slots 0-3 of module 0, taxels 0, 1, 3
    path = tmp_path / "lossy.asc"
    write_log(path, [m for burst in sweeps for m in burst])
    frames = list(Replay(str(path), taxel_ids=LOG_IDS).frames())
    assert [f.missing for f in frames] == [0, 3, 0]
    assert frames[1].values[:3].tolist() == values[0, :3].tolist()  # held from sweep 0
    assert frames[1].values[3:].tolist() == values[1, 3:].tolist()
    assert all(f.label is None for f in frames)


def test_a_can_log_in_realtime_and_in_a_loop(can_log):
    start = time.monotonic()
    frames = list(Replay(str(can_log), sample=0, realtime=True).frames())
    assert len(frames) == 4 and time.monotonic() - start >= 0.15 - 0.01  # last at 0.15 s
    sensor = Replay(str(can_log), loop=True)
    stream = sensor.frames()
    frames = [next(stream) for _ in range(16)]
    sensor.close()
    assert list(stream) == []
    assert np.all(np.diff([f.timestamp for f in frames]) > 0)  # time goes on across passes
    assert [f.sequence for f in frames] == list(range(16))
    np.testing.assert_array_equal(frames[7].values, frames[0].values)


def test_can_options_are_refused_for_other_data(saved):
    with pytest.raises(ValueError, match="apply to CAN logs"):
        Replay(str(saved), taxel_ids=[7, 8, 9])


def test_every_registered_sensor_meets_the_sensor_contract(saved):
    """Registry.build checks the contract; each built-in sensor passes it when built."""
    import uuid

    registry = load_registry()
    built = {"replay": registry.build("sensor", "replay", path=str(saved)),
             "cyskin-can": registry.build("sensor", "cyskin-can",
                                          channel=f"contract-{uuid.uuid4().hex[:8]}",
                                          taxel_ids="0-10")}
    builtin = {n for n in registry.names("sensor")
               if registry.get("sensor", n).target.startswith("tactbench.sensors.")}
    assert builtin == set(built)  # a new built-in sensor gets a case here
    for name, sensor in built.items():
        with sensor:
            assert SENSOR.problems(sensor) == [], name
            assert SENSOR.get(sensor, "taxel_ids").dtype.kind in "iu"
