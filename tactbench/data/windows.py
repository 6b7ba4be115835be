"""Windows of L frames: how sequences become training and test examples.

The study's protocol:

- training: every window of ``L`` consecutive frames of every training
  sequence (a sequence shorter than ``L`` gives one window, padded);
- testing: only the first ``L`` frames of each test sequence;
- padding: blank (all-zero) frames appended after the sequence's end.

A :class:`Windows` holds the sequences once and the window positions, so the
many overlapping training windows share memory; :meth:`Windows.batch`
materialises a batch ``(B, L, *frame_shape)`` on demand. The sequences may be
arrays or *stored sequences* (:func:`tactbench.runner.cache.load_encoding`: anything
with ``shape`` and slicing that reads frames from disk on demand): a batch then reads
only its windows' frames, so memory is O(batch), whatever the dataset's size. A batch
is estimated (windows × L × frame) before it is allocated, and one above the memory
budget is refused (:func:`tactbench.integrity.check_budget`): ``L`` is the user's, and
``L = 1000`` over 27-frame sequences would otherwise allocate mostly padding.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tactbench.errors import InputError, check_positive_int
from tactbench.integrity import check_budget


@dataclass(frozen=True)
class Windows:
    """Windows of ``length`` frames over ``sequences``.

    ``sequences[i]`` is float32 ``(T_i, *frame_shape)`` (``(T, C, H, W)`` for
    images, ``(T, N)`` for taxel vectors), an array or a stored sequence (only
    ``shape`` and ``seq[a:b]`` are used); window ``j`` starts at frame
    ``starts[j]`` of sequence ``seq_index[j]`` and has label ``labels[j]``.
    """

    sequences: Sequence[np.ndarray]
    seq_index: np.ndarray  # (B,) int64
    starts: np.ndarray  # (B,) int64
    labels: np.ndarray  # (B,) int64
    length: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "length", check_positive_int(self.length, "window length L"))
        if not (len(self.seq_index) == len(self.starts) == len(self.labels)):
            # built by training_windows / test_windows: a mismatch is a bug, not an input
            raise ValueError("seq_index, starts and labels must have the same length")
        shapes = {s.shape[1:] for s in self.sequences}
        if len(shapes) > 1:
            raise InputError(f"sequences have different frame shapes: {sorted(shapes)}")

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def frame_shape(self) -> tuple[int, ...]:
        return tuple(self.sequences[0].shape[1:]) if self.sequences else ()

    def batch(self, index: Sequence[int] | np.ndarray | slice) -> np.ndarray:
        """Windows ``index`` as float32 ``(B, L, *frame_shape)``, zero-padded past the end."""
        idx = np.arange(len(self))[index] if isinstance(index, slice) else np.asarray(index)
        frame = int(np.prod(self.frame_shape, dtype=np.int64)) if self.frame_shape else 1
        check_budget(4 * len(idx) * self.length * frame,
                     f"a batch of {len(idx)} windows of L={self.length} frames "
                     f"{self.frame_shape}")
        out = np.zeros((len(idx), self.length, *self.frame_shape), dtype=np.float32)
        for row, j in enumerate(idx):
            seq = self.sequences[self.seq_index[j]]
            start = int(self.starts[j])
            chunk = seq[start:start + self.length]
            out[row, :len(chunk)] = chunk
        return out

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """All windows and labels at once: ``(B, L, *frame_shape)``, ``(B,)`` (O(dataset)
        memory: for small sets and tests; training and prediction read in batches)."""
        return self.batch(slice(None)), self.labels.copy()


def _check(sequences: Sequence[np.ndarray], labels: Sequence[int]) -> np.ndarray:
    if len(sequences) != len(labels):
        raise InputError(f"{len(sequences)} sequences but {len(labels)} labels")
    for i, seq in enumerate(sequences):
        if seq.ndim < 2 or seq.shape[0] == 0:
            raise InputError(f"sequence {i} has shape {seq.shape}; expected (T, ...) with T ≥ 1")
    return np.asarray(labels, dtype=np.int64)


def training_windows(sequences: Sequence[np.ndarray], labels: Sequence[int],
                     length: int) -> Windows:
    """Every ``length``-frame window of every sequence (one padded window if shorter)."""
    labels_arr = _check(sequences, labels)
    seq_index, starts = [], []
    for i, seq in enumerate(sequences):
        n = max(1, seq.shape[0] - length + 1)
        seq_index.append(np.full(n, i, dtype=np.int64))
        starts.append(np.arange(n, dtype=np.int64))
    si = np.concatenate(seq_index) if seq_index else np.zeros(0, np.int64)
    st = np.concatenate(starts) if starts else np.zeros(0, np.int64)
    return Windows(list(sequences), si, st, labels_arr[si], length)


def test_windows(sequences: Sequence[np.ndarray], labels: Sequence[int],
                 length: int) -> Windows:
    """The first ``length`` frames of each sequence, padded with blank frames."""
    labels_arr = _check(sequences, labels)
    n = len(sequences)
    return Windows(list(sequences), np.arange(n, dtype=np.int64), np.zeros(n, np.int64),
                   labels_arr, length)


test_windows.__test__ = False  # not a pytest test, despite the name
