"""Encodings on disk: whole folders or none, keyed by everything that decides them,
streamed a chunk at a time, stored at a precision, read back a sequence at a time."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from tactbench.errors import CorruptArtefactError
from tactbench.runner import EncodingCache, ensure_encodings, load_encoding, plan
from tactbench.encoders.encoding import Storage, chunk_bounds
from tactbench.runner.execution import entries as entries_module


def test_write_and_load_round_trip(tmp_path):
    cache = EncodingCache(tmp_path)
    seqs = [np.full((t, 2, 3, 4), t, np.float32) for t in (3, 1, 5)]
    key = cache.key("hash", {"kind": "images", "pixel_mm": 5.0}, "raw", "1")
    assert not cache.has(key)
    cache.write(key, seqs, {"encoder": "raw"})
    assert cache.has(key)
    loaded, meta = load_encoding(cache.path(key))
    assert [s.shape for s in loaded] == [s.shape for s in seqs]
    assert all(np.array_equal(a, b) for a, b in zip(loaded, seqs))
    assert meta["encoder"] == "raw" and "created" in meta
    assert (meta["precision"], meta["dtype"], meta["n_frames"], meta["frames"],
            meta["frame_shape"], meta["scale"], meta["offset"]) == \
           ("float32", "float32", 9, 9, [2, 3, 4], [1.0, 1.0], [0.0, 0.0])
    (entry,) = cache.entries()
    assert entry["key"] == key and entry["bytes"] > 9 * 24 * 4
    assert entry["precision"] == "float32"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no leftovers
    assert cache.clear() == 1 and cache.entries() == []


def test_a_failed_write_leaves_no_entry(tmp_path):
    cache = EncodingCache(tmp_path)
    with pytest.raises(ValueError, match=r"sequence 1 has shape \(2, 3\), expected \(2, 4\)"):
        cache.write("k", [np.zeros((2, 4), np.float32), np.zeros((2, 3), np.float32)], {})
    with pytest.raises(ValueError, match="got 1 of its 2 sequences"):
        with cache.entry("k", [1, 1], (4,), Storage.for_channels("float32", 1)) as writer:
            writer.append(np.zeros((1, 4), np.float32))
    assert not cache.has("k") and list(tmp_path.iterdir()) == []


def test_keys_change_with_imaging_encoder_version_and_precision():
    cache_key = EncodingCache.key
    base = cache_key(None, "h", {"kind": "vectors"}, "raw", "1")
    assert base != cache_key(None, "h2", {"kind": "vectors"}, "raw", "1")
    assert base != cache_key(None, "h", {"kind": "images"}, "raw", "1")
    assert base != cache_key(None, "h", {"kind": "vectors"}, "frame-diff", "1")
    assert base != cache_key(None, "h", {"kind": "vectors"}, "raw", "2")
    others = {cache_key(None, "h", {"kind": "vectors"}, "raw", "1", p)
              for p in ("float16", "uint8")}
    assert len(others) == 2 and base not in others


def test_keys_change_with_the_cpu_kernels_and_float32_is_the_unmarked_precision(monkeypatch):
    """An encoding computed by numpy's and OpenCV's AVX-512 loops is not the pinned AVX2
    one: the kernels are in the key (issue 36); float32 adds nothing to it."""
    from tactbench.kernels import KERNEL_VARIABLES, KERNELS_ENV

    pinned = EncodingCache.key(None, "h", {"kind": "vectors"}, "raw", "1")
    assert pinned == EncodingCache.key(None, "h", {"kind": "vectors"}, "raw", "1", "float32")
    monkeypatch.setenv(KERNELS_ENV, "native")
    for name in KERNEL_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert EncodingCache.key(None, "h", {"kind": "vectors"}, "raw", "1") != pinned


# --------------------------------------------------------------------- precision


def _values(shape, ranges, seed=0):
    rng = np.random.default_rng(seed)
    lo = np.array([r[0] for r in ranges], np.float32).reshape(1, -1, 1, 1)
    hi = np.array([r[1] for r in ranges], np.float32).reshape(1, -1, 1, 1)
    return (lo + rng.random(shape, dtype=np.float32) * (hi - lo)).astype(np.float32)


def test_uint8_is_within_half_a_quantum_of_each_channel_and_clips_outside(tmp_path):
    ranges = ((0.0, 1.0), (-1.0, 1.0), (0.0, 10.0))
    seqs = [_values((t, 3, 5, 6), ranges, seed=t) for t in (4, 2, 7)]
    seqs[0][0, 0, 0, 0], seqs[0][0, 1, 0, 0] = 1.5, -3.0  # outside their ranges
    cache = EncodingCache(tmp_path)
    cache.write("q", seqs, {}, precision="uint8", ranges=ranges)
    loaded, meta = load_encoding(cache.path("q"))
    assert meta["dtype"] == "uint8" and (tmp_path / "q" / "frames.npy").stat().st_size < \
        13 * 3 * 30 + 256  # one byte a value, and the .npy header
    quantum = np.array([(hi - lo) / 255 for lo, hi in ranges])
    np.testing.assert_allclose(meta["scale"], quantum, rtol=1e-6)
    assert meta["offset"] == [0.0, -1.0, 0.0]
    clipped = [np.clip(s, np.reshape([r[0] for r in ranges], (1, 3, 1, 1)),
                       np.reshape([r[1] for r in ranges], (1, 3, 1, 1))) for s in seqs]
    for want, got in zip(clipped, loaded):
        got = np.asarray(got)
        assert got.dtype == np.float32
        err = np.abs(got - want).max(axis=(0, 2, 3))
        assert np.all(err <= quantum / 2 + 1e-6), err
    assert np.asarray(loaded[0])[0, 0, 0, 0] == 1.0
    assert np.asarray(loaded[0])[0, 1, 0, 0] == -1.0


def test_float16_is_within_a_thousandth_relative(tmp_path):
    seqs = [_values((t, 2, 4, 4), ((0.0, 1.0), (0.0, 1.0)), seed=t) for t in (3, 5)]
    cache = EncodingCache(tmp_path)
    cache.write("h", seqs, {}, precision="float16")
    loaded, meta = load_encoding(cache.path("h"))
    assert meta["precision"] == meta["dtype"] == "float16"
    for want, got in zip(seqs, loaded):
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-3, atol=1e-7)


# ------------------------------------------------------------------------ reader


@pytest.fixture
def stored(tmp_path):
    """A uint8 entry of three sequences and the float32 values it was made from."""
    seqs = [_values((t, 2, 3, 4), ((0.0, 1.0), (0.0, 1.0)), seed=t) for t in (5, 1, 3)]
    cache = EncodingCache(tmp_path)
    cache.write("r", seqs, {}, precision="uint8")
    loaded, _ = load_encoding(cache.path("r"))
    return loaded, [Storage.for_channels("uint8", 2).decode(
        Storage.for_channels("uint8", 2).encode(s)) for s in seqs]


def test_a_stored_sequence_reads_like_a_float32_array(stored):
    loaded, want = stored
    s, w = loaded[0], want[0]
    assert (s.shape, len(s), s.ndim, s.dtype, s.size) == ((5, 2, 3, 4), 5, 4, np.float32,
                                                          120)
    for index in (slice(1, 4), slice(3, None), slice(None, -2), slice(4, 9), slice(3, 1),
                  2, -1, slice(None, None, 2), slice(None, None, -1), [4, 0, 2],
                  (slice(1, 3), 1), (0, 1, 2), Ellipsis):
        got = s[index]
        assert got.dtype == np.float32, index
        np.testing.assert_array_equal(got, w[index], err_msg=str(index))
    np.testing.assert_array_equal(np.asarray(s), w)
    whole = np.ascontiguousarray(s, dtype=np.float32)
    assert whole.flags.c_contiguous and whole.flags.writeable
    np.testing.assert_array_equal(whole, w)
    assert np.asarray(s, dtype=np.float64).dtype == np.float64
    with pytest.raises(IndexError):
        s[5]
    assert [x.shape for x in loaded] == [(5, 2, 3, 4), (1, 2, 3, 4), (3, 2, 3, 4)]


def test_stored_sequences_pickle_and_are_read_in_another_process(stored):
    import concurrent.futures
    import multiprocessing

    loaded, want = stored
    again = pickle.loads(pickle.dumps(loaded))
    np.testing.assert_array_equal(again[2][1:], want[2][1:])
    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=ctx) as pool:
        np.testing.assert_array_equal(pool.submit(np.asarray, loaded[0]).result(), want[0])


def test_reading_an_entry_sequence_by_sequence_keeps_memory_small(tmp_path):
    """48 MiB on disk, read whole, one sequence at a time: the process grows by about
    one sequence (1 MiB), not by the entry (a memory map's touched pages would stay)."""
    cache = EncodingCache(tmp_path)
    frame = (4, 64, 64)  # 64 KiB a frame
    with cache.entry("big", [16] * 48, frame, Storage.for_channels("float32", 4)) as w:
        for i in range(48):
            w.append(np.full((16, *frame), i, np.float32))
    loaded, _ = load_encoding(cache.path("big"))

    def rss_mib() -> float:
        with open("/proc/self/status") as fh:
            line = next(x for x in fh if x.startswith("VmRSS:"))
        return int(line.split()[1]) / 1024

    before = rss_mib()
    total = 0.0
    for i, seq in enumerate(loaded):
        total += float(seq[:].mean())
        assert seq[15, 3, 63, 63] == i
    assert total == sum(range(48))
    assert rss_mib() - before < 12


def test_an_entry_of_an_older_format_is_refused_and_rebuilt(tiny_scene, cache, caplog):
    """Format 1 (before precisions) had no key, sizes or checksums: it cannot be verified,
    so it is reported and encoded again, not read and not crashed on."""
    p = plan(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0]))
    (folder,) = ensure_encodings(p, cache, p.cells).values()
    loaded, _ = load_encoding(folder)
    want = [np.asarray(s) for s in loaded]
    for name in ("frames.npy", "offsets.npy", "meta.json"):
        (Path(folder) / name).unlink()
    frames = np.concatenate(want)
    np.save(Path(folder) / "frames.npy", frames)
    np.save(Path(folder) / "offsets.npy", np.cumsum([0] + [len(s) for s in want]))
    (Path(folder) / "meta.json").write_text(json.dumps({"encoder": "raw",
                                                        "frames": len(frames)}))
    with pytest.raises(CorruptArtefactError, match="entry format 1"):
        load_encoding(folder)
    assert cache.entries()[0]["state"] == "damaged"
    ensure_encodings(p, cache, p.cells)
    assert "entry format 1" in caplog.text and "encoding it again" in caplog.text
    loaded, meta = load_encoding(folder)
    assert meta["format"] == 3 and meta["key"] == Path(folder).name
    assert all(np.array_equal(a, b) for a, b in zip(loaded, want))


