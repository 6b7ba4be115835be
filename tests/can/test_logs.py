"""CAN logs: simulated samples written to .blf/.asc and read back exactly, with labels."""

from __future__ import annotations

import can
import numpy as np
import pytest

from tactbench.can.codec import FrameFormat, TaxelMap, encode_sweep
from tactbench.can.logs import (
    infer_taxel_ids,
    is_can_log,
    read_log,
    read_messages,
    write_log,
)
from tactbench.can.meta import MetaAssembler, is_meta, marker_messages, taxel_map_messages
from tactbench.can.simulate import SimSample, schedule_messages, traffic

# Two modules with a gap (slot 2 of module 0 absent), like a real patch with a dead taxel.
IDS = np.array([0, 1, 3, 4, 5, 16, 17, 18, 19, 20, 21])


def samples(seed: int = 0) -> list[SimSample]:
    rng = np.random.default_rng(seed)
    out = []
    for i, (label, n) in enumerate([("Grasp", 7), ("Pull", 5), ("Grasp", 6)]):
        values = rng.integers(0, 65536, (n, IDS.size)).astype(np.float32)
        out.append(SimSample(values, 0.1 * np.arange(n) + 3.0 * i,
                             {"label": label, "user": i % 2, "repetition": i}))
    return out


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_simulated_samples_read_back_equal(tmp_path, suffix):
    path = tmp_path / f"run{suffix}"
    taxels = TaxelMap(IDS)
    originals = samples()
    write_log(path, schedule_messages(traffic(originals, taxels), t0=1.7e9))
    log = read_log(path)
    assert log.taxel_source == "announced"
    np.testing.assert_array_equal(log.taxel_ids, IDS)
    assert [s.label for s in log.segments] == ["Grasp", "Pull", "Grasp"]
    for seg, orig in zip(log.segments, originals):
        np.testing.assert_array_equal(seg.values, orig.values)
        assert seg.values.dtype == np.float32
        np.testing.assert_allclose(seg.timestamps - seg.timestamps[0],
                                   orig.timestamps - orig.timestamps[0], atol=2e-6)
        assert seg.info == orig.info
        assert not seg.missing.any()
    summary = log.summary()
    assert summary["samples_per_class"] == {"Grasp": 2, "Pull": 1}
    assert summary["frames_per_sample"] == {"min": 5, "median": 6.0, "max": 7}
    assert summary["assembler"]["lost_messages"] == 0


def test_without_announcement_taxels_are_inferred_from_the_traffic(tmp_path):
    path = tmp_path / "bare.asc"
    taxels = TaxelMap(IDS)
    write_log(path, schedule_messages(traffic(samples(), taxels, announce=False)))
    log = read_log(path)
    assert log.taxel_source == "inferred"
    # The absent slot 2 travels inside a message as 0, so it shows up as a taxel.
    assert log.taxel_ids.tolist() == [0, 1, 2, 3, 4, 5, 16, 17, 18, 19, 20, 21]
    assert (log.segments[0].values[:, 2] == 0).all()
    exact = read_log(path, taxel_ids=IDS)
    assert exact.taxel_source == "given"
    np.testing.assert_array_equal(exact.segments[1].values, samples()[1].values)


def test_unmarked_traffic_is_one_unlabelled_segment(tmp_path):
    path = tmp_path / "plain.blf"
    taxels = TaxelMap(IDS)
    values = np.arange(3 * IDS.size, dtype=np.float32).reshape(3, IDS.size)
    msgs = [m for k in range(3) for m in encode_sweep(values[k], taxels, k, timestamp=k * 0.1)]
    write_log(path, msgs)
    log = read_log(path, taxel_ids=IDS)
    [seg] = log.segments
    assert seg.label is None and len(seg) == 3 and log.labelled == []
    np.testing.assert_array_equal(log.sweeps()[1], values)


def test_other_traffic_in_the_log_is_ignored_and_counted(tmp_path):
    path = tmp_path / "busy.asc"
    taxels = TaxelMap(IDS)
    msgs = list(schedule_messages(traffic(samples()[:1], taxels)))
    noise = [can.Message(arbitration_id=0x7E0, is_extended_id=False, data=b"\x02\x01\x0c",
                         timestamp=0.05),
             can.Message(is_error_frame=True, timestamp=0.06)]
    write_log(path, msgs[:5] + noise + msgs[5:])
    log = read_log(path)
    np.testing.assert_array_equal(log.segments[0].values, samples()[0].values)
    assert log.stats.rejected["foreign_id"] == 1 and log.stats.rejected["error_frame"] == 1


def test_fd_frames_survive_both_log_formats(tmp_path):
    fmt = FrameFormat(fd=True)
    taxels = TaxelMap(IDS, fmt)
    for suffix in (".blf", ".asc"):
        path = tmp_path / f"fd{suffix}"
        write_log(path, schedule_messages(traffic(samples(), taxels)))
        log = read_log(path, fmt=fmt)
        np.testing.assert_array_equal(log.segments[2].values, samples()[2].values)


