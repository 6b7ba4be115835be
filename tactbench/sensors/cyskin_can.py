"""The ``cyskin-can`` sensor: CySkin sweeps read from any python-can interface.

Frames are :class:`tactbench.can.assembler.Sweep` objects: ``timestamp`` (s,
the bus clock, time of the sweep's last message) and ``values`` float32
``(N,)`` raw 16-bit counts in the order of ``taxel_ids``, plus ``sequence``,
``missing`` and ``label`` (the label marker in force, if any).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from tactbench.can.assembler import SweepAssembler
from tactbench.can.bus import open_bus
from tactbench.can.busload import BusLoad, bus_load
from tactbench.can.codec import MAX_TAXELS, FrameFormat, TaxelMap
from tactbench.can.meta import META_PREFIX, MetaAssembler, is_meta
from tactbench.data.layout_io import load_layout
from tactbench.errors import InputError, check_number


def parse_taxel_ids(spec: Any) -> np.ndarray:
    """Taxel ids from an array, a list, or text: ``"0,1,2"``, ``"0-10,16-26"``.

    Text may name at most :data:`~tactbench.can.codec.MAX_TAXELS` ids (what one bus
    carries); a range beyond that (``0-99999999999``) is refused before it is expanded.
    """
    if isinstance(spec, (list, tuple, np.ndarray)):
        try:
            return np.asarray(spec, dtype=np.int64)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"taxel ids must be integers (0 to 2**63-1), got "
                             f"{_short(spec)}") from None
    if isinstance(spec, (int, np.integer)) and not isinstance(spec, bool):
        spec = str(int(spec))
    ranges: list[tuple[int, int]] = []
    total = 0
    for item in str(spec).replace(";", ",").replace(" ", ",").split(","):
        if not item:
            continue
        lo, dash, hi = item.partition("-")
        try:
            first, last = int(lo), int(hi) if dash else int(lo)
        except ValueError:
            raise InputError(f"bad taxel id item {_short(item)} in {_short(spec)}: expected "
                             f"N or N-M") from None
        if not 0 <= first <= last <= _ID_MAX:
            raise InputError(f"bad taxel id item {_short(item)}: " + (
                f"the range {first}-{last} is empty (N-M needs N ≤ M)" if first > last
                else "taxel ids must be 0 to 2**63-1"))
        total += last - first + 1
        if total > MAX_TAXELS:
            raise InputError(f"taxel ids {_short(spec)} name more than {MAX_TAXELS} taxels, "
                             f"the most a CAN bus carries (4096 modules × 16 slots)")
        ranges.append((first, last))
    return np.asarray([k for first, last in ranges for k in range(first, last + 1)],
                      dtype=np.int64)


_ID_MAX = int(np.iinfo(np.int64).max)


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value) if not isinstance(value, str) else f"'{value}'"
    return text if len(text) <= limit else text[:limit] + "…"


def resolve_taxel_ids(taxel_ids: Any = None, layout: Any = None) -> np.ndarray:
    """Ids from ``taxel_ids`` or a layout (a file path or an object with ``.ids``)."""
    if (taxel_ids is None) == (layout is None):
        raise InputError("cyskin-can needs exactly one of taxel_ids (\"0-10,16-26\") or "
                         "layout (a layout file)")
    if taxel_ids is not None:
        return parse_taxel_ids(taxel_ids)
    if isinstance(layout, (str, Path)):
        layout = load_layout(layout)
    return np.asarray(layout.ids, dtype=np.int64)


class CySkinCAN:
    """Read CySkin sweeps from a CAN bus.

    Parameters
    ----------
    interface : str
        python-can interface (``virtual``, ``socketcan``, ``pcan``, ...).
    channel : str
        Interface channel (``vcan0``, ``PCAN_USBBUS1``; any name for ``virtual``).
    bitrate : int
        Nominal bitrate in bit/s (passed to the interface; used for bus load).
    taxel_ids : str or sequence of int, optional
        The taxels, e.g. ``"0-10,16-26"``; or give ``layout``.
    layout : str or TaxelLayout, optional
        Layout file (its ids are the taxels).
    format : str
        Frame format spec, ``"ids=standard,base_id=0x200,fd=true"`` (see
        :class:`~tactbench.can.codec.FrameFormat`); or ``format_file``, a JSON file.
    data_bitrate : int, optional
        CAN FD data-phase bitrate.
    rate_hz : float
        Expected sweep rate (for the bus-load figure only).
    missing : {"hold", "nan", "zero"}
        Rule for taxels of lost messages.
    window : int
        Sweeps assembled at once (reordering tolerance).
    flush_after : float
        Seconds of silence after which an incomplete sweep is emitted anyway.
    idle_timeout : float, optional
        Stop ``frames()`` after this many seconds without any message (``None``: wait forever).
    max_sweeps : int, optional
        Stop after this many sweeps.
    """

    def __init__(self, *, interface: str = "virtual", channel: str = "tactbench",
                 bitrate: int = 1_000_000, taxel_ids: Any = None, layout: Any = None,
                 format: str = "", format_file: str | None = None,
                 data_bitrate: int | None = None, rate_hz: float = 10.0,
                 missing: str = "hold", window: int = 2, flush_after: float = 0.15,
                 idle_timeout: float | None = None, max_sweeps: int | None = None,
                 receive_own_messages: bool = False) -> None:
        fmt = FrameFormat.parse(format, format_file)
        if isinstance(layout, (str, Path)):
            layout = load_layout(layout)
        self.layout = layout  # the TaxelLayout when given one (see contracts.SENSOR)
        self.taxel_map = TaxelMap(resolve_taxel_ids(taxel_ids, layout), fmt)
        self.taxel_ids = self.taxel_map.taxel_ids
        self.assembler = SweepAssembler(self.taxel_map, missing=missing, window=window)
        self.bitrate, self.data_bitrate, self.rate_hz = bitrate, data_bitrate, rate_hz

        self.flush_after = check_number(flush_after, "flush_after", minimum=0)
        # NaN never compares: a NaN timeout would never end
        self.idle_timeout = None if idle_timeout is None else check_number(
            idle_timeout, "idle_timeout", minimum=0, exclusive_minimum=True)
        self.max_sweeps = None if max_sweeps is None else check_number(
            max_sweeps, "max_sweeps", minimum=1, integer=True)
        check_number(rate_hz, "rate_hz", minimum=0, exclusive_minimum=True)
        check_number(bitrate, "bitrate", minimum=1, integer=True)
        self.label: str | None = None
        self._meta = MetaAssembler()
        self._closed = threading.Event()
        # Hardware filters: only this format's data ids and tactbench's meta frames.
        if fmt.ids == "extended":
            filters = [{"can_id": fmt.prefix << 24, "can_mask": 0x1F000000, "extended": True}]
        else:
            filters = [{"can_id": 0, "can_mask": 0, "extended": False}]
        filters.append({"can_id": META_PREFIX << 24, "can_mask": 0x1F000000, "extended": True})
        self.bus = open_bus(interface, channel, bitrate=bitrate, data_bitrate=data_bitrate,
                            fd=fmt.fd, receive_own_messages=receive_own_messages,
                            can_filters=filters, who="cyskin-can")

    # ------------------------------------------------------------------ info
    @property
    def stats(self):
        return self.assembler.stats

    def bus_load(self) -> BusLoad:
        return bus_load(self.taxel_map, bitrate=self.bitrate, rate_hz=self.rate_hz,
                        data_bitrate=self.data_bitrate)

    # ------------------------------------------------------------------ stream
    def frames(self) -> Iterator[Any]:
        """Sweeps as they complete, until closed, idle for ``idle_timeout``, or ``max_sweeps``."""
        emitted = 0
        last_msg = time.monotonic()
        poll = min(0.05, self.flush_after)
        while not self._closed.is_set():
            try:
                msg = self.bus.recv(timeout=poll)
            except Exception:
                if self._closed.is_set():  # closed from another thread
                    break
                raise
            now = time.monotonic()
            if msg is None:
                out = []
                if now - last_msg >= self.flush_after:
                    out = self.assembler.flush()
                done = self.idle_timeout is not None and now - last_msg >= self.idle_timeout
            else:
                last_msg = now
                done = False
                if is_meta(msg):
                    event = self._meta.feed(msg)
                    if event is not None and event.kind == "label_start":
                        self.label = str(event.info["label"])
                    elif event is not None and event.kind == "label_end":
                        self.label = None
                    continue
                out = self.assembler.feed(msg)
            for sweep in out:
                sweep.label = self.label
                yield sweep
                emitted += 1
                if self.max_sweeps is not None and emitted >= self.max_sweeps:
                    return
            if done:
                return

    def close(self) -> None:
        if not self._closed.is_set():
            self._closed.set()
            self.bus.shutdown()

    def __enter__(self) -> "CySkinCAN":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"CySkinCAN({self.bus.channel_info}, taxels={self.taxel_ids.size}, "
                f"format={self.taxel_map.fmt})")