# --------------------------------------------------------------------- streaming


def test_streaming_writes_exactly_what_the_in_memory_path_wrote(tiny_scene, cache):
    """Several chunks (the budget holds two samples' images), every encoder of the
    plan, bit-identical to imaging and encoding the whole dataset at once."""
    from tactbench.encoders.parallel import encode_all

    p = plan(tiny_scene(encoders=["raw", "farneback"], classifiers=["logreg"]))
    ds, pixel_mm = p.dataset, p.scene.resolved_pixel_mm()
    h, w = ds.image_shape(pixel_mm)
    budget = 4 * h * w * int(ds.lengths()[:2].sum())
    assert len(chunk_bounds(ds.lengths(), 4 * h * w, budget)) >= 4
    folders = ensure_encodings(p, cache, p.cells, chunk_bytes=budget)
    images = ds.images(pixel_mm=pixel_mm)
    for enc in ("raw", "farneback"):
        loaded, meta = load_encoding(folders[(enc, "images")])
        expected = encode_all(p.encoders[enc], images, workers=1)
        assert len(loaded) == len(expected) == len(ds)
        for got, want in zip(loaded, expected):
            assert np.array_equal(np.asarray(got), want)
        assert meta["chunk_bytes"] == budget and meta["n_frames"] == sum(map(len, images))
        assert meta["imaging_seconds"] > 0 and meta["encode_seconds"] >= 0
        assert meta["frame_shape"] == [len(meta["channels"]), h, w]
        assert meta["peak_rss_mb"] > 0 and meta["workers"] >= 1


