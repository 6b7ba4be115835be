"""`tactbench can simulate|record|load|info`: the command line over logs and the virtual bus."""

from __future__ import annotations

import json
import threading
import time
import uuid

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli


def invoke(*args: str):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


@pytest.fixture(scope="module")
def dataset():
    from tactbench.datasets.loading import load_dataset

    return load_dataset("synthetic-forearm:users=1,repetitions=1")


def assert_same_samples(original, back):
    assert [original.classes[s.label] for s in original.samples] == \
        [back.classes[s.label] for s in back.samples]
    for a, b in zip(original.samples, back.samples):
        np.testing.assert_array_equal(a.recording.values, b.recording.values)
        np.testing.assert_allclose(a.recording.timestamps - a.recording.timestamps[0],
                                   b.recording.timestamps, atol=2e-6)
        assert (a.user, a.position, a.repetition) == (b.user, b.position, b.repetition)
        np.testing.assert_array_equal(a.recording.taxel_ids, b.recording.taxel_ids)


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_simulated_dataset_written_and_read_back_equals_the_original(tmp_path, dataset, suffix):
    from tactbench.can.logs import read_log

    out = tmp_path / f"sim{suffix}"
    result = invoke("can", "simulate", "synthetic-forearm:users=1,repetitions=1",
                    "--out", str(out), "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["samples"] == len(dataset) and doc["sweeps"] == int(dataset.lengths().sum())
    assert 0.4 < doc["bus_load"]["load"] < 0.6
    back = read_log(out).to_dataset()
    assert back.classes == dataset.classes
    assert_same_samples(dataset, back)


def test_record_writes_the_bus_with_label_markers(tmp_path, dataset):
    """simulate (on the virtual bus, in a thread) → record → read back == original."""
    import can

    from tactbench.can.codec import TaxelMap
    from tactbench.can.logs import read_log
    from tactbench.can.simulate import as_sim_sample, play, traffic

    # trailing digits above 65535: python-can's BLF writer cannot store such a channel
    channel = f"rec-{uuid.uuid4().hex[:8]}-9912345"
    sample = dataset.samples[3]
    out = tmp_path / "rec.blf"

    def send():
        time.sleep(0.3)  # let the recorder open its bus first
        with can.Bus(interface="virtual", channel=channel) as bus:
            play(bus, traffic([as_sim_sample(sample.recording)], TaxelMap(dataset.taxel_ids),
                              announce=False), speed=20)

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    result = invoke("can", "record", "--out", str(out), "--channel", channel,
                    "--idle-timeout", "0.6", "--label", "Twist", "--user", "7",
                    "--taxel-ids",
                    ",".join(map(str, dataset.taxel_ids)), "--json")
    sender.join()
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["messages"] > 0 and doc["label"] == "Twist"
    assert 0 < doc["bus_load_measured"] < 1
    log = read_log(out)
    assert log.taxel_source == "announced"
    [seg] = log.labelled
    assert seg.info == {"label": "Twist", "user": "7"}
    np.testing.assert_array_equal(seg.values, sample.recording.values)


def test_info_and_load_print_json(tmp_path):
    out = tmp_path / "s.asc"
    assert invoke("can", "simulate", "synthetic-forearm:users=1,repetitions=1", "--samples",
                  "2", "--out", str(out)).exit_code == 0
    info = json.loads(invoke("can", "info", str(out), "--json").stdout)
    assert info["samples"] == 2 and info["taxels"] == 1558
    assert info["assembler"]["lost_messages"] == 0
    load = json.loads(invoke("can", "load", "--taxels", "1558", "--json").stdout)
    assert load["messages_per_sweep"] == 425 and load["fits"]
    table = invoke("can", "load", "--taxels", "1558", "--bitrate", "500000")
    assert "NOT fit" in table.output


def test_errors_are_one_line(tmp_path):
    runner = CliRunner()
    res = runner.invoke(cli, ["can", "simulate", str(tmp_path / "missing.blf"), "--out",
                              str(tmp_path / "x.blf")])
    assert res.exit_code != 0 and "no such CAN log" in res.output
    res = runner.invoke(cli, ["can", "load", "--taxels", "10", "--format", "ids=nope"])
    assert res.exit_code != 0 and "ids must be" in res.output
    res = runner.invoke(cli, ["can", "record", "--out", str(tmp_path / "x.txt"),
                              "--duration", "0"])
    assert res.exit_code != 0 and "not a CAN log file name" in res.output
