"""CAN messages → complete sweeps, whatever the bus does to them.

A sweep is identified by its 8-bit sequence counter, unwrapped to a running
sequence number. The assembler keeps up to ``window`` sweeps open at once, so
messages may arrive out of order across neighbouring sweeps. A sweep is
emitted

- as soon as every message the layout expects for it has arrived (the usual
  case: the sweep's last message completes it, with no waiting), or
- incomplete, when a newer sweep completes or when more than ``window`` sweeps
  are open (the oldest goes), or on :meth:`SweepAssembler.flush` (end of the
  stream or a receive timeout).

Sweeps always come out in sequence order. A sensor that restarts its counter
(a reset) first looks like a run of late or duplicate messages; after one
sweep's worth of them in a row the assembler resynchronises on the new
counter (counted in ``resyncs``; the sweep during which it notices comes out
incomplete).
Missing taxels (their message was
lost) follow the ``missing`` rule:

``"hold"`` (default)
    the taxel's value in the last emitted sweep that had it; NaN until it has
    been received once;
``"nan"``
    NaN;
``"zero"``
    0.

Everything that is not taxel data of this layout — error frames, remote
frames, other ids, unknown modules, wrong lengths — is counted by reason and
otherwise ignored; no message makes :meth:`SweepAssembler.feed` raise.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator

import numpy as np

from tactbench.can.codec import COUNTER_MODULO, Decoded, TaxelMap, decode_message
from tactbench.errors import InputError

MISSING_RULES = ("hold", "nan", "zero")


@dataclass
class Sweep:
    """One sweep of every taxel.

    Attributes
    ----------
    timestamp : float
        Time of the sweep's last message (seconds, the messages' clock).
    values : np.ndarray
        float32 ``(N,)`` raw 16-bit counts in the layout's taxel order; missing
        taxels follow the assembler's ``missing`` rule.
    sequence : int
        Running sweep number (the 8-bit counter unwrapped; the first is 0 plus
        the first counter seen).
    counter : int
        The 8-bit counter as sent.
    missing : int
        How many taxels were not received (0 for a complete sweep).
    first_timestamp : float
        Time of the sweep's first message.
    label : str or None
        The label marker in force when the sweep arrived (set by readers that
        track markers; ``None`` otherwise).
    """

    timestamp: float
    values: np.ndarray
    sequence: int
    counter: int
    missing: int
    first_timestamp: float
    label: str | None = None

    @property
    def complete(self) -> bool:
        return self.missing == 0


@dataclass
class AssemblerStats:
    """What the assembler saw. ``messages`` = ``accepted`` + ``duplicates`` + ``late``
    + the sum of ``rejected``."""

    messages: int = 0
    accepted: int = 0
    duplicates: int = 0
    late: int = 0  # for a sweep already emitted (or too old to be kept open)
    out_of_order: int = 0  # accepted, but older than a sweep already started
    sweeps: int = 0
    complete_sweeps: int = 0
    incomplete_sweeps: int = 0
    lost_messages: int = 0  # expected messages missing from emitted sweeps
    lost_sweeps: int = 0  # sequence numbers never seen at all
    resyncs: int = 0  # counter restarts followed
    rejected: Counter = field(default_factory=Counter)

    def to_dict(self) -> dict[str, Any]:
        out = {k: v for k, v in self.__dict__.items() if k != "rejected"}
        out["rejected"] = dict(sorted(self.rejected.items()))
        return out


class _Open:
    """A sweep being assembled."""

    __slots__ = ("counts", "received", "n_received", "first", "last")

    def __init__(self, n_taxels: int, n_chunks: int, timestamp: float) -> None:
        self.counts = np.zeros(n_taxels, dtype=np.float32)
        self.received = np.zeros(n_chunks, dtype=bool)
        self.n_received = 0
        self.first = timestamp
        self.last = timestamp


class SweepAssembler:
    """Group CySkin CAN messages into sweeps.

    Parameters
    ----------
    taxels : TaxelMap
        The layout's taxels and frame format (which messages make a sweep).
    missing : {"hold", "nan", "zero"}
        Rule for taxels whose message was lost (see the module docstring).
    window : int
        Sweeps kept open at once (≥ 1); 2 tolerates reordering between a
        sweep and the next.
    """

    def __init__(self, taxels: TaxelMap, *, missing: str = "hold", window: int = 2) -> None:
        if missing not in MISSING_RULES:
            raise InputError(f"missing must be one of {', '.join(MISSING_RULES)}, "
                             f"got {missing!r}")
        if window < 1:
            raise InputError(f"window must be ≥ 1, got {window}")
        self.taxels = taxels
        self.missing = missing
        self.window = int(window)
        self.stats = AssemblerStats()
        self._open: dict[int, _Open] = {}
        self._newest: int | None = None  # highest sequence number started
        self._emitted: int | None = None  # highest sequence number emitted
        self._recent: dict[int, np.ndarray] = {}  # emitted seq → chunks received
        self._held = np.full(taxels.n_taxels, np.nan, dtype=np.float32)
        self._n_chunks = taxels.n_messages
        # the chunk (message) that carries each taxel: lost taxels in one step
        self._chunk_of = np.zeros(taxels.n_taxels, dtype=np.int64)
        for i in range(self._n_chunks):
            self._chunk_of[taxels.chunk_taxels(i)] = i
        self._base = 0  # public sequence = internal sequence + base (changes on resync)
        self._late_run = 0  # late or duplicate messages in a row
        self._resync_after = max(2, self._n_chunks)

    # ------------------------------------------------------------------ input
    def feed(self, msg: Any) -> list[Sweep]:
        """Take one message; return the sweeps it finished (often none, in order)."""
        self.stats.messages += 1
        decoded = decode_message(msg, self.taxels)
        if isinstance(decoded, str):
            self.stats.rejected[decoded] += 1
            return []
        timestamp = _timestamp(msg)
        return self._take(decoded, timestamp)

    def feed_all(self, messages: Iterable[Any]) -> Iterator[Sweep]:
        """Every sweep in ``messages``, the last ones flushed at the end."""
        for msg in messages:
            yield from self.feed(msg)
        yield from self.flush()

    def flush(self) -> list[Sweep]:
        """Emit every open sweep (incomplete ones by the ``missing`` rule)."""
        return [self._emit(seq) for seq in sorted(self._open)]

    # ------------------------------------------------------------------ logic
    def _sequence(self, counter: int) -> int:
        if self._newest is None:
            return counter
        delta = (counter - self._newest) % COUNTER_MODULO
        if delta < COUNTER_MODULO // 2:
            return self._newest + delta
        return self._newest - (COUNTER_MODULO - delta)

    def _take(self, d: Decoded, timestamp: float) -> list[Sweep]:
        seq = self._sequence(d.counter)
        out: list[Sweep] = []
        if self._emitted is not None and seq <= self._emitted:
            recent = self._recent.get(seq)
            return self._stale(d, timestamp, recent is not None and bool(recent[d.chunk]))
        sweep = self._open.get(seq)
        if sweep is None:
            if self._newest is not None and seq <= self._newest - self.window:
                return self._stale(d, timestamp, False)
            sweep = self._open[seq] = _Open(self.taxels.n_taxels, self._n_chunks, timestamp)
            if self._newest is None or seq > self._newest:
                self._newest = seq
            # Too many open sweeps: the oldest will not complete in time.
            while len(self._open) > self.window:
                out.append(self._emit(min(self._open)))
        elif sweep.received[d.chunk]:
            self.stats.duplicates += 1
            return out
        if seq < self._newest:
            self.stats.out_of_order += 1
        self.stats.accepted += 1
        self._late_run = 0
        sweep.counts[self.taxels.chunk_taxels(d.chunk)] = d.values
        sweep.received[d.chunk] = True
        sweep.n_received += 1
        sweep.first = min(sweep.first, timestamp)
        sweep.last = max(sweep.last, timestamp)
        if sweep.n_received == self._n_chunks:
            # Older open sweeps will not get their messages in time: they go first.
            for older in sorted(s for s in self._open if s < seq):
                out.append(self._emit(older))
            out.append(self._emit(seq))
        return out

    def _stale(self, d: Decoded, timestamp: float, duplicate: bool) -> list[Sweep]:
        """A message for a sweep already emitted (a duplicate) or too old to keep (late)."""
        if duplicate:
            self.stats.duplicates += 1
        else:
            self.stats.late += 1
        self._late_run += 1
        if self._late_run < self._resync_after:
            return []
        # A sweep's worth of late messages in a row: the counter restarted.
        out = self.flush()
        last = (self._emitted + self._base) if self._emitted is not None else -1
        self._open.clear()
        self._recent.clear()
        self._newest = self._emitted = None
        self._base = last + 1 - d.counter
        self._late_run = 0
        self.stats.resyncs += 1
        if duplicate:  # this message starts the new count instead
            self.stats.duplicates -= 1
        else:
            self.stats.late -= 1
        return out + self._take(d, timestamp)

    def _emit(self, seq: int) -> Sweep:
        sweep = self._open.pop(seq)
        stats = self.stats
        if self._emitted is not None and seq > self._emitted + 1:
            stats.lost_sweeps += seq - self._emitted - 1
        self._emitted = seq
        self._recent[seq] = sweep.received
        for old in [s for s in self._recent if s <= seq - self.window - 1]:
            del self._recent[old]
        values = sweep.counts
        n_missing = 0
        if sweep.n_received < self._n_chunks:
            lost = np.flatnonzero(~sweep.received)
            cols = np.flatnonzero(~sweep.received[self._chunk_of])
            n_missing = int(cols.size)
            if self.missing == "hold":
                values[cols] = self._held[cols]
            elif self.missing == "nan":
                values[cols] = np.nan
            else:
                values[cols] = 0.0
            got = np.ones(self.taxels.n_taxels, dtype=bool)
            got[cols] = False
            self._held[got] = values[got]
            stats.incomplete_sweeps += 1
            stats.lost_messages += int(lost.size)
        else:
            self._held[:] = values
            stats.complete_sweeps += 1
        stats.sweeps += 1
        return Sweep(timestamp=sweep.last, values=values, sequence=seq + self._base,
                     counter=seq % COUNTER_MODULO, missing=n_missing,
                     first_timestamp=sweep.first)


def _timestamp(msg: Any) -> float:
    try:
        t = float(msg.timestamp)
    except Exception:
        return 0.0
    return t if np.isfinite(t) else 0.0
