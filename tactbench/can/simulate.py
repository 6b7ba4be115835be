"""Play recordings as CySkin CAN traffic: on a live bus at the sensor's rate, or into a log.

:func:`load_samples` reads what to play (a dataset or a CAN log);
:func:`traffic` turns samples into a time-ordered schedule of message bursts
(one burst per sweep, framed by label markers, led by a taxel-map
announcement); :func:`play` sends a schedule on a python-can bus in real time
(or faster), :func:`schedule_messages` stamps it for writing straight to a log.
:func:`send_samples` and :func:`write_samples` do the whole job of
``tactbench can simulate`` (on a bus, or into a log).
The 8-bit sweep counter runs on across samples, like a real sensor's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from tactbench.can.codec import TaxelMap, encode_sweep
from tactbench.can.logs import is_can_log, read_log, write_log
from tactbench.can.meta import is_meta, marker_messages, taxel_map_messages
from tactbench.data.recording import Recording, Sample
from tactbench.datasets.loading import load_dataset
from tactbench.errors import InputError


@dataclass(frozen=True)
class SimSample:
    """What the simulator plays: values ``(T, N)``, timestamps ``(T,)`` s, marker info."""

    values: np.ndarray
    timestamps: np.ndarray
    info: dict[str, Any] | None = None


def as_sim_sample(sample: Any, rate_hz: float = 10.0,
                  classes: Any = None) -> SimSample:
    """Accept a :class:`tactbench.data.recording.Sample`, a ``Recording``, or a ``(T, N)`` array.

    A sample's label, user, position, repetition and source become the marker info
    (its integer label becomes the class name, and ``class_index``, when ``classes``
    is given). A bare array is timed at ``rate_hz`` (sweeps per second) and unlabelled.
    """
    info = None
    if isinstance(sample, Sample):
        label: Any = sample.label
        info = {}
        if classes is not None and isinstance(label, (int, np.integer)):
            info["class_index"] = int(label)  # keeps the dataset's class order in a log
            label = classes[int(label)]
        info["label"] = str(label)
        for key in ("user", "position", "repetition", "source"):
            value = getattr(sample, key)
            if value is not None and value != "":
                info[key] = value if isinstance(value, (int, float)) else str(value)
        sample = sample.recording
    if isinstance(sample, Recording):
        values = np.asarray(sample.values, dtype=np.float32)
        ts = np.asarray(sample.timestamps, dtype=np.float64)
    else:
        values = np.asarray(sample, dtype=np.float32)
        if values.ndim != 2:
            raise InputError(f"a sample's values must be (T, N), got shape {values.shape}")
        ts = np.arange(len(values)) / rate_hz
    return SimSample(values, ts, info)


def load_samples(source: str, *, rate_hz: float = 10.0) -> tuple[list[SimSample], np.ndarray]:
    """What to play from ``source``: the samples and their taxel ids int ``(N,)``.

    ``source`` is a CAN log (its labelled segments, or its unlabelled stretches when it
    has no markers; the log's taxel ids) or anything
    :func:`tactbench.datasets.loading.load_dataset` reads (a dataset folder, CySkin
    text, a registered spec such as ``synthetic-forearm:users=2``; the recordings'
    taxel ids, in the order of their values). ``rate_hz`` times samples without
    timestamps.
    """
    if is_can_log(source):
        log = read_log(source)
        segments = log.labelled or log.segments
        return [SimSample(s.values, s.timestamps, s.info) for s in segments], log.taxel_ids

    dataset = load_dataset(source)
    samples = [as_sim_sample(s, rate_hz, dataset.classes) for s in dataset.samples]
    return samples, np.asarray(dataset.taxel_ids, dtype=np.int64)


def traffic(samples: Iterable[Any], taxels: TaxelMap, *, rate_hz: float = 10.0,
            gap_s: float = 0.5, markers: bool = True, announce: bool = True,
            counter_start: int = 0) -> Iterator[tuple[float, list]]:
    """Bursts ``(t, messages)`` with ``t`` in seconds from the start, in time order.

    Each sample's sweeps keep their own spacing (its timestamps); samples follow
    each other ``gap_s`` apart. A labelled sample is framed by start/end markers
    when ``markers`` is set; ``announce`` sends the taxel map first.
    """
    period = 1.0 / rate_hz
    t = 0.0
    counter = counter_start
    seq = 0
    if announce:
        yield t, taxel_map_messages(taxels.taxel_ids, seq)
        seq += 1
    for raw in samples:
        sample = raw if isinstance(raw, SimSample) else as_sim_sample(raw, rate_hz)
        if sample.values.shape[1] != taxels.n_taxels:
            raise InputError(f"sample has {sample.values.shape[1]} taxels, "
                             f"the layout {taxels.n_taxels}")
        if markers and sample.info is not None:
            yield t, marker_messages(True, sample.info, seq)
        offsets = sample.timestamps - sample.timestamps[0] if len(sample.timestamps) else []
        for k, dt in enumerate(offsets):
            yield t + float(dt), encode_sweep(sample.values[k], taxels, counter)
            counter += 1
        end = t + (float(offsets[-1]) if len(offsets) else 0.0)
        if markers and sample.info is not None:
            # Just after the last sweep, before the next one would be due.
            yield end + period / 2, marker_messages(False, sample.info, seq)
        seq += 1
        t = end + period + gap_s


def schedule_messages(bursts: Iterable[tuple[float, list]], *, t0: float = 0.0) -> Iterator:
    """Messages stamped with their scheduled time ``t0 + t`` (for writing a log directly)."""
    for t, msgs in bursts:
        for msg in msgs:
            msg.timestamp = t0 + t
            yield msg


def play(bus: Any, bursts: Iterable[tuple[float, list]], *, speed: float = 1.0,
         should_stop: Callable[[], bool] | None = None,
         on_burst: Callable[[float, list], None] | None = None) -> int:
    """Send ``bursts`` on ``bus`` at their times divided by ``speed``; returns messages sent.

    ``speed=0`` sends as fast as the bus takes them. Messages are stamped with
    the wall-clock time they are sent.
    """
    if speed < 0:
        raise InputError(f"speed must be ≥ 0, got {speed}")
    start = time.perf_counter()
    wall0 = time.time()
    sent = 0
    for t, msgs in bursts:
        if should_stop is not None and should_stop():
            break
        if speed > 0:
            delay = start + t / speed - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        for msg in msgs:
            msg.timestamp = wall0 + (time.perf_counter() - start)
            bus.send(msg)
            sent += 1
        if on_burst is not None:
            on_burst(t, msgs)
    return sent


def _sweep_counter(progress: Callable[..., None] | None,
                   ) -> Callable[[float, list], None] | None:
    """An ``on_burst`` for :func:`play` that reports sweeps sent (not markers)."""
    if progress is None:
        return None
    done = 0

    def on_burst(_t: float, msgs: list) -> None:
        nonlocal done
        if msgs and not is_meta(msgs[0]):  # a sweep, not a marker or taxel map
            done += 1
            progress(done)

    return on_burst


def send_samples(bus: Any, samples: list[SimSample], taxels: TaxelMap, *,
                 rate_hz: float = 10.0, gap_s: float = 0.5, markers: bool = True,
                 speed: float = 1.0, loop: bool = False,
                 should_stop: Callable[[], bool] | None = None,
                 progress: Callable[..., None] | None = None) -> int:
    """Play ``samples`` on ``bus`` as CySkin traffic (see :func:`traffic`, :func:`play`).

    ``speed`` divides the samples' times (0: as fast as the bus takes them); ``loop``
    starts again after the last sample until ``should_stop()`` is true or Ctrl-C.
    ``progress(sweeps_sent)`` is called after each sweep (from 1 again on each loop).
    Returns the number of messages sent. A ``KeyboardInterrupt`` propagates.
    """
    if speed < 0:
        raise InputError(f"speed must be ≥ 0, got {speed}")
    sent = 0
    while True:
        sent += play(bus, traffic(samples, taxels, rate_hz=rate_hz, gap_s=gap_s,
                                  markers=markers),
                     speed=speed, should_stop=should_stop, on_burst=_sweep_counter(progress))
        if not loop or (should_stop is not None and should_stop()):
            return sent


def write_samples(path: str | Path, samples: list[SimSample], taxels: TaxelMap, *,
                  rate_hz: float = 10.0, gap_s: float = 0.5, markers: bool = True,
                  t0: float | None = None) -> int:
    """Write ``samples`` as CySkin traffic straight into the log ``path``, stamped from
    ``t0`` (s, default now); returns the number of messages written."""
    bursts = traffic(samples, taxels, rate_hz=rate_hz, gap_s=gap_s, markers=markers)
    return write_log(path, schedule_messages(bursts, t0=time.time() if t0 is None else t0))
