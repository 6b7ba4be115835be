"""Windows of L frames: how sequences become training and test examples.

The study's protocol (test window ``first``):

- training: every window of ``L`` consecutive frames of every training
  sequence (a sequence shorter than ``L`` gives one window, padded);
- testing: only the first ``L`` frames of each test sequence;
- padding: blank (all-zero) frames appended after the sequence's end.

Testing on the first frames assumes that recordings start at contact. Where they start
before it, as the built-in simulator's (version 2) and many real sets' do, two other test
windows are offered, and ``vote`` is the runner's default. A test window is a small
strategy object registered through the hook ``register_test_windows`` (the built-ins:
:mod:`tactbench.data.strategies`); this module holds the windows they are made of:

- ``onset``: the ``L`` frames from the contact onset, :func:`onset_frame`: the first
  frame whose total pressure (the sum of the normalised taxel values) reaches
  :data:`ONSET_FRACTION` of that recording's peak total pressure (frame 0 for a
  recording without pressure); the window is moved back to end at the last frame when
  fewer than ``L`` frames follow the onset. Training then uses the windows starting at
  or after each training sequence's own onset window, so that it sees what tests see;
- ``vote``: every window of the test sequence is classified and the class
  probabilities are averaged (training unchanged). It is the default because it is the
  one window that held up on every set measured (docs/reports/which-window.md): far
  above ``first`` where recordings start before contact, and not told apart from it
  where they start at contact; ``onset`` loses to ``first`` on a real set whose contact
  begins before its recordings do.

A :class:`Windows` holds the sequences once and the window positions, so the
many overlapping training windows share memory; :meth:`Windows.batch`
materialises a batch ``(B, L, *frame_shape)`` on demand. The sequences may be
arrays or *stored sequences* (:func:`tactbench.runner.execution.entries.load_encoding`: anything
with ``shape`` and slicing that reads frames from disk on demand): a batch then reads
only its windows' frames, so memory is O(batch), whatever the dataset's size. A batch
is estimated (windows × L × frame) before it is allocated, and one above the memory
budget is refused (:func:`tactbench.budget.check_budget`): ``L`` is the user's, and
``L = 1000`` over 27-frame sequences would otherwise allocate mostly padding.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tactbench.budget import check_budget
from tactbench.errors import ContractError, InputError, check_positive_int


@dataclass(frozen=True)
class Windows:
    """Windows of ``L`` frames over ``sequences``.

    ``sequences[i]`` is float32 ``(T_i, *frame_shape)`` (``(T, C, H, W)`` for
    images, ``(T, N)`` for taxel vectors), an array or a stored sequence (only
    ``shape`` and ``seq[a:b]`` are used); window ``j`` starts at frame
    ``starts[j]`` of sequence ``seq_index[j]`` and has label ``labels[j]``.
    """

    sequences: Sequence[np.ndarray]
    seq_index: np.ndarray  # (B,) int64
    starts: np.ndarray  # (B,) int64
    labels: np.ndarray  # (B,) int64
    L: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "L", check_positive_int(self.L, "window length L"))
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
        check_budget(4 * len(idx) * self.L * frame,
                     f"a batch of {len(idx)} windows of L={self.L} frames "
                     f"{self.frame_shape}")
        out = np.zeros((len(idx), self.L, *self.frame_shape), dtype=np.float32)
        for row, j in enumerate(idx):
            seq = self.sequences[self.seq_index[j]]
            start = int(self.starts[j])
            chunk = seq[start:start + self.L]
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


def check_windows(windows: "Windows", name: str, *, every: bool = False) -> "Windows":
    """``windows`` if each starts inside its recording (``0 ≤ start < T``: a window
    starting past the end would score padding) and, with ``every``, every recording has
    at least one (a test recording without a window would be predicted as nothing, and
    scored as class 0). Raises :class:`~tactbench.errors.ContractError` naming ``name``."""
    n = len(windows.sequences)
    si, st = np.asarray(windows.seq_index), np.asarray(windows.starts)
    if si.size and (si.min() < 0 or si.max() >= n):
        raise ContractError(f"{name} names a recording outside the {n} it was given")
    lengths = np.array([s.shape[0] for s in windows.sequences], dtype=np.int64)
    if si.size and ((st < 0) | (st >= lengths[si])).any():
        bad = int(np.flatnonzero((st < 0) | (st >= lengths[si]))[0])
        raise ContractError(f"{name} starts a window at frame {int(st[bad])} of a "
                            f"recording of {int(lengths[si[bad]])} frames")
    if every and len(np.unique(si)) != n:
        raise ContractError(f"{name} gives {n - len(np.unique(si))} of its {n} test "
                            f"recordings no window: each must be classified")
    return windows


def training_windows(sequences: Sequence[np.ndarray], labels: Sequence[int],
                     L: int) -> Windows:
    """Every ``L``-frame window of every sequence (one padded window if shorter)."""
    labels_arr = _check(sequences, labels)
    seq_index, starts = [], []
    for i, seq in enumerate(sequences):
        n = max(1, seq.shape[0] - L + 1)
        seq_index.append(np.full(n, i, dtype=np.int64))
        starts.append(np.arange(n, dtype=np.int64))
    si = np.concatenate(seq_index) if seq_index else np.zeros(0, np.int64)
    st = np.concatenate(starts) if starts else np.zeros(0, np.int64)
    return Windows(list(sequences), si, st, labels_arr[si], L)


def test_windows(sequences: Sequence[np.ndarray], labels: Sequence[int],
                 L: int) -> Windows:
    """The first ``L`` frames of each sequence, padded with blank frames."""
    labels_arr = _check(sequences, labels)
    n = len(sequences)
    return Windows(list(sequences), np.arange(n, dtype=np.int64), np.zeros(n, np.int64),
                   labels_arr, L)


test_windows.__test__ = False  # not a pytest test, despite the name

#: The test window of rows and cell identities that name none: the study's, the only one
#: before test windows existed. A cell identity leaves it out, so that keys made then stay
#: valid; a run's default is :class:`tactbench.runner.execution.scene.Scene`'s ``test_window``.
UNNAMED_TEST_WINDOW = "first"
#: Contact onset: the first frame whose total pressure reaches this fraction of the peak
#: (both above the recording's quietest frame).
ONSET_FRACTION = 0.1


def onset_frame(pressure: np.ndarray, fraction: float = ONSET_FRACTION) -> int:
    """The first frame whose total pressure reaches ``fraction`` of the recording's peak,
    both measured from its quietest frame (the sensor's noise floor, summed over many
    taxels, is not contact).

    ``pressure`` is the recording's normalised values ``(T, N)`` (or already summed,
    ``(T,)``); NaN (a missing reading) counts as 0. A recording without any pressure has
    its onset at frame 0.
    """
    p = np.asarray(pressure, dtype=np.float64)
    total = np.nansum(p.reshape(p.shape[0], -1), axis=1) if p.ndim > 1 else np.nan_to_num(p)
    total = total - total.min() if total.size else total
    peak = float(total.max()) if total.size else 0.0
    if not peak > 0:
        return 0
    return int(np.argmax(total >= fraction * peak))


def window_starts(n_frames: Sequence[int], L: int, onsets: Sequence[int]) -> np.ndarray:
    """Start of each sequence's onset window: its onset, moved back so that the window
    ends at the last frame when fewer than ``L`` frames follow (never before 0)."""
    n = np.asarray(n_frames, dtype=np.int64)
    on = np.asarray(onsets, dtype=np.int64)
    return np.maximum(0, np.minimum(on, n - int(L))).astype(np.int64)


def onset_test_windows(sequences: Sequence[np.ndarray], labels: Sequence[int], L: int,
                       onsets: Sequence[int]) -> Windows:
    """One window per sequence, from its onset window (:func:`window_starts`)."""
    labels_arr = _check(sequences, labels)
    if len(onsets) != len(sequences):
        raise ValueError("onset test windows need one onset per sequence")  # a bug
    starts = window_starts([s.shape[0] for s in sequences], L, onsets)
    return Windows(list(sequences), np.arange(len(sequences), dtype=np.int64), starts,
                   labels_arr, L)


def onset_training_windows(sequences: Sequence[np.ndarray], labels: Sequence[int], L: int,
                           onsets: Sequence[int]) -> Windows:
    """Every window starting at or after its sequence's onset window."""
    windows = training_windows(sequences, labels, L)
    if len(onsets) != len(sequences):
        raise ValueError("onset training windows need one onset per sequence")  # a bug
    first = window_starts([s.shape[0] for s in sequences], L, onsets)
    keep = windows.starts >= first[windows.seq_index]
    return Windows(windows.sequences, windows.seq_index[keep], windows.starts[keep],
                   windows.labels[keep], L)


def dataset_onsets(dataset) -> tuple[int, ...]:
    """:func:`onset_frame` of every sample of a :class:`~tactbench.data.dataset.Dataset`,
    on its normalised values (one recording at a time)."""
    return tuple(onset_frame(dataset.normalise(s.recording.values)) for s in dataset.samples)
