"""Recording, Frame: the contract of raw taxel values over time."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.recording import Frame, Recording


def test_recording_converts_and_iterates():
    rec = Recording(np.arange(6).reshape(3, 2), [0.0, 0.1, 0.2], np.array([5, 6], np.int32))
    assert rec.values.dtype == np.float32 and rec.timestamps.dtype == np.float64
    assert rec.taxel_ids.dtype == np.int64
    assert (rec.n_frames, rec.n_taxels) == (3, 2) and rec.duration == pytest.approx(0.2)
    frames = list(rec.frames())
    assert isinstance(frames[1], Frame) and frames[1].timestamp == pytest.approx(0.1)
    ts, values = frames[2]  # frames are (timestamp, values) tuples too
    assert values.tolist() == [4, 5]


@pytest.mark.parametrize("kwargs, message", [
    (dict(values=np.zeros(3), timestamps=[0], taxel_ids=[1]), "shape \\(T, N\\)"),
    (dict(values=np.zeros((0, 2)), timestamps=[], taxel_ids=[1, 2]), "T, N ≥ 1"),
    (dict(values=np.zeros((2, 2)), timestamps=[0.0], taxel_ids=[1, 2]), "timestamps must have"),
    (dict(values=np.zeros((2, 2)), timestamps=[0.1, 0.0], taxel_ids=[1, 2]), "go backwards"),
    (dict(values=np.zeros((2, 2)), timestamps=[0, np.nan], taxel_ids=[1, 2]), "finite"),
    (dict(values=np.zeros((2, 2)), timestamps=[0, 1], taxel_ids=[1, 1]), "duplicate taxel"),
    (dict(values=np.zeros((2, 2)), timestamps=[0, 1], taxel_ids=[1.5, 2]), "integers"),
    (dict(values=np.array([[0, np.inf], [0, 0]]), timestamps=[0, 1], taxel_ids=[1, 2]),
     "infinite values .first at frame 0, taxel column 1"),
])
def test_bad_recordings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Recording(**kwargs)


def test_nan_marks_a_missing_reading():
    rec = Recording(np.array([[1, np.nan]]), [0.0], [1, 2])
    assert np.isnan(rec.values[0, 1])
