"""Hostile label markers: counted as broken traffic by every CAN reader, never raised.

A marker nested 16 000 ``[`` deep raised ``RecursionError`` (the JSON parser recurses)
in ``can info``, ``data info``, the replay sensor and ``CySkinCAN.frames()``; a marker
whose ``repetition`` is a list or ``1e999`` raised ``TypeError`` / ``OverflowError``
when the log became a dataset. The convention for broken meta messages (a lost part,
bad JSON) is to count them and read on; these follow it.
"""

from __future__ import annotations

import json
import threading
import uuid

import can
import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.can.codec import TaxelMap
from tactbench.can.logs import read_log, write_log
from tactbench.can.meta import (
    LABEL_END,
    LABEL_START,
    MAX_MARKER_DEPTH,
    MetaAssembler,
    json_depth,
    marker_messages,
    meta_id,
)
from tactbench.can.simulate import SimSample, schedule_messages, traffic
from tactbench.cli import cli

IDS = np.array([m * 16 + s for m in (2, 3) for s in range(11)])  # 22 taxels

NESTED = b"[" * 16_000  # 2000 parts: within the 2048 a meta message may have
HOSTILE = {
    "nested": NESTED,
    "nested-in-object": b'{"label":"x","user":' + b"[" * 5000 + b"]" * 5000 + b"}",
    "repetition-list": b'{"label":"Grasp","repetition":[1,2]}',
    "repetition-1e999": b'{"label":"Grasp","repetition":1e999}',
    "repetition-text": b'{"label":"Grasp","repetition":"three"}',
    "repetition-huge": b'{"label":"Grasp","repetition":' + b"9" * 30 + b"}",
    "label-object": b'{"label":{"a":1}}',
    "label-nan": b'{"label":NaN}',
    "user-null": b'{"label":"Grasp","user":null}',
}


def raw_marker(payload: bytes, seq: int, *, start: bool = True, t: float = 0.0) -> list:
    """A label marker carrying any payload, cut into 8-byte parts as tactbench sends."""
    kind = LABEL_START if start else LABEL_END
    parts = [payload[i:i + 8] for i in range(0, len(payload), 8)]
    return [can.Message(timestamp=t, is_extended_id=True, data=part,
                        arbitration_id=meta_id(kind, i, i == len(parts) - 1, seq))
            for i, part in enumerate(parts)]


def sim_samples() -> list[SimSample]:
    rng = np.random.default_rng(3)
    return [SimSample(rng.integers(0, 65536, (n, IDS.size)).astype(np.float32),
                      0.1 * np.arange(n), {"label": label, "repetition": k})
            for k, (label, n) in enumerate([("Grasp", 4), ("Pull", 3)])]


def hostile_log(path, payload: bytes) -> None:
    """Two good samples, and a third framed by hostile start and end markers."""
    msgs = list(schedule_messages(traffic(sim_samples(), TaxelMap(IDS)), t0=100.0))
    t = msgs[-1].timestamp + 1
    third = list(schedule_messages(traffic(sim_samples()[:1], TaxelMap(IDS), markers=False,
                                           announce=False, counter_start=50), t0=t))
    write_log(path, msgs + raw_marker(payload, 77, t=t) + third
              + raw_marker(payload, 77, start=False, t=t + 1))


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_a_hostile_marker_is_counted_as_broken(name):
    meta = MetaAssembler()
    events = [meta.feed(m) for m in raw_marker(HOSTILE[name], 9)]
    assert events == [None] * len(events) and meta.broken == 1
    # the assembler goes on: the next good marker is read
    [*_, event] = [meta.feed(m) for m in marker_messages(True, {"label": "ok"}, 10)]
    assert event.info == {"label": "ok"} and meta.broken == 1


def test_markers_tactbench_writes_are_not_broken():
    info = {"label": "Grasp", "user": 3, "position": "p1", "repetition": -2,
            "source": "a/b.npz", "class_index": 0, "extra": {"nested": [[1, 2], {}]}}
    meta = MetaAssembler()
    [*_, event] = [meta.feed(m) for m in marker_messages(True, info, 1)]
    assert event.info == info and meta.broken == 0
    with pytest.raises(ValueError, match="'repetition' must be an integer"):
        marker_messages(True, {"label": "x", "repetition": [1]}, 0)


def test_json_depth_counts_without_recursion():
    assert json_depth('{"a": [1, {"b": "[[[["}], "c": "\\"["}') == 3
    assert json_depth("[" * 100_000) == MAX_MARKER_DEPTH + 1
    assert json_depth('"just a string"') == 0


@pytest.mark.parametrize("name", ["nested", "repetition-list", "repetition-1e999"])
@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_every_log_reader_reads_on(tmp_path, name, suffix):
    from tactbench.datasets.loading import load_dataset
    from tactbench.sensors.replay import Replay

    path = tmp_path / f"hostile{suffix}"
    hostile_log(path, HOSTILE[name])
    before = path.read_bytes()
    log = read_log(path)
    assert log.broken_meta == 2  # its start and its end
    assert [s.label for s in log.labelled] == ["Grasp", "Pull"]
    assert len(log.segments) == 3 and log.segments[2].label is None  # the third: unlabelled
    dataset = load_dataset(str(path))
    assert dataset.classes == ("Grasp", "Pull") and dataset.repetitions.tolist() == [0, 1]
    with Replay(str(path)) as sensor:
        assert len(list(sensor.frames())) == 4 + 3 + 4
    runner = CliRunner()
    for args in (["can", "info", str(path), "--json"], ["data", "info", str(path), "--json"]):
        res = runner.invoke(cli, args)
        assert res.exit_code == 0, res.output
    assert json.loads(runner.invoke(cli, ["can", "info", str(path), "--json"]).stdout)[
        "broken_meta_messages"] == 2
    assert path.read_bytes() == before


def test_the_cyskin_can_sensor_reads_on(tmp_path):
    from tactbench.can.simulate import play
    from tactbench.sensors.cyskin_can import CySkinCAN

    channel = f"meta-{uuid.uuid4().hex[:8]}"
    good = sim_samples()
    bursts = list(traffic(good, TaxelMap(IDS), announce=False))
    bursts.insert(0, (0.0, raw_marker(NESTED, 200)))
    bursts.insert(1, (0.0, raw_marker(HOSTILE["repetition-1e999"], 201)))

    with CySkinCAN(channel=channel, taxel_ids="32-42;48-58", idle_timeout=0.5) as sensor:
        def send():
            with can.Bus(interface="virtual", channel=channel) as bus:
                play(bus, bursts, speed=0)

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        sweeps = list(sensor.frames())
        sender.join()
        assert sensor._meta.broken == 2
    assert [s.label for s in sweeps] == ["Grasp"] * 4 + ["Pull"] * 3
    np.testing.assert_array_equal(np.stack([s.values for s in sweeps]),
                                  np.concatenate([s.values for s in good]))
