"""encode_all: every sequence encoded, in order, on several workers, with progress."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.encoders.farneback import Farneback
from tactbench.encoders.parallel import encode_all
from tactbench.encoders.simple import FrameDiff
from tactbench.encoders.testing import contact_sequence


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