def test_bad_paths_give_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such CAN log"):
        read_log(tmp_path / "nope.blf")
    odd = tmp_path / "x.txt"
    odd.write_text("hello")
    with pytest.raises(ValueError, match="not a CAN log file name"):
        read_log(odd)
    empty = tmp_path / "empty.asc"
    write_log(empty, [])
    with pytest.raises(ValueError, match="no CySkin data messages"):
        read_log(empty)
    assert is_can_log("a.BLF") and not is_can_log("a.npz")


def test_log_messages_keep_ids_and_payloads(tmp_path):
    msgs = encode_sweep(np.arange(IDS.size) * 999, TaxelMap(IDS), 5)
    write_log(tmp_path / "m.blf", msgs)
    back = list(read_messages(tmp_path / "m.blf"))
    assert [(m.arbitration_id, bytes(m.data)) for m in back] == \
        [(m.arbitration_id, bytes(m.data)) for m in msgs]
    np.testing.assert_array_equal(infer_taxel_ids(back), [0, 1, 2, 3, 4, 5, 16, 17, 18, 19,
                                                           20, 21])


# ----------------------------------------------------------------- meta frames

def test_markers_and_taxel_maps_reassemble_from_parts():
    info = {"label": "2hGrasp", "user": "participant-with-a-long-name", "repetition": 4}
    msgs = marker_messages(True, info, seq=7, timestamp=2.0)
    assert len(msgs) > 1 and all(is_meta(m) and m.dlc <= 8 for m in msgs)
    meta = MetaAssembler()
    events = [meta.feed(m) for m in msgs]
    assert events[:-1] == [None] * (len(msgs) - 1)
    assert events[-1].kind == "label_start" and events[-1].info == info
    ids = np.array([3, 17, 4095 * 16 + 15])
    [*_, last] = [meta.feed(m) for m in taxel_map_messages(ids, seq=8)]
    np.testing.assert_array_equal(last.taxel_ids, ids)


def test_a_marker_with_a_lost_part_is_counted_not_raised():
    msgs = marker_messages(False, {"label": "Twist" * 5}, seq=1)
    meta = MetaAssembler()
    assert [meta.feed(m) for m in msgs[1:]] == [None] * (len(msgs) - 1)
    assert meta.broken == 1
    with pytest.raises(ValueError, match="needs a 'label'"):
        marker_messages(True, {}, seq=0)


def test_a_log_becomes_a_dataset(tmp_path):
    from tactbench.data.dataset import Dataset

    path = tmp_path / "run.blf"
    write_log(path, schedule_messages(traffic(samples(), TaxelMap(IDS)), t0=5.0))
    dataset = read_log(path).to_dataset(name="run")
    assert isinstance(dataset, Dataset)
    assert dataset.classes == ("Grasp", "Pull")
    assert dataset.labels.tolist() == [0, 1, 0]
    assert dataset.users == ["0", "1", "0"]
    for sample, orig in zip(dataset.samples, samples()):
        np.testing.assert_array_equal(sample.recording.values, orig.values)
        np.testing.assert_allclose(sample.recording.timestamps,
                                   orig.timestamps - orig.timestamps[0], atol=2e-6)
        np.testing.assert_array_equal(sample.recording.taxel_ids, IDS)


def test_unmarked_log_becomes_an_unlabelled_dataset(tmp_path):
    pytest.importorskip("tactbench.data.recording")
    path = tmp_path / "plain.asc"
    taxels = TaxelMap(IDS)
    write_log(path, [m for k in range(4) for m in encode_sweep(np.full(IDS.size, k), taxels, k,
                                                                timestamp=10 + 0.1 * k)])
    dataset = read_log(path, taxel_ids=IDS).to_dataset()
    assert dataset.classes == ("unlabelled",) and len(dataset) == 1
    np.testing.assert_array_equal(dataset.samples[0].recording.values[:, 0], [0, 1, 2, 3])


def test_iter_sweeps_gives_every_sweep_or_one_sample(tmp_path):
    path = tmp_path / "run.blf"
    originals = samples()
    write_log(path, schedule_messages(traffic(originals, TaxelMap(IDS))))
    log = read_log(path)
    sweeps = list(log.iter_sweeps())
    np.testing.assert_array_equal(np.stack([s.values for s in sweeps]),
                                  np.concatenate([s.values for s in originals]))
    assert [s.label for s in sweeps] == [s.info["label"] for s in originals
                                         for _ in range(len(s.values))]
    assert [s.sequence for s in sweeps] == list(range(len(sweeps)))
    assert all(np.diff([s.timestamp for s in sweeps]) > 0)
    second = list(log.iter_sweeps(1))
    np.testing.assert_array_equal(np.stack([s.values for s in second]), originals[1].values)
    second[0].values[:] = -1  # copies: the log is untouched
    assert (log.segments[1].values >= 0).all()
    with pytest.raises(ValueError, match="sample 3 is out of range"):
        next(log.iter_sweeps(3))


