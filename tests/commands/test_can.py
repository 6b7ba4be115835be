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
    # a virtual bus played at 20x has no real capacity, so the load may pass 100 %;
    # what must hold is that it counts every frame at its nominal length (67 + 8 per byte)
    bits_per_message = doc["bus_load_measured"] * 1e6 * doc["seconds"] / doc["messages"]
    assert 67 < bits_per_message <= 67 + 64
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
                              "--duration", "1"])
    assert res.exit_code != 0 and "not a CAN log file name" in res.output


def one_error_line(res, *needles: str) -> str:
    """The command failed as a user's mistake: exit 2 and one line naming the problem."""
    assert res.exit_code == 2, (res.exit_code, res.output, res.exception)
    [line] = res.output.strip().splitlines()
    assert line.startswith("Error: ") and all(n in line for n in needles), line
    return line


def test_an_out_under_a_file_is_refused_before_the_bus_opens(tmp_path):
    """Before: NotADirectoryError from the log writer, after the bus was opened. The
    interface below cannot open, so an error about --out shows it is checked first."""
    runner = CliRunner()
    (tmp_path / "file").write_text("x")
    under = str(tmp_path / "file" / "rec.blf")
    one_error_line(runner.invoke(cli, ["can", "record", "--out", under, "--interface",
                                       "no-such-interface", "--duration", "1"]),
                   "rec.blf", "is a file, not a folder")
    deeper = str(tmp_path / "file" / "a" / "b" / "rec.asc")
    one_error_line(runner.invoke(cli, ["can", "record", "--out", deeper, "--interface",
                                       "no-such-interface", "--duration", "1"]),
                   "is a file, not a folder")
    folder = tmp_path / "folder.blf"
    folder.mkdir()
    res = runner.invoke(cli, ["can", "record", "--out", str(folder), "--interface",
                              "no-such-interface", "--duration", "1"])
    assert res.exit_code == 2 and "is a directory" in res.output  # click's own check
    # simulate checks --out before it loads the samples
    one_error_line(runner.invoke(cli, ["can", "simulate", "no-such-dataset", "--out", under]),
                   "is a file, not a folder")
    # a missing folder is created, as before
    out = tmp_path / "new" / "deeper" / "s.asc"
    assert invoke("can", "simulate", "synthetic-forearm:users=1,repetitions=1", "--samples",
                  "1", "--out", str(out)).exit_code == 0
    assert out.stat().st_size > 0


@pytest.mark.parametrize("args, needle", [
    (["can", "info", "LOG", "--taxel-ids", "0-99999999999"], "more than 65536 taxels"),
    (["can", "info", "LOG", "--taxel-ids", "0-99999999999999999999999"], "0 to 2**63-1"),
    (["can", "info", "LOG", "--taxel-ids", "10-5"], "the range 10-5 is empty"),
    (["can", "load", "--taxel-ids", "0-40000,50000-99999"], "more than 65536 taxels"),
    (["can", "load", "--taxels", "99999999999"], "at most 65536"),
    (["can", "record", "--out", "OUT", "--taxel-ids", "0-99999999999", "--duration", "1"],
     "more than 65536 taxels"),
])
def test_huge_taxel_id_ranges_are_refused_before_expanding(tmp_path, memory_cap, args, needle):
    """Before: MemoryError (a list of 10^11 ints) for `can info --taxel-ids 0-99999999999`."""
    log = tmp_path / "s.asc"
    log.write_text("")
    args = [str(log) if a == "LOG" else str(tmp_path / "r.blf") if a == "OUT" else a
            for a in args]
    with memory_cap(50):
        res = CliRunner().invoke(cli, args)
    one_error_line(res, needle)