def test_taxel_vectors_stream_into_the_cache(tiny_scene, cache, nolayout_dataset):
    from tactbench.datasets.loading import load_dataset

    p = plan(tiny_scene(dataset=str(nolayout_dataset), encoders=["raw"],
                        classifiers=["logreg"], precision="uint8"))
    folders = ensure_encodings(p, cache, p.cells, chunk_bytes=100)
    loaded, meta = load_encoding(folders[("raw", "vectors")])
    assert meta["precision"] == "uint8" and meta["frame_shape"] == [5]
    for got, want in zip(loaded, load_dataset(str(nolayout_dataset)).vectors()):
        assert got.shape == want.shape
        assert np.abs(np.asarray(got) - want).max() <= 0.5 / 255 + 1e-7


def test_a_run_at_uint8_completes_and_its_rows_record_the_precision(tiny_scene, cache):
    from tactbench.runner import run

    result = run(tiny_scene(encoders=["frame-diff"], classifiers=["logreg"], seeds=[0],
                            precision="uint8"), progress=False, cache=cache)
    (row,) = result.rows
    assert row["status"] == "ok" and row["precision"] == "uint8"
    assert row["run"]["scene"]["precision"] == "uint8"
    (entry,) = cache.entries()
    assert entry["precision"] == "uint8" and entry["encoder"] == "frame-diff"
    assert entry["scale"] == pytest.approx([1 / 255, 2 / 255]) and entry["offset"] == [0, -1]


