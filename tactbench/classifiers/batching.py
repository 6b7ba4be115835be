"""Window batching for the torch classifiers: frames prepared once, or read per batch.

A fit draws batches of windows ``(B, L, *frame)`` in one of two ways, which give the same
batches: from a :class:`FrameBank` (every frame of the training sequences prepared once
and held, when it fits :func:`bank_budget_bytes`), or read from the sequences and prepared
per batch (:class:`WindowBatches`, with :func:`loader_workers` processes reading ahead).
:func:`training_batches` chooses. Overlapping windows can share frames
(:func:`window_runs`, :func:`share_frames`, :func:`shares_at_inference`), and
:func:`read_windows` reads any windows in bounded sub-batches. torch is imported inside
the functions that use it.
"""

from __future__ import annotations

import math
import os
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from tactbench.data.windows import Windows
from tactbench.errors import InputError, check_positive_int

#: The largest :class:`FrameBank` (every training frame prepared once and held for the
#: whole fit), in bytes: a budget that does not grow with the dataset. Above it, windows
#: are read from the sequences and prepared per batch (:class:`WindowBatches`), so a fit's
#: memory is O(min(dataset, budget) + batch + model). ``$TACTBENCH_BANK_MIB`` overrides
#: it (``0``: always per batch); the results are the same either way.
BANK_BUDGET_BYTES = 512 * 2 ** 20
#: Raw (unprepared) frames read from the sequences at once, in bytes: a batch is read
#: in sub-batches of at most this size, each prepared (resized) before the next is read.
READ_CHUNK_BYTES = 64 * 2 ** 20


