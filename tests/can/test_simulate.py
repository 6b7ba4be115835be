"""Playing recordings as CySkin traffic: what to play, on a virtual bus or into a log."""

from __future__ import annotations

import threading
import uuid

import can
import numpy as np
import pytest

from tactbench.can.codec import TaxelMap
from tactbench.can.logs import read_log
from tactbench.can.simulate import SimSample, load_samples, send_samples, write_samples
from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample

IDS = np.array([16, 17, 18, 0, 1])  # not sorted: the values' order is what counts


@pytest.fixture
def dataset_dir(tmp_path):
    rng = np.random.default_rng(2)
    samples = [Sample(Recording(rng.integers(0, 60000, (n, IDS.size)).astype(np.float32),
                                0.1 * np.arange(n), IDS), label, user=f"u{label}",
                      repetition=1)
               for n, label in [(3, 0), (4, 1)]]
    Dataset("sim", samples, ("Grasp", "Pull")).save(tmp_path / "d")
    return tmp_path / "d"


def test_load_samples_of_a_dataset_keeps_values_labels_and_taxel_order(dataset_dir):
    samples, ids = load_samples(str(dataset_dir))
    np.testing.assert_array_equal(ids, IDS)
    assert [s.info["label"] for s in samples] == ["Grasp", "Pull"]
    assert [s.info["class_index"] for s in samples] == [0, 1]
    assert samples[1].info["user"] == "u1" and samples[1].info["repetition"] == 1
    back = Dataset.load(dataset_dir)
    for sim, orig in zip(samples, back.samples):
        np.testing.assert_array_equal(sim.values, orig.recording.values)


def test_a_dataset_written_as_traffic_reads_back_equal_and_loads_again(dataset_dir, tmp_path):
    samples, ids = load_samples(str(dataset_dir))
    log = tmp_path / "sim.asc"
    n = write_samples(log, samples, TaxelMap(ids), gap_s=0.2, t0=50.0)
    assert n > 0
    back = read_log(log)
    np.testing.assert_array_equal(back.taxel_ids, np.sort(IDS))  # announced, layout order
    again, again_ids = load_samples(str(log))  # a CAN log is a source too
    np.testing.assert_array_equal(again_ids, back.taxel_ids)
    order = np.searchsorted(again_ids, IDS)
    for a, b in zip(samples, again):
        np.testing.assert_array_equal(b.values[:, order], a.values)
        assert b.info["label"] == a.info["label"]


def test_send_samples_on_the_virtual_bus_reports_sweeps(tmp_path):
    channel = f"sim-{uuid.uuid4().hex[:8]}"
    taxels = TaxelMap(IDS)
    samples = [SimSample(np.full((4, IDS.size), k, np.float32), 0.01 * np.arange(4),
                         {"label": f"g{k}"}) for k in range(2)]
    received = []
    with can.Bus(interface="virtual", channel=channel) as listener:
        def listen():
            while (msg := listener.recv(timeout=0.5)) is not None:
                received.append(msg)

        thread = threading.Thread(target=listen, daemon=True)
        thread.start()
        done = []
        with can.Bus(interface="virtual", channel=channel) as bus:
            sent = send_samples(bus, samples, taxels, speed=0,
                                progress=lambda n, total=None, **_: done.append(n))
        thread.join()
    assert done == list(range(1, 9))  # sweeps, not markers
    assert sent == len(received) > 8
    with pytest.raises(ValueError, match="speed must be"):
        send_samples(None, samples, taxels, speed=-1)


def test_send_samples_loops_until_told_to_stop():
    channel = f"loop-{uuid.uuid4().hex[:8]}"
    samples = [SimSample(np.zeros((2, IDS.size), np.float32), 0.01 * np.arange(2))]
    passes = []
    with can.Bus(interface="virtual", channel=channel) as bus:
        send_samples(bus, samples, TaxelMap(IDS), speed=0, loop=True,
                     should_stop=lambda: len(passes) >= 3,
                     progress=lambda n, total=None, **_: passes.append(n) if n == 2 else None)
    assert len(passes) == 3
