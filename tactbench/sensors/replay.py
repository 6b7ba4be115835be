"""Sensor ``replay``: plays a recorded sample as a stream of frames.

``path`` is anything :func:`tactbench.datasets.loading.load_dataset` reads (a
dataset folder, a CySkin text file or folder, a CoST CSV, or a registered
dataset spec such as ``synthetic-forearm:users=2``); ``sample`` picks the
recording. Frames come as :class:`tactbench.data.recording.Frame`
``(timestamp, values)`` with timestamps as recorded, values float32 ``(N,)``
in raw sensor units (NaN = missing reading). With ``realtime=True`` each frame
is released at its recorded time after the first (``time.monotonic`` pacing);
otherwise as fast as the consumer takes them.
"""

from __future__ import annotations

import time
from typing import Iterator

import numpy as np

from tactbench.data.recording import Frame, Recording
from tactbench.errors import InputError


class Replay:
    """Replay one recording (see the module docstring).

    Parameters
    ----------
    path
        Dataset path or spec.
    sample
        Index of the sample to play (0-based).
    realtime
        Pace frames by their timestamps.
    loop
        Start again after the last frame (timestamps keep increasing).
    """

    def __init__(self, path: str, sample: int = 0, realtime: bool = False,
                 loop: bool = False) -> None:
        from tactbench.datasets.loading import load_dataset

        dataset = load_dataset(path)
        if isinstance(sample, bool) or not isinstance(sample, int) \
                or not 0 <= sample < len(dataset):
            raise InputError(f"sample {sample!r} is out of range: {path} has {len(dataset)} "
                             f"samples (0..{len(dataset) - 1})")
        self.dataset = dataset
        self.sample = dataset[sample]
        self.recording: Recording = self.sample.recording
        self.taxel_ids: np.ndarray = self.recording.taxel_ids
        self.layout = dataset.layout
        self.realtime = bool(realtime)
        self.loop = bool(loop)
        self._closed = False

    @classmethod
    def from_recording(cls, recording: Recording, *, realtime: bool = False,
                       loop: bool = False) -> "Replay":
        """A replay of a recording already in memory."""
        self = cls.__new__(cls)
        self.dataset = None
        self.sample = None
        self.recording = recording
        self.taxel_ids = recording.taxel_ids
        self.layout = None
        self.realtime, self.loop, self._closed = bool(realtime), bool(loop), False
        return self

    def frames(self) -> Iterator[Frame]:
        rec = self.recording
        period = float(np.median(np.diff(rec.timestamps))) if rec.n_frames > 1 else 0.1
        shift = 0.0
        start_wall = time.monotonic()
        start_ts = float(rec.timestamps[0])
        while not self._closed:
            for k in range(rec.n_frames):
                if self._closed:
                    return
                ts = float(rec.timestamps[k]) + shift
                if self.realtime:
                    delay = (ts - start_ts) - (time.monotonic() - start_wall)
                    if delay > 0:
                        time.sleep(delay)
                yield Frame(ts, rec.values[k].copy())
            if not self.loop:
                return
            shift += rec.duration + period

    def __iter__(self) -> Iterator[Frame]:
        return self.frames()

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> "Replay":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
