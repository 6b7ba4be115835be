"""Sensor ``replay``: plays recorded data as a stream of frames — the one way to replay.

``path`` is anything :func:`tactbench.datasets.loading.load_dataset` reads (a
dataset folder, a CySkin text file or folder, a CoST CSV, a CAN log, or a
registered dataset spec such as ``synthetic-forearm:users=2``).

- **A CAN log** (``.blf``, ``.asc``, ``.log``, ``.trc``) plays as the bus carried it:
  every sweep of every segment, in order (``sample=k`` plays only the log's sample
  ``k``, numbered as in :meth:`tactbench.can.logs.CanLog.to_dataset`). Frames are
  :class:`tactbench.can.assembler.Sweep` objects: ``timestamp`` (s, the log's clock),
  ``values`` float32 ``(N,)`` raw counts in the order of ``taxel_ids``, ``missing``
  (taxels not received in that sweep) and ``label`` (the label marker in force, or
  ``None``). The taxel ids come from ``taxel_ids``, else the log's announcement, else
  the traffic (see :func:`tactbench.can.logs.read_log`).
- **Anything else** plays one sample (``sample``, default 0). Frames are
  :class:`tactbench.data.recording.Frame` ``(timestamp, values)`` with timestamps as
  recorded, values float32 ``(N,)`` in raw sensor units (NaN = missing reading).

With ``realtime=True`` each frame is released at its recorded time after the first
(``time.monotonic`` pacing); otherwise as fast as the consumer takes them. With
``loop=True`` the stream starts again after its last frame, timestamps increasing.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Iterator

import numpy as np

from tactbench.can.codec import FrameFormat
from tactbench.can.logs import LOG_SUFFIXES, is_can_log, read_log
from tactbench.data.recording import Frame, Recording
from tactbench.datasets.loading import load_dataset
from tactbench.errors import InputError
from tactbench.sensors.cyskin_can import parse_taxel_ids


class Replay:
    """Replay a recording or a CAN log (see the module docstring).

    Parameters
    ----------
    path : str
        Dataset path or spec, CySkin text, CoST CSV or CAN log.
    sample : int, optional
        Index of the sample to play (0-based); default: sample 0, or for a CAN log
        every sweep of the log.
    realtime : bool
        Pace frames by their timestamps.
    loop : bool
        Start again after the last frame (timestamps keep increasing).
    taxel_ids : array-like of int, optional
        CAN logs only: the layout's taxel ids (default: announced in the log, else
        inferred from the traffic).
    format : str or FrameFormat
        CAN logs only: the data frames' format spec (``"ids=standard;base_id=0x200"``,
        see :class:`~tactbench.can.codec.FrameFormat`); or ``format_file``, a JSON file.
    missing : {"hold", "nan", "zero"}
        CAN logs only: rule for taxels of lost messages.
    """

    def __init__(self, path: str, sample: int | None = None, realtime: bool = False,
                 loop: bool = False, *, taxel_ids: Any = None, format: Any = "",
                 format_file: str | None = None, missing: str = "hold") -> None:
        self.realtime = bool(realtime)
        self.loop = bool(loop)
        self._closed = False
        self.log = None
        self.dataset = None
        self.sample = None
        self.recording: Recording | None = None
        self.layout = None
        if is_can_log(path):
            fmt = (format if isinstance(format, FrameFormat)
                   else FrameFormat.parse(format, format_file))
            ids = None if taxel_ids is None else parse_taxel_ids(taxel_ids)
            self.log = read_log(path, taxel_ids=ids, fmt=fmt, missing=missing)
            self.taxel_ids: np.ndarray = self.log.taxel_ids
            self._sample_index = sample
            next(self.log.iter_sweeps(sample), None)  # a bad sample index fails here, not later
            return
        if taxel_ids is not None or format or format_file or missing != "hold":
            raise InputError(f"{path}: taxel_ids, format, format_file and missing apply to "
                             f"CAN logs ({', '.join(_can_suffixes())}) only")

        dataset = load_dataset(path)
        sample = 0 if sample is None else sample
        if isinstance(sample, bool) or not isinstance(sample, int) \
                or not 0 <= sample < len(dataset):
            raise InputError(f"sample {sample!r} is out of range: {path} has {len(dataset)} "
                             f"samples (0..{len(dataset) - 1})")
        self.dataset = dataset
        self.sample = dataset[sample]
        self.recording = self.sample.recording
        self.taxel_ids = self.recording.taxel_ids
        self.layout = dataset.layout

    @classmethod
    def from_recording(cls, recording: Recording, *, realtime: bool = False,
                       loop: bool = False) -> "Replay":
        """A replay of a recording already in memory."""
        self = cls.__new__(cls)
        self.log = self.dataset = self.sample = self.layout = None
        self.recording = recording
        self.taxel_ids = recording.taxel_ids
        self.realtime, self.loop, self._closed = bool(realtime), bool(loop), False
        return self

    # ------------------------------------------------------------------ stream
    def _one_pass(self) -> Iterator[Any]:
        """The frames once through, with their recorded timestamps."""
        if self.log is not None:
            yield from self.log.iter_sweeps(self._sample_index)
            return
        rec = self.recording
        for k in range(rec.n_frames):
            yield Frame(float(rec.timestamps[k]), rec.values[k].copy())

    def frames(self) -> Iterator[Any]:
        """Frames in time order until the end (or forever with ``loop``) or :meth:`close`."""
        shift = 0.0  # added to the timestamps of each later pass, so time keeps going
        sequence = 0
        start_wall = time.monotonic()
        start_ts: float | None = None
        while not self._closed:
            stamps = []
            for frame in self._one_pass():
                if self._closed:
                    return
                stamps.append(frame.timestamp)
                ts = frame.timestamp + shift
                if start_ts is None:
                    start_ts = ts
                if self.realtime:
                    delay = (ts - start_ts) - (time.monotonic() - start_wall)
                    if delay > 0:
                        time.sleep(delay)
                if shift:
                    frame = _restamped(frame, ts, sequence)
                sequence += 1
                yield frame
            if not self.loop or not stamps:
                return
            period = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 0.1
            shift += stamps[-1] - stamps[0] + period

    def __iter__(self) -> Iterator[Any]:
        return self.frames()

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> "Replay":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        what = f"CAN log {self.log.path}" if self.log is not None else "recording"
        return f"Replay({what}, taxels={self.taxel_ids.size}, realtime={self.realtime})"


def _restamped(frame: Any, timestamp: float, sequence: int) -> Any:
    """``frame`` at ``timestamp`` (a later pass of a loop); sweeps keep counting."""
    if isinstance(frame, Frame):
        return Frame(timestamp, frame.values)

    return dataclasses.replace(frame, timestamp=timestamp, first_timestamp=timestamp,
                               sequence=sequence, counter=sequence % 256)


def _can_suffixes() -> tuple[str, ...]:
    return LOG_SUFFIXES
