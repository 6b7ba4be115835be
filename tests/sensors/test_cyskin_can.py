"""The cyskin-can sensor on python-can's virtual bus, fed by the simulator."""

from __future__ import annotations

import threading
import uuid

import can
import numpy as np
import pytest

from tactbench.can.codec import TaxelMap, encode_sweep
from tactbench.can.simulate import SimSample, as_sim_sample, play, traffic
from tactbench.contracts import SENSOR
from tactbench.plugins import load_registry
from tactbench.sensors.cyskin_can import CySkinCAN, parse_taxel_ids

IDS = np.array([m * 16 + s for m in (2, 3) for s in range(11)])  # 22 taxels


@pytest.fixture
def channel() -> str:
    return f"test-{uuid.uuid4().hex[:8]}"  # a private virtual bus per test


def sim_samples(n_sweeps=(4, 3)) -> list[SimSample]:
    rng = np.random.default_rng(5)
    return [SimSample(rng.integers(0, 65536, (n, IDS.size)).astype(np.float32),
                      0.1 * np.arange(n), {"label": f"g{i}"}) for i, n in enumerate(n_sweeps)]


def run_sender(channel: str, bursts, **kw) -> threading.Thread:
    def send():
        with can.Bus(interface="virtual", channel=channel) as bus:
            play(bus, bursts, **kw)

    thread = threading.Thread(target=send, daemon=True)
    thread.start()
    return thread


def test_sensor_yields_the_simulated_sweeps_with_labels(channel):
    samples = sim_samples()
    with CySkinCAN(channel=channel, taxel_ids="32-42;48-58", idle_timeout=0.5) as sensor:
        assert SENSOR.problems(sensor) == []
        np.testing.assert_array_equal(sensor.taxel_ids, IDS)
        sender = run_sender(channel, traffic(samples, sensor.taxel_map), speed=10)
        frames = list(sensor.frames())
        sender.join()
    expected = np.concatenate([s.values for s in samples])
    assert len(frames) == len(expected)
    np.testing.assert_array_equal(np.stack([f.values for f in frames]), expected)
    assert [f.label for f in frames] == ["g0"] * 4 + ["g1"] * 3
    ts = np.array([f.timestamp for f in frames])
    assert (np.diff(ts) > 0).all()
    assert sensor.stats.complete_sweeps == 7 and sensor.stats.lost_messages == 0


def test_a_sweep_with_a_lost_message_comes_out_after_flush_after(channel):
    taxels = TaxelMap(IDS)
    values = np.full((2, IDS.size), 7.0, np.float32)
    msgs = [encode_sweep(values[k], taxels, k) for k in range(2)]
    del msgs[1][0]
    with CySkinCAN(channel=channel, taxel_ids=IDS, idle_timeout=0.6, flush_after=0.1,
                   missing="zero") as sensor:
        run_sender(channel, [(0.0, msgs[0]), (0.05, msgs[1])], speed=1).join()
        frames = list(sensor.frames())
    assert [f.missing for f in frames] == [0, 4]
    assert (frames[1].values == 0).sum() == 4


def test_max_sweeps_and_close_from_another_thread(channel):
    taxels = TaxelMap(IDS)
    with CySkinCAN(channel=channel, taxel_ids=IDS, max_sweeps=2) as sensor:
        with can.Bus(interface="virtual", channel=channel) as tx:
            for k in range(5):
                for m in encode_sweep(np.zeros(IDS.size), taxels, k):
                    tx.send(m)
        assert len(list(sensor.frames())) == 2
    sensor = CySkinCAN(channel=channel, taxel_ids=IDS)  # no idle timeout: waits
    timer = threading.Timer(0.2, sensor.close)
    timer.start()
    assert list(sensor.frames()) == []
    timer.join()


def test_built_through_the_registry(channel):
    registry = load_registry()
    comp = registry.get("sensor", "cyskin-can")
    assert comp.requires == ("can",)
    sensor = registry.build("sensor", f"cyskin-can:channel={channel},taxel_ids=32-42;48-58,"
                                      f"format=ids=standard;base_id=0x200,idle_timeout=0.1")
    with sensor:
        assert sensor.taxel_map.fmt.ids == "standard"
        assert sensor.taxel_map.fmt.base_id == 0x200
        assert "22 taxels" in sensor.bus_load().describe()


def test_sensor_options_are_checked(channel, tmp_path):
    with pytest.raises(ValueError, match="exactly one of taxel_ids"):
        CySkinCAN(channel=channel)
    with pytest.raises(ValueError, match="expected N or N-M"):
        CySkinCAN(channel=channel, taxel_ids="1,x")
    with pytest.raises(ValueError, match="cannot open"):
        CySkinCAN(interface="no-such-interface", channel="x", taxel_ids="1")
    assert parse_taxel_ids("0-2 5").tolist() == [0, 1, 2, 5]


def test_layout_file_gives_the_taxels_and_the_layout(channel, tmp_path):
    from tactbench.data.layout_io import load_layout

    path = tmp_path / "layout.csv"
    path.write_text("id,x_mm,y_mm\n" + "".join(f"{t},{i * 7.5},0\n" for i, t in enumerate(IDS)))
    layout = load_layout(path)
    with CySkinCAN(channel=channel, layout=str(path)) as sensor:
        np.testing.assert_array_equal(np.sort(sensor.taxel_ids), np.sort(layout.ids))
        np.testing.assert_array_equal(sensor.layout.positions, layout.positions)
    with CySkinCAN(channel=channel, taxel_ids=IDS) as sensor:
        assert sensor.layout is None


def test_as_sim_sample_accepts_arrays():
    s = as_sim_sample(np.zeros((3, 4)), rate_hz=20)
    np.testing.assert_allclose(s.timestamps, [0, 0.05, 0.1])
    assert s.info is None
    with pytest.raises(ValueError, match=r"\(T, N\)"):
        as_sim_sample(np.zeros(3))