def test_values_uint8_clipped_are_said_when_written_and_again_when_read(
        tiny_scene, cache, caplog, monkeypatch):
    """An entry whose values uint8 storage clipped says so once when it is written; a
    later run (another process: the said-once record is empty) reading the entry says it
    again from the counts its meta keeps. Storage of raw at (0, 0.5) stands in for an
    encoder declaring no range that gives values beyond (0, 1)."""
    from tactbench.runner.execution import cache as cache_module

    monkeypatch.setattr(cache_module, "image_storage",
                        lambda encoder, precision: Storage.for_channels("uint8", 1,
                                                                        [(0.0, 0.5)]))
    p = plan(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0],
                        precision="uint8"))

    def said():
        lines = [r.getMessage() for r in caplog.records if "were clipped" in r.getMessage()]
        caplog.clear()
        return lines

    with caplog.at_level("WARNING", logger="tactbench.runner"):
        (folder,) = ensure_encodings(p, cache, p.cells).values()
        [written] = said()
        _, meta = load_encoding(folder)
        counts = meta["clipped"]
        assert counts["above"] > 0 and counts["below"] == 0
        assert f"{counts['above']} of {counts['values']} values" in written
        ensure_encodings(p, cache, p.cells)
        assert said() == []  # once per entry in a process
        monkeypatch.setattr(cache_module, "_SAID_CLIPPING", set())  # a later run
        ensure_encodings(p, cache, p.cells)
        [read] = said()
    assert read.startswith(written) and "cached encoding" in read and "\n" not in read


def test_an_entry_without_clipped_values_records_and_says_nothing(tiny_scene, cache, caplog):
    p = plan(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0],
                        precision="uint8"))
    with caplog.at_level("WARNING", logger="tactbench.runner"):
        (folder,) = ensure_encodings(p, cache, p.cells).values()
        ensure_encodings(p, cache, p.cells)
    assert "clipped" not in load_encoding(folder)[1]
    assert "were clipped" not in caplog.text


# ------------------------------------------------------- verification, races, orphans


