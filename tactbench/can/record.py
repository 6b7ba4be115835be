"""Recording a CAN bus to a log, with tactbench's label markers and taxel map around it.

:func:`record` is what ``tactbench can record`` runs: every message the bus delivers
goes into the log (``.blf``, ``.asc``, ...), optionally after a taxel-map announcement
and between a label start and end marker, so :func:`tactbench.can.logs.read_log` (and
the ``replay`` sensor) read the recording back as labelled sweeps.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

from tactbench.can.busload import frame_bits
from tactbench.can.logs import open_writer
from tactbench.can.meta import marker_messages, taxel_map_messages
from tactbench.errors import check_number

#: Seconds between two calls of the ``progress`` callback (a bus carries thousands of
#: messages per second; drawing each would cost more than receiving it).
PROGRESS_EVERY_S = 0.25


@dataclass
class Recorded:
    """What :func:`record` wrote.

    ``messages`` received from the bus, ``meta_messages`` written by tactbench
    (taxel map, markers), ``seconds`` of wall time, ``bus_load_measured`` the fraction
    of the bus the received frames took at nominal frame lengths (``None`` for an
    empty time span), ``stopped`` why it ended: ``"duration"``, ``"idle"``,
    ``"max_messages"`` or ``"interrupted"`` (Ctrl-C).
    """

    out: str
    messages: int
    meta_messages: int
    seconds: float
    label: str | None
    bus_load_measured: float | None
    stopped: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _write_all(writer: Any, messages: Any) -> int:
    """Write ``messages`` to the log; returns how many."""
    count = 0
    for msg in messages:
        writer.on_message_received(msg)
        count += 1
    return count


def _receive(bus: Any, writer: Any, *, bitrate: int, data_bitrate: int | None) -> float | None:
    """Write the next message ``bus`` receives (waiting up to 50 ms) to the log; returns
    its nominal bit times (0 for an error frame), or None when none came."""
    msg = bus.recv(timeout=0.05)
    if msg is None:
        return None
    # A log holds one bus. python-can's BLF writer turns a channel *name* into a number
    # from its trailing digits ("rec-912345" → 912345) and fails above 65535, so the name
    # is not written.
    msg.channel = None
    writer.on_message_received(msg)
    if msg.is_error_frame:
        return 0.0
    return frame_bits(min(len(msg.data), 64 if msg.is_fd else 8), extended=msg.is_extended_id,
                      fd=msg.is_fd, bitrate=bitrate, data_bitrate=data_bitrate)


def _stop_reason(elapsed: float, idle: float, messages: int, *, duration: float | None,
                 idle_timeout: float | None, max_messages: int | None) -> str | None:
    """Why a recording stops now (``"duration"``, ``"idle"``, ``"max_messages"``), or
    None to go on."""
    if duration is not None and elapsed >= duration:
        return "duration"
    if idle_timeout is not None and idle >= idle_timeout:
        return "idle"
    if max_messages is not None and messages >= max_messages:
        return "max_messages"
    return None


def record(bus: Any, out: str | Path, *, duration: float | None = None,
           idle_timeout: float | None = None, max_messages: int | None = None,
           label: dict[str, Any] | None = None, taxel_ids: Any = None,
           bitrate: int = 1_000_000, data_bitrate: int | None = None,
           progress: Callable[..., None] | None = None) -> Recorded:
    """Write what ``bus`` receives to the log ``out`` until a stop condition.

    Parameters
    ----------
    bus : can.BusABC
        An open python-can bus (see :func:`tactbench.can.bus.open_bus`); not closed here.
    out : str or Path
        The log file; its suffix picks the format (``.blf``, ``.asc``, ``.log``, ``.trc``).
    duration, idle_timeout : float, optional
        Stop after ``duration`` seconds, or after ``idle_timeout`` seconds without a
        message. ``max_messages`` stops after that many messages. With none of them it
        records until Ctrl-C (``KeyboardInterrupt``), which ends the recording normally
        (``stopped="interrupted"``): the log is closed with its end marker.
    label : dict, optional
        Marker info (``{"label": "Grasp", "user": "u07", ...}``): a start marker is
        written before the first message and an end marker after the last.
    taxel_ids : array-like of int, optional
        Announced in the log first (a taxel-map meta message).
    bitrate, data_bitrate : int
        Bit/s, for the measured bus load.
    progress : callable, optional
        ``progress(messages, max_messages, seconds=...)``, at most every
        :data:`PROGRESS_EVERY_S` seconds and once at the end.
    """
    for value, name in ((duration, "duration"), (idle_timeout, "idle_timeout")):
        if value is not None:  # NaN never compares: a NaN limit would never stop
            check_number(value, name, minimum=0, exclusive_minimum=True)
    if max_messages is not None:
        check_number(max_messages, "max_messages", minimum=1, integer=True)
    writer = open_writer(out)
    n = meta = 0
    bits = 0.0  # nominal bit times of the data frames received (for the measured load)
    t_start = time.time()
    stopped = "interrupted"
    try:
        if taxel_ids is not None:
            meta += _write_all(writer, taxel_map_messages(taxel_ids, 0, timestamp=t_start))
        if label is not None:
            meta += _write_all(writer, marker_messages(True, label, 1, timestamp=t_start))
        start = last = shown = time.monotonic()
        while True:
            now = time.monotonic()
            stop = _stop_reason(now - start, now - last, n, duration=duration,
                                idle_timeout=idle_timeout, max_messages=max_messages)
            if stop is not None:
                stopped = stop
                break
            if progress is not None and now - shown >= PROGRESS_EVERY_S:
                progress(n, max_messages, seconds=now - start)
                shown = now
            received = _receive(bus, writer, bitrate=bitrate, data_bitrate=data_bitrate)
            if received is not None:
                last = time.monotonic()
                n += 1
                bits += received
    except KeyboardInterrupt:
        stopped = "interrupted"  # the normal end of an open-ended recording
    finally:
        if label is not None:
            meta += _write_all(writer, marker_messages(False, label, 1, timestamp=time.time()))
        writer.stop()
    seconds = time.time() - t_start
    if progress is not None:
        progress(n, n if max_messages is None else max_messages, seconds=seconds)
    return Recorded(out=str(out), messages=n, meta_messages=meta, seconds=seconds,
                    label=None if label is None else str(label["label"]),
                    bus_load_measured=bits / bitrate / seconds if seconds > 0 else None,
                    stopped=stopped)