def test_a_log_under_a_file_or_onto_a_folder_is_one_clear_error(tmp_path):
    from tactbench.errors import InputError

    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=r"rec.blf: cannot write there: .*f is a file"):
        write_log(tmp_path / "f" / "sub" / "rec.blf", [])
    (tmp_path / "d.asc").mkdir()
    with pytest.raises(InputError, match=r"d.asc: is a folder"):
        write_log(tmp_path / "d.asc", [])
    assert (tmp_path / "f").read_text() == "x"


def _blf_with(tmp_path, name: str, objects: bytes):
    """A .blf: the header tactbench's writer makes, then ``objects``."""
    import struct

    base = tmp_path / "base.blf"
    write_log(base, encode_sweep(np.arange(IDS.size), TaxelMap(IDS), 0))
    header_size = struct.unpack_from("<L", base.read_bytes(), 4)[0]
    path = tmp_path / name
    path.write_bytes(base.read_bytes()[:header_size] + objects)
    return path


def _container(payload: bytes, method: int = 2) -> bytes:
    import struct

    body = struct.pack("<H6xL4x", method, 0) + payload
    return struct.pack("<4sHHLL", b"LOBJ", 16, 1, 16 + len(body), 10) + body \
        + b"\0" * ((16 + len(body)) % 4)


def test_a_blf_decompression_bomb_is_refused_before_inflating(tmp_path, memory_cap,
                                                              monkeypatch):
    """260 kB of .blf holding 256 MiB of zlib-compressed zeros: python-can inflates a
    container whole (256 MiB at once); check_blf counts it 1 MiB at a time first."""
    import zlib

    from tactbench.errors import BudgetError

    z = zlib.compressobj(9)
    zeros = bytes(1 << 20)
    bomb = b"".join(z.compress(zeros) for _ in range(256)) + z.flush()
    path = _blf_with(tmp_path, "bomb.blf", _container(bomb))
    assert path.stat().st_size < 300_000
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "64")
    with memory_cap(50), pytest.raises(BudgetError, match=r"bomb.blf: \d+ bytes of .blf "
                                                          r"objects once decompressed"):
        read_log(path)


def test_a_blf_object_claiming_gigabytes_is_refused(tmp_path, memory_cap):
    """An object header claiming 4 GB in a 1 kB file: python-can would allocate 4 GB."""
    import struct

    from tactbench.errors import InputError

    good = tmp_path / "good.blf"
    write_log(good, encode_sweep(np.arange(IDS.size), TaxelMap(IDS), 0))
    data = bytearray(good.read_bytes())
    first = struct.unpack_from("<L", data, 4)[0]  # the first object follows the header
    struct.pack_into("<L", data, first + 8, 0xFFFFFFF0)
    path = tmp_path / "claims.blf"
    path.write_bytes(bytes(data))
    with memory_cap(50), pytest.raises(InputError, match=rf"claims.blf: damaged .blf: the "
                                                         rf"object at byte {first} claims"):
        read_log(path)
    # a log cut short (a crash while recording) still reads up to its last whole message
    msgs = [m for k in range(200) for m in encode_sweep(np.full(IDS.size, k), TaxelMap(IDS), k,
                                                        timestamp=0.1 * k)]
    write_log(good, msgs)
    cut = tmp_path / "cut.blf"
    cut.write_bytes(good.read_bytes()[:-50])
    assert len(read_log(cut, taxel_ids=IDS).segments[0]) > 0


def test_what_python_can_skips_is_counted_not_printed(tmp_path):
    """python-can logs a warning (a second line beside tactbench's) for each .blf
    container it skips; it is gathered: counted in the summary, named in an error."""
    import json
    import struct

    from click.testing import CliRunner

    from tactbench.cli import cli
    from tactbench.errors import InputError

    taxels = TaxelMap(IDS)
    msgs = [m for k in range(1000) for m in encode_sweep(np.full(IDS.size, k % 500), taxels,
                                                         k, timestamp=0.1 * k)]
    path = tmp_path / "two.blf"
    write_log(path, msgs)  # 4000 messages: python-can writes two containers
    data = bytearray(path.read_bytes())
    first = struct.unpack_from("<L", data, 4)[0]
    second = first + struct.unpack_from("<L", data, first + 8)[0]
    second += second % 4
    assert data[second:second + 4] == b"LOBJ"
    struct.pack_into("<H", data, second + 16, 77)  # an unknown compression method
    path.write_bytes(bytes(data))
    log = read_log(path, taxel_ids=IDS)
    assert 0 < log.summary()["sweeps"] < 1000 and log.summary()["reader_skipped"] == 1
    res = CliRunner().invoke(cli, ["can", "info", str(path), "--json"])
    assert res.exit_code == 0 and "Unknown compression" not in res.output
    assert json.loads(res.output)["reader_skipped"] == 1
    struct.pack_into("<H", data, first + 16, 77)  # both: nothing left to read
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"two.blf: no CySkin data messages .*python-can "
                                         r"skipped 2 damaged part.s. of it: Unknown compr"):
        read_log(path)
    res = CliRunner().invoke(cli, ["can", "info", str(path)])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1, res.output