def test_an_entry_records_what_it_is_and_checksums_streamed_while_writing(tmp_path):
    from tactbench.integrity import hash_file

    cache = EncodingCache(tmp_path)
    seqs = [np.full((t, 2, 3, 4), t, np.float32) for t in (3, 1, 5)]
    cache.write("k1", seqs, {"encoder": "raw"}, precision="float16")
    meta = json.loads((cache.path("k1") / "meta.json").read_text())
    assert (meta["format"], meta["key"], meta["n_frames"], meta["n_sequences"],
            meta["dtype"], meta["frame_shape"], meta["algorithm"]) == \
        (3, "k1", 9, 3, "float16", [2, 3, 4], "sha256")
    for name in ("frames.npy", "offsets.npy"):
        path = cache.path("k1") / name
        assert meta["files"][name] == {"bytes": path.stat().st_size,
                                       "checksum": hash_file(path)}
    assert cache.verify("k1")["meta_checksum"] == meta["meta_checksum"]


def test_the_identity_recorded_in_an_entry_must_hash_to_its_key(tmp_path):
    from tactbench.runner.execution.entries import seal

    cache = EncodingCache(tmp_path)
    identity = cache.identity("h", {"kind": "vectors"}, "raw", "1")
    key = cache.key("h", {"kind": "vectors"}, "raw", "1")
    cache.write(key, [np.zeros((2, 3), np.float32)], {"identity": identity})
    cache.verify(key)
    meta = json.loads((cache.path(key) / "meta.json").read_text())
    meta["identity"]["encoder"] = "frame-diff"  # re-sealed: only the identity gives it away
    (cache.path(key) / "meta.json").write_text(json.dumps(seal(meta)))
    with pytest.raises(CorruptArtefactError, match="identity does not hash to its key"):
        cache.verify(key)


def test_the_full_checksum_is_read_once_per_process_per_version_of_the_file(tmp_path,
                                                                           monkeypatch):
    cache = EncodingCache(tmp_path)
    cache.write("k", [np.ones((4, 3), np.float32)], {})
    calls = []
    real = entries_module.hash_file  # the entries' own name for it (imported at the top)
    monkeypatch.setattr(entries_module, "hash_file",
                        lambda *a, **k: calls.append(a) or real(*a, **k))
    cache.verify("k")
    assert calls == []  # the writer hashed the bytes as it wrote them: no second read
    entries_module._VERIFIED.clear()  # as in another process
    cache.verify("k")
    cache.verify("k")
    load_encoding(cache.path("k"))
    assert len(calls) == 1  # then memoised
    path = cache.path("k") / "frames.npy"
    data = bytearray(path.read_bytes())
    data[-1] ^= 0xFF  # same size, another version of the file
    path.write_bytes(bytes(data))
    with pytest.raises(CorruptArtefactError, match="frames.npy does not match its checksum"):
        load_encoding(cache.path("k"))
    assert len(calls) == 2
    assert cache.verify("k", full=False)["key"] == "k"  # the cheap checks cannot see it


def test_a_second_writer_of_a_key_drops_its_folder_and_verifies_the_winner(tmp_path):
    cache = EncodingCache(tmp_path)
    storage = Storage.for_channels("float32", 1)
    with cache.entry("k", [2], (3,), storage) as writer:
        writer.append(np.zeros((2, 3), np.float32))
        cache.write("k", [np.ones((2, 3), np.float32)], {"who": "winner"})  # finishes first
    loaded, meta = load_encoding(cache.path("k"))
    assert meta["who"] == "winner" and np.asarray(loaded[0]).sum() == 6
    assert [p.name for p in tmp_path.iterdir()] == ["k"]
    # a winner that is damaged is not used: the loser says so
    with pytest.raises(CorruptArtefactError, match="frames.npy is"):
        with cache.entry("k", [2], (3,), storage) as writer:
            writer.append(np.zeros((2, 3), np.float32))
            with open(cache.path("k") / "frames.npy", "ab") as fh:
                fh.write(b"x")
    assert [p.name for p in tmp_path.iterdir()] == ["k"]