def frame_index(windows: Windows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each window's frames lie in the sequences laid end to end, with one blank
    frame after them: ``(lengths (S,), offsets (S + 1,), index (B, L))``; ``offsets[-1]``
    is the number of frames, and the index of a frame past its sequence's end is that
    number (the blank frame)."""
    lengths = np.array([s.shape[0] for s in windows.sequences], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    pos = windows.starts[:, None] + np.arange(windows.L, dtype=np.int64)[None, :]
    index = offsets[windows.seq_index][:, None] + pos
    index[pos >= lengths[windows.seq_index][:, None]] = offsets[-1]
    return lengths, offsets, index


class FrameBank:
    """Every frame of a :class:`Windows`' sequences, prepared once, as one tensor.

    Overlapping training windows share frames (a sequence of ``T`` frames gives
    ``T - L + 1`` windows of ``L``), so resizing each frame once instead of once per
    window saves ~``L``× the work. ``frames[-1]`` is the blank padding frame.
    """

    def __init__(self, windows: Windows, prepare, *, dtype=None) -> None:
        import torch

        seqs = windows.sequences
        lengths, offsets, index = frame_index(windows)
        first = prepare(torch.from_numpy(np.ascontiguousarray(seqs[0][:1], dtype=np.float32)))
        bank = torch.zeros((int(offsets[-1]) + 1, *first.shape[1:]), dtype=dtype or first.dtype)
        # Each sequence is read in chunks of at most READ_CHUNK_BYTES raw frames.
        step = frames_per_chunk(windows.frame_shape)
        for i, seq in enumerate(seqs):
            for a in range(0, int(lengths[i]), step):
                b = min(int(lengths[i]), a + step)
                chunk = torch.from_numpy(np.ascontiguousarray(seq[a:b], dtype=np.float32))
                bank[offsets[i] + a:offsets[i] + b] = prepare(chunk)
        self.frames = bank
        self.index = torch.from_numpy(index)
        self.labels = torch.from_numpy(np.asarray(windows.labels, dtype=np.int64))

    @staticmethod
    def nbytes(windows: Windows, prepared_shape: tuple[int, ...]) -> int:
        """Bytes of the bank of ``windows`` with frames of ``prepared_shape`` (float32)."""
        total = sum(s.shape[0] for s in windows.sequences) + 1
        return total * int(np.prod(prepared_shape)) * 4

    def to(self, device) -> "FrameBank":
        self.frames = self.frames.to(device)
        self.index = self.index.to(device)
        self.labels = self.labels.to(device)
        return self

    def batch(self, idx: np.ndarray):
        import torch

        sel = torch.as_tensor(np.ascontiguousarray(idx), dtype=torch.int64,
                              device=self.index.device)
        return self.frames[self.index[sel]], self.labels[sel]

    def shared_batch(self, idx: np.ndarray):
        """Windows ``idx`` as :class:`~tactbench.classifiers.nets.SharedWindows` (each
        distinct frame once, in bank order) and their labels."""
        import torch

        from tactbench.classifiers.nets import SharedWindows

        sel = torch.as_tensor(np.ascontiguousarray(idx), dtype=torch.int64,
                              device=self.index.device)
        distinct, inverse = torch.unique(self.index[sel], return_inverse=True)
        return SharedWindows(self.frames[distinct], inverse), self.labels[sel]


def window_runs(windows: Windows, run: int | None = None) -> np.ndarray:
    """A run number per window for ``shared_features``: windows of one sequence whose
    starts lie in the same ``[k·run, k·run + run)`` share a run (``run`` defaults to
    ``L``: then a run's windows overlap in up to ``L - 1`` frames and span at most
    ``2L - 1``)."""
    run = max(1, int(windows.L if run is None else run))
    keys = np.stack([windows.seq_index, windows.starts // run], axis=1)
    return np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)


def share_frames(windows: Windows, idx: np.ndarray, x):
    """A read batch ``x`` ``(B, L, *frame)`` of windows ``idx`` as
    :class:`~tactbench.classifiers.nets.SharedWindows`: the same distinct frames in the
    same order as :meth:`FrameBank.shared_batch` (by sequence, then position; the
    blank padding frame last)."""
    import torch

    from tactbench.classifiers.nets import SharedWindows

    idx = np.asarray(idx)
    lengths = np.array([s.shape[0] for s in windows.sequences], dtype=np.int64)
    stride = int(lengths.max()) + 1
    pos = windows.starts[idx][:, None] + np.arange(windows.L, dtype=np.int64)[None, :]
    seq = windows.seq_index[idx][:, None]
    keys = np.where(pos < lengths[seq], seq * stride + pos, len(lengths) * stride)
    _, first, inverse = np.unique(keys.reshape(-1), return_index=True, return_inverse=True)
    flat = x.reshape(x.shape[0] * x.shape[1], *x.shape[2:])
    return SharedWindows(flat[torch.from_numpy(first)],
                         torch.from_numpy(inverse.reshape(keys.shape).astype(np.int64)))


def bank_budget_bytes() -> int:
    """The frame-bank budget in bytes: ``$TACTBENCH_BANK_MIB`` (MiB) when set, else
    :data:`BANK_BUDGET_BYTES`."""
    text = os.environ.get("TACTBENCH_BANK_MIB", "").strip()
    if not text:
        return BANK_BUDGET_BYTES
    try:
        mib = float(text)
    except ValueError:
        mib = -1.0
    if not (math.isfinite(mib) and mib >= 0):  # inf, nan: no number of bytes
        raise InputError(f"TACTBENCH_BANK_MIB must be a finite number of MiB ≥ 0 (unset: "
                         f"{BANK_BUDGET_BYTES // 2 ** 20}), got {text!r}")
    return int(mib * 2 ** 20)


def frames_per_chunk(frame_shape: Sequence[int], frames_per_item: int = 1) -> int:
    """How many items of ``frames_per_item`` raw float32 frames fit in READ_CHUNK_BYTES
    (at least one)."""
    item = 4 * frames_per_item * int(np.prod(frame_shape, dtype=np.int64))
    return max(1, READ_CHUNK_BYTES // max(item, 1))


def shares_at_inference(windows: Windows | np.ndarray, net: Any) -> bool:
    """Whether prediction on ``windows`` encodes each distinct frame once: windows that
    overlap (two of one sequence, ``L`` ≥ 2) on a :class:`~tactbench.classifiers.nets.
    SequenceNet` (a plugin's own network need not accept
    :class:`~tactbench.classifiers.nets.SharedWindows`). One window per sequence
    (``first``, ``onset``) keeps the plain path."""
    from tactbench.classifiers.nets import SequenceNet

    return (isinstance(windows, Windows) and windows.L >= 2 and isinstance(net, SequenceNet)
            and len(np.unique(windows.seq_index)) < len(windows))


def read_windows(windows: Windows | np.ndarray, index: np.ndarray | slice,
                 prepare: Callable[[Any], Any] | None = None):
    """Windows ``index`` as one float32 tensor ``(B, L, *prepared frame)``.

    ``windows`` is a :class:`Windows` (frames read from its sequences on demand) or an
    array ``(N, L, *frame_shape)``. Raw frames are read in sub-batches of at most
    :data:`READ_CHUNK_BYTES`, and each sub-batch is passed through ``prepare``
    (``(n, *frame_shape)`` → ``(n, *prepared)``, e.g. the network's resize) before the
    next is read: the memory is the prepared batch plus one raw sub-batch. Past a
    sequence's end, frames are blank (zero) before ``prepare``.
    """
    import torch

    idx = np.arange(len(windows))[index] if isinstance(index, slice) else np.asarray(index)
    length = windows.L if isinstance(windows, Windows) else windows.shape[1]
    frame_shape = windows.frame_shape if isinstance(windows, Windows) else windows.shape[2:]
    step = frames_per_chunk(frame_shape, length)
    out = None
    for lo in range(0, len(idx), step):
        part = idx[lo:lo + step]
        raw = (windows.batch(part) if isinstance(windows, Windows)
               else np.ascontiguousarray(windows[part], dtype=np.float32))
        x = torch.from_numpy(raw)
        if prepare is not None:
            b = x.shape[0]
            x = prepare(x.reshape(b * length, *x.shape[2:]))
            x = x.reshape(b, length, *x.shape[1:])
        if out is None:
            if len(part) == len(idx):
                return x
            out = torch.empty((len(idx), *x.shape[1:]), dtype=x.dtype)
        out[lo:lo + len(part)] = x
    if out is None:  # no windows asked for
        x = torch.zeros((0, *frame_shape))
        x = prepare(x) if prepare is not None else x
        return x.reshape(0, length, *x.shape[1:])
    return out


class WindowBatches:
    """A map-style torch dataset whose items are whole batches, read lazily.

    ``batches[idx]`` (``idx``: an array of window indices) is ``(x, y)``: ``x`` the
    windows read and prepared by :func:`read_windows`, float32 ``(B, L, *prepared)``,
    and ``y`` their labels, int64 ``(B,)``. Nothing is held but the windows' positions,
    so memory is O(batch) whatever the dataset's size. Give it to
    ``torch.utils.data.DataLoader(batches, batch_size=None, sampler=[idx, ...],
    num_workers=n)`` to read ahead in worker processes.
    """

    def __init__(self, windows: Windows, prepare: Callable[[Any], Any] | None = None) -> None:
        self.windows = windows
        self.prepare = prepare

    def __len__(self) -> int:
        return len(self.windows)

    def __getitem__(self, idx):
        import torch

        idx = np.asarray(idx)
        with torch.no_grad():
            x = read_windows(self.windows, idx, self.prepare)
        return x, torch.from_numpy(np.asarray(self.windows.labels[idx], dtype=np.int64))


def streamed_mean_std(chunks: Iterable[Any]) -> tuple[Any, Any]:
    """Mean and standard deviation over axis 1 (channels, taxels or features) of chunks
    ``(n_i, D, *spatial)`` that are never held together: per-chunk mean and squared
    deviations in float64, merged (Chan et al.); Bessel's correction, like ``torch.std``.
    Returns two float64 tensors ``(D,)``; equal to the whole-array statistics up to
    rounding."""
    import torch

    n, mean, m2 = 0, None, None
    for chunk in chunks:
        x = chunk.double()
        dims = [0] + list(range(2, x.ndim))
        k = x.numel() // x.shape[1] if x.ndim > 1 else 0
        if k == 0:
            continue
        mu = x.mean(dim=dims)
        sq = ((x - mu.reshape(1, -1, *[1] * (x.ndim - 2))) ** 2).sum(dim=dims)
        if mean is None:
            n, mean, m2 = k, mu, sq
            continue
        delta = mu - mean
        mean = mean + delta * (k / (n + k))
        m2 = m2 + sq + delta ** 2 * (n * k / (n + k))
        n += k
    if mean is None:
        raise InputError("no frames to compute statistics from")
    return mean, torch.sqrt(m2 / max(n - 1, 1))


#: At most this many loader processes (more is a typo, and would start that many).
MAX_LOADER_WORKERS = 64


def loader_workers(device) -> int:
    """DataLoader worker processes that read ahead during a per-batch fit:
    ``$TACTBENCH_LOADER_WORKERS`` when set, else 0 on the CPU (where torch's own
    threads already use the cores; see docs/classifiers.md) and up to 4 with CUDA."""
    text = os.environ.get("TACTBENCH_LOADER_WORKERS", "").strip()
    if text:
        try:
            value = int(text)
        except ValueError:
            raise InputError(f"TACTBENCH_LOADER_WORKERS must be an integer ≥ 0, "
                             f"got {text!r}") from None
        return check_positive_int(value, "TACTBENCH_LOADER_WORKERS", minimum=0,
                                  maximum=MAX_LOADER_WORKERS)
    if getattr(device, "type", "cpu") != "cuda":
        return 0
    return max(0, min(4, (os.cpu_count() or 1) - 1))


def training_batches(train: Windows, prepare: Callable[[Any], Any], dev, report, *,
                     share: bool):
    """``(get_batch, load_batches)`` for :func:`.training.train_loop` on device ``dev``.

    From a :class:`FrameBank` of frames prepared once (``prepare``: the network's
    ``(n, *frame) → (n, *prepared)``) when it fits :func:`bank_budget_bytes`, else read
    and prepared per batch (:class:`WindowBatches`, with :func:`loader_workers` processes
    reading ahead). Both give the same batches; ``share``: as
    :class:`~tactbench.classifiers.nets.SharedWindows`. ``report`` (a
    :class:`~tactbench.classifiers.training.FitReport`) records the path taken.
    """
    import torch

    probe = prepare(torch.zeros((1, *train.frame_shape)))
    bank_bytes = FrameBank.nbytes(train, tuple(probe.shape[1:]))
    report.bank_mb = bank_bytes / 2 ** 20
    if bank_bytes <= bank_budget_bytes():
        report.batches = "frame bank"
        with torch.no_grad():
            bank = FrameBank(train, prepare)
        if dev.type == "cuda":
            bank.to(dev)

        def get_batch(idx):
            x, y = bank.shared_batch(idx) if share else bank.batch(idx)
            return x.to(dev, non_blocking=True), y.to(dev, non_blocking=True)
        return get_batch, None
    report.batches = "per batch"
    reader = WindowBatches(train, prepare)
    workers = loader_workers(dev)
    report.loader_workers = workers

    def on_device(idx, x, y):
        if share:
            x = share_frames(train, idx, x)
        return x.to(dev, non_blocking=True), y.to(dev, non_blocking=True)

    def get_read(idx):
        return on_device(idx, *reader[idx])

    if workers == 0:
        return get_read, None

    def load_batches(indices: list[np.ndarray]):
        from torch.utils.data import DataLoader

        # Its own generator: a DataLoader draws a worker seed from the generator it is
        # given, and from the global one (dropout's) without: that would change the model.
        loader = DataLoader(reader, batch_size=None, sampler=indices, num_workers=workers,
                            pin_memory=dev.type == "cuda",
                            generator=torch.Generator().manual_seed(0))
        for idx, (x, y) in zip(indices, loader):
            yield on_device(idx, x, y)
    return get_read, load_batches
