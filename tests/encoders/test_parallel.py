"""encode_all: every sequence encoded, in order, on several workers, with progress."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.encoders.farneback import Farneback
from tactbench.encoders.parallel import encode_all, encode_chunks
from tactbench.encoders.simple import FrameDiff
from tactbench.encoders.evaluation.conformance import contact_sequence


@pytest.fixture(scope="module")
def sequences():
    # different lengths and sizes, as in a real dataset
    return [contact_sequence((16 + 4 * (i % 3), 20), 2 + i % 4, shift=1.0, seed=i)
            for i in range(7)]


@pytest.mark.parametrize("mode, workers", [("serial", 1), ("threads", 2), ("threads", None)])
def test_results_match_one_by_one_encoding_in_order(sequences, mode, workers):
    enc = Farneback()
    calls = []
    out = encode_all(enc, sequences, workers=workers, mode=mode,
                     progress=lambda done, total: calls.append((done, total)))
    assert len(out) == len(sequences)
    for seq, got in zip(sequences, out):
        np.testing.assert_array_equal(got, enc.encode(seq))
    assert calls[0] == (0, 7) and calls[-1] == (7, 7)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_processes_give_the_same_results(sequences):
    enc = FrameDiff()
    out = encode_all(enc, sequences[:3], workers=2, mode="processes")
    for seq, got in zip(sequences, out):
        np.testing.assert_array_equal(got, enc.encode(seq))


def test_a_bad_sequence_is_named(sequences):
    bad = list(sequences)
    bad[4] = np.full((2, 5, 5), np.nan, np.float32)
    with pytest.raises(ValueError, match="sequence 4"):
        encode_all(FrameDiff(), bad, workers=2)


def test_library_threads_are_restored(sequences):
    import cv2

    before = cv2.getNumThreads()
    encode_all(Farneback(), sequences[:2], workers=2)
    assert cv2.getNumThreads() == before


def test_arguments_are_checked():
    assert encode_all(FrameDiff(), []) == []
    with pytest.raises(ValueError, match="mode"):
        encode_all(FrameDiff(), [], mode="gpu")
    with pytest.raises(ValueError, match="workers"):
        encode_all(FrameDiff(), [np.zeros((1, 2, 2), np.float32)], workers=0)


# ------------------------------------------------------------------ encode_chunks


def _chunks(sequences, sizes):
    start = 0
    for n in sizes:
        yield sequences[start:start + n]
        start += n


@pytest.mark.parametrize("mode, workers", [("serial", 1), ("threads", 2)])
def test_chunks_come_back_in_order_encoded_by_every_encoder(sequences, mode, workers):
    encoders = {"farneback": Farneback(), "frame-diff": FrameDiff()}
    calls = []
    got = list(encode_chunks(encoders, _chunks(sequences, [3, 1, 3]), workers=workers,
                             mode=mode, total=7,
                             progress=lambda done, total, encoder: calls.append(
                                 (encoder, done, total))))
    assert [c.start for c in got] == [0, 3, 4]
    for name, enc in encoders.items():
        out = [seq for chunk in got for seq in chunk.encoded[name]]
        assert len(out) == len(sequences)
        for seq, encoded in zip(sequences, out):
            np.testing.assert_array_equal(encoded, enc.encode(seq))
        assert [d for e, d, _ in calls if e == name] == list(range(1, 8))
        assert all(c.cpu_seconds[name] >= 0 for c in got)
    assert sum(c.cpu_seconds["farneback"] for c in got) > 0


def test_chunks_are_read_one_ahead_of_the_one_handed_back(sequences):
    pulled = []

    def chunks():
        for k in range(5):
            pulled.append(k)
            yield sequences[k:k + 1]

    stream = encode_chunks({"d": FrameDiff()}, chunks(), workers=2, ahead=1)
    first = next(stream)
    assert first.start == 0 and pulled == [0, 1]  # chunk 1 queued while 0 is handed back
    assert [c.start for c in stream] == [1, 2, 3, 4]


def test_a_bad_sequence_in_a_stream_is_named_by_its_place_in_the_stream(sequences):
    bad = list(sequences[:4])
    bad[3] = np.full((2, 5, 5), np.nan, np.float32)
    with pytest.raises(ValueError, match="sequence 3"):
        list(encode_chunks({"d": FrameDiff()}, _chunks(bad, [2, 2]), workers=2))
    with pytest.raises(ValueError, match="ahead"):
        list(encode_chunks({"d": FrameDiff()}, [], ahead=-1))