RACER = """
import sys, time, zlib
from pathlib import Path
import numpy as np
from tactbench.runner.execution.cache import EncodingCache
from tactbench.runner.execution.entries import load_encoding
root, go = sys.argv[1], Path(sys.argv[2])
while not go.exists():
    time.sleep(0.001)
cache = EncodingCache(root)
seqs = [np.full((10, 4, 64, 64), i, np.float32) for i in range(24)]
cache.write("k", seqs, {"pid": __import__("os").getpid()})
loaded, meta = load_encoding(cache.path("k"))
print(sum(zlib.crc32(np.asarray(s).tobytes()) for s in loaded), meta["pid"])
"""


def test_two_processes_writing_one_key_both_use_the_winners_entry(tmp_path):
    import subprocess
    import sys

    go = tmp_path / "go"
    procs = [subprocess.Popen([sys.executable, "-c", RACER, str(tmp_path / "c"), str(go)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    go.touch()
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [err for _, err in outs]
    (crc, winner), (crc2, winner2) = [out.split() for out, _ in outs]
    assert crc == crc2 and winner == winner2  # one entry, read by both
    assert winner in {str(p.pid) for p in procs}
    cache = EncodingCache(tmp_path / "c")
    assert [p.name for p in cache.root.iterdir()] == ["k"]  # no temporary left
    assert cache.verify("k")["pid"] == int(winner)


SLOW_WRITER = """
import sys, time
import numpy as np
from tactbench.encoders.encoding import Storage
from tactbench.runner.execution.cache import EncodingCache
cache = EncodingCache(sys.argv[1])
with cache.entry("k", [1] * 1000, (3,), Storage.for_channels("float32", 1)) as w:
    for _ in range(1000):
        w.append(np.zeros((1, 3), np.float32))
        time.sleep(0.05)
"""


def _dead_pid() -> int:
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_writer_killed_mid_write_leaves_an_orphan_that_the_next_run_removes(
        tmp_path, tiny_scene):
    import signal
    import subprocess
    import sys
    import time

    cache = EncodingCache(tmp_path / "c")
    proc = subprocess.Popen([sys.executable, "-c", SLOW_WRITER, str(cache.root)])
    deadline = time.time() + 60
    while time.time() < deadline and not cache.temporaries():
        time.sleep(0.02)
    (live,) = cache.temporaries()
    assert (live["key"], live["pid"], live["state"]) == ("k", proc.pid, "in progress")
    assert cache.clean() == [] and cache.clear() == 0  # a running writer's folder is kept
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    (orphan,) = cache.temporaries()
    assert (orphan["key"], orphan["pid"], orphan["state"]) == ("k", proc.pid, "orphaned")
    assert cache.entries() == []  # not an entry
    # the next run removes it before anything else
    p = plan(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0]))
    ensure_encodings(p, cache, p.cells)
    assert cache.temporaries() == [] and [e["state"] for e in cache.entries()] == ["ok"]


def test_clear_removes_entries_and_orphans_but_not_a_running_writers_folder(tmp_path):
    from tactbench.paths import host_tag

    cache = EncodingCache(tmp_path)
    cache.write("k", [np.zeros((2, 3), np.float32)], {})
    dead = tmp_path / f".k2.tmp-{_dead_pid()}-{host_tag()}-0a1b2c3d"
    running = tmp_path / f".k3.tmp-{__import__('os').getpid()}-{host_tag()}-0a1b2c3d"
    legacy = tmp_path / ".k4.tmp-x1y2z3_q"  # named by tactbench before pids were recorded
    for folder in (dead, running, legacy):
        folder.mkdir()
        (folder / "frames.npy").write_bytes(b"12345")
    states = {t["key"]: t["state"] for t in cache.temporaries()}
    assert states == {"k2": "orphaned", "k3": "in progress", "k4": "orphaned"}
    assert cache.clear() == 3
    assert [p.name for p in tmp_path.iterdir()] == [running.name]
