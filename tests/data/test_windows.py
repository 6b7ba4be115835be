"""Training and test windows of L frames (the study's protocol)."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.data.windows import Windows, test_windows, training_windows


def seqs():
    # sequence i has T = 3 + i frames; frame t of sequence i is filled with 10*i + t + 1
    return [np.stack([np.full((2, 2), 10 * i + t + 1, np.float32) for t in range(3 + i)])
            for i in range(3)]


def test_training_windows_are_every_window_of_L():
    w = training_windows(seqs(), [0, 1, 2], 3)
    assert len(w) == 1 + 2 + 3
    x, y = w.arrays()
    assert x.shape == (6, 3, 2, 2) and x.dtype == np.float32
    np.testing.assert_array_equal(y, [0, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(x[2, :, 0, 0], [12, 13, 14])  # second window of seq 1


def test_short_sequence_gives_one_padded_window():
    w = training_windows(seqs(), [0, 1, 2], 5)
    assert len(w) == 3
    x = w.batch([0])
    np.testing.assert_array_equal(x[0, :, 0, 0], [1, 2, 3, 0, 0])  # blank frames appended


def test_test_windows_take_the_first_L_frames():
    w = test_windows(seqs(), [4, 5, 6], 4)
    x, y = w.arrays()
    np.testing.assert_array_equal(y, [4, 5, 6])
    np.testing.assert_array_equal(x[:, :, 0, 0], [[1, 2, 3, 0], [11, 12, 13, 14],
                                                  [21, 22, 23, 24]])


def test_taxel_vectors_work_too():
    w = training_windows([np.ones((4, 7), np.float32)], [1], 2)
    assert w.frame_shape == (7,) and w.batch(slice(None)).shape == (3, 2, 7)


@pytest.mark.parametrize("make, match", [
    (lambda: training_windows(seqs(), [0, 1], 2), "3 sequences but 2 labels"),
    (lambda: training_windows(seqs(), [0, 1, 2], 0), "L must be ≥ 1"),
    (lambda: training_windows([np.zeros((0, 2), np.float32)], [0], 2), "T ≥ 1"),
    (lambda: Windows([np.zeros((2, 2)), np.zeros((2, 3))], np.zeros(0, int),
                     np.zeros(0, int), np.zeros(0, int), 1), "different frame shapes"),
])
def test_bad_input_is_named(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_mismatched_index_arrays_are_a_bug_not_a_user_error():
    from tactbench.errors import TactbenchError

    with pytest.raises(ValueError, match="must have the same length") as info:
        Windows(seqs(), np.zeros(2, int), np.zeros(1, int), np.zeros(2, int), 2)
    assert not isinstance(info.value, TactbenchError)


class SliceOnly:
    """A stored sequence as the runner's cache gives it: ``shape``, ``ndim`` and slices, nothing
    more; it records the frames each read asked for."""

    def __init__(self, array, reads):
        self.array, self.reads, self.shape, self.ndim = array, reads, array.shape, array.ndim

    def __len__(self):
        return self.shape[0]

    def __getitem__(self, index):
        assert isinstance(index, slice)
        self.reads.append(index.indices(len(self))[:2])
        return self.array[index].copy()


def test_a_batch_reads_only_its_windows_frames_from_stored_sequences():
    reads = []
    lazy = [SliceOnly(s, reads) for s in seqs()]
    w = training_windows(lazy, [0, 1, 2], 3)
    np.testing.assert_array_equal(w.batch([5, 2]), training_windows(seqs(), [0, 1, 2], 3)
                                  .batch([5, 2]))
    assert reads == [(2, 5), (1, 4)]  # window 5: frames 2..4 of seq 2; window 2: 1..3 of seq 1


def test_a_batch_of_windows_above_the_memory_budget_is_refused_before_it_allocates(
        monkeypatch, memory_cap):
    """L = 1000 over sequences of ≤ 5 frames is almost all padding: a batch is estimated
    (windows × L × frame) and refused before the zeros are allocated."""
    from tactbench.errors import BudgetError

    big = [np.zeros((5, 64, 64), np.float32) for _ in range(3)]
    w = training_windows(big, [0, 1, 2], 1000)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "16")
    with memory_cap(4):
        with pytest.raises(BudgetError, match=r"a batch of 3 windows of L=1000 frames "
                                              r"\(64, 64\) would need about 46\.9 MiB, more "
                                              r"than the memory budget of 16\.0 MiB"):
            w.arrays()
    assert w.batch([0]).shape == (1, 1000, 64, 64)  # 15.6 MiB: within the budget


# ----------------------------------------------------------------- test windows


def test_onset_is_the_first_frame_reaching_a_tenth_of_the_peak():
    from tactbench.data.windows import onset_frame

    pressure = np.zeros((8, 3))
    pressure[3] = [0.01, 0.0, 0.0]  # 2 % of the peak: noise, not contact
    pressure[4] = [0.05, 0.05, 0.0]  # 20 %
    pressure[6] = [0.2, 0.2, 0.1]  # the peak, 0.5
    assert onset_frame(pressure) == 4
    assert onset_frame(pressure, fraction=0.5) == 6
    assert onset_frame(np.zeros((5, 3))) == 0  # no contact at all
    with_nan = pressure.copy()
    with_nan[1, 0] = np.nan
    assert onset_frame(with_nan) == 4
    assert onset_frame(pressure + 0.3) == 4  # a noise floor is not contact


def test_each_test_window_picks_its_frames_and_combines_its_predictions():
    from tactbench.data.windows import window_starts
    from tactbench.plugins import load_registry

    registry = load_registry()
    first, onset, vote = (registry.build("test-window", n) for n in ("first", "onset", "vote"))
    seqs = [np.arange(10, dtype=np.float32)[:, None] * np.ones((1, 2), np.float32),
            np.arange(4, dtype=np.float32)[:, None] * np.ones((1, 2), np.float32)]
    labels = [0, 1]
    onsets = [6, 3]
    # the onset window moves back to end at the last frame; never before frame 0
    assert window_starts([10, 4], 3, onsets).tolist() == [6, 1]
    assert window_starts([10, 2], 3, [9, 1]).tolist() == [7, 0]
    assert first.test(seqs, labels, 3).starts.tolist() == [0, 0]
    at_onset = onset.test(seqs, labels, 3, prepared=onsets)
    assert at_onset.starts.tolist() == [6, 1]
    np.testing.assert_array_equal(at_onset.batch(np.arange(2))[0, :, 0], [6, 7, 8])
    every = vote.test(seqs, labels, 3)
    assert every.seq_index.tolist() == [0] * 8 + [1] * 2
    train = onset.training(seqs, labels, 3, prepared=onsets)
    assert list(zip(train.seq_index.tolist(), train.starts.tolist())) == \
        [(0, 6), (0, 7), (1, 1)]
    assert len(vote.training(seqs, labels, 3)) == len(first.training(seqs, labels, 3)) == 10

    class Model:  # predicts class 1 for a window starting at frame ≥ 3, else 0
        def predict(self, windows):
            return (windows.starts >= 3).astype(int)

        def predict_proba(self, windows):
            p = (windows.starts >= 3).astype(float)
            return np.stack([1 - p, p], axis=1)

    assert first.combine(Model(), first.test(seqs, labels, 3), 2).tolist() == [0, 0]
    assert onset.combine(Model(), at_onset, 2).tolist() == [1, 0]
    # vote: 5 of sequence 0's 8 windows start at frame ≥ 3, none of sequence 1's 2
    assert vote.combine(Model(), every, 2).tolist() == [1, 0]
    from tactbench.contracts import TEST_WINDOW

    assert TEST_WINDOW.get(first, "prepare") is None and TEST_WINDOW.get(vote, "prepare") is None
    assert callable(TEST_WINDOW.get(onset, "prepare"))
