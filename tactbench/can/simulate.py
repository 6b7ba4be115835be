"""Play recordings as CySkin CAN traffic: on a live bus at the sensor's rate, or into a log.

:func:`traffic` turns samples into a time-ordered schedule of message bursts
(one burst per sweep, framed by label markers, led by a taxel-map
announcement); :func:`play` sends a schedule on a python-can bus in real time
(or faster), :func:`schedule_messages` stamps it for writing straight to a log.
The 8-bit sweep counter runs on across samples, like a real sensor's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from tactbench.can.codec import TaxelMap, encode_sweep
from tactbench.can.meta import marker_messages, taxel_map_messages
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

    A sample's integer label becomes its class name when ``classes`` is given.
    """
    rec = getattr(sample, "recording", sample)
    values = np.asarray(getattr(rec, "values", rec), dtype=np.float32)
    if values.ndim != 2:
        raise InputError(f"a sample's values must be (T, N), got shape {values.shape}")
    ts = getattr(rec, "timestamps", None)
    ts = (np.arange(len(values)) / rate_hz if ts is None
          else np.asarray(ts, dtype=np.float64))
    info = None
    label = getattr(sample, "label", None)
    if label is not None:
        info = {}
        if classes is not None and isinstance(label, (int, np.integer)):
            info["class_index"] = int(label)  # keeps the dataset's class order in a log
            label = classes[int(label)]
        info["label"] = str(label)
        for key in ("user", "position", "repetition", "source"):
            value = getattr(sample, key, None)
            if value is not None and value != "":
                info[key] = value if isinstance(value, (int, float)) else str(value)
    return SimSample(values, ts, info)


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
