"""CAN logs (``.blf``, ``.asc``, and the other formats python-can reads) ↔ sweeps.

:func:`read_log` turns a log of CySkin traffic into labelled segments of sweeps
(one per label marker pair; see :mod:`tactbench.can.meta`), :func:`write_log`
writes messages to a log. The taxel ids come, in this order of preference,
from the caller, from a taxel-map announcement in the log, or from the traffic
itself (every slot a message carries; absent slots inside a message then show
up as taxels that are always 0).
"""

from __future__ import annotations

import contextlib
import logging
import os
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from tactbench.budget import check_budget, memory_budget_bytes
from tactbench.can.assembler import AssemblerStats, Sweep, SweepAssembler
from tactbench.can.codec import SLOTS_PER_MODULE, FrameFormat, TaxelMap
from tactbench.can.meta import META_PREFIX, MetaAssembler, MetaEvent, is_meta
from tactbench.data.dataset import Dataset
from tactbench.data.recording import Recording, Sample
from tactbench.errors import InputError, TactbenchError
from tactbench.integrity import check_regular_file

#: Class name of the samples of a log without label markers.
UNLABELLED = "unlabelled"

#: Suffixes of the CAN logs read and written here (python-can needs no extra package
#: for them). python-can's ``.csv`` is left out: that suffix means CoST data here.
LOG_SUFFIXES = (".blf", ".asc", ".log", ".trc")

#: Bytes one python-can message read from a log holds (measured: 450 for .blf, 610 for
#: .asc); a log's messages must fit the memory budget at this size.
MESSAGE_BYTES = 640


def is_can_log(path: str | Path) -> bool:
    """Whether ``path`` looks like a CAN log (by suffix: .blf, .asc, .log, .trc)."""
    return Path(path).suffix.lower() in LOG_SUFFIXES


def check_log_name(path: str | Path) -> Path:
    """``path`` as a Path if its suffix names a CAN log format, else :class:`InputError`."""
    path = Path(path)
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise InputError(f"{path}: not a CAN log file name; use one of "
                         f"{', '.join(LOG_SUFFIXES)}")
    return path


def check_log_out(path: str | Path) -> Path:
    """``path`` as a Path if a log can be written there, else one :class:`InputError` line.

    Checked before any work (``tactbench can record`` checks before it opens the bus):
    a CAN log suffix, not a folder, no file where a folder of its path should be, and
    the nearest existing folder (the ones missing are created) writable.
    """
    path = check_log_name(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give a log file name ({', '.join(LOG_SUFFIXES)})")
    existing = path.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{path}: cannot write there: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{path}: cannot write in {existing} (permission denied)")
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(f"{path}: cannot overwrite it (permission denied)")
    return path


def open_writer(path: str | Path):
    """A python-can writer for ``path`` (format from the suffix); call ``.stop()`` to close."""
    import can

    path = check_log_out(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return can.Logger(str(path))
    except OSError as exc:
        raise InputError(f"{path}: cannot write the log: {exc.strerror or exc}") from None


def write_log(path: str | Path, messages: Iterable[Any]) -> int:
    """Write ``messages`` to ``path``; returns how many were written."""
    writer = open_writer(path)
    n = 0
    try:
        for msg in messages:
            writer.on_message_received(msg)
            n += 1
    finally:
        writer.stop()
    return n


def read_messages(path: str | Path) -> Iterator[Any]:
    """The messages of a log, in file order."""
    import can

    path = Path(path)
    check_regular_file(path, what="CAN log")  # a FIFO or a device: never opened
    check_log_name(path)
    if path.suffix.lower() == ".blf":
        check_blf(path)
    try:
        reader = can.LogReader(str(path))
    except Exception as exc:
        raise InputError(f"{path}: cannot open as a CAN log: {type(exc).__name__}: "
                         f"{_one_line(exc)}") from None
    try:
        yield from reader
    except TactbenchError:
        raise
    except Exception as exc:  # python-can's readers raise anything on a damaged file
        raise InputError(f"{path}: unreadable CAN log: {type(exc).__name__}: "
                         f"{_one_line(exc)}") from None
    finally:
        stop = getattr(reader, "stop", None)
        if stop is not None:
            stop()


#: Bytes an object of a .blf may claim beyond the end of the file: a log cut short (a
#: crash while recording) still reads up to its last whole message.
BLF_SLACK = 1 << 20


def check_blf(path: str | Path, *, budget: int | None = None) -> None:
    """Walk a .blf's objects before python-can reads it, refusing what would make the
    reader allocate without bound: a header or an object claiming far more bytes than the
    file has (python-can allocates what is claimed), or containers that decompress to more
    than the memory budget (python-can inflates each container whole: 3 MB of zlib can
    hold 3 GB). Decompression here is streamed, 1 MiB at a time; it costs a fraction of
    python-can's parsing. Anything else damaged is left to python-can to report.
    """
    path = Path(path)
    limit = memory_budget_bytes() if budget is None else budget
    size = path.stat().st_size
    inflated = 0  # bytes of objects after decompression: python-can holds up to ~2× that

    def refuse(offset: int, claimed: int) -> None:
        raise InputError(f"{path}: damaged .blf: the object at byte {offset} claims {claimed} "
                         f"bytes, but the file has {size}")

    with open(path, "rb") as f:
        head = f.read(48)
        if len(head) < 48 or head[:4] != b"LOGG":
            return  # python-can says what is wrong
        header_size = struct.unpack_from("<L", head, 4)[0]
        if header_size > size + BLF_SLACK:
            refuse(0, header_size)
        f.seek(header_size)
        while True:
            offset = f.tell()
            base = f.read(16)
            if len(base) < 16 or base[:4] != b"LOBJ":
                return
            obj_size, obj_type = struct.unpack_from("<LL", base, 8)
            if obj_size - 16 > size - offset - 16 + BLF_SLACK:
                refuse(offset, obj_size)
            body = max(0, obj_size - 16)
            if obj_type == 10 and body >= 16:  # LOG_CONTAINER: method, uncompressed size
                container = f.read(16)
                method = struct.unpack_from("<H", container)[0] if len(container) == 16 else -1
                if method == 0:
                    inflated += body - 16
                elif method == 2:
                    inflated = _inflate_count(f, body - 16, inflated, 2 * limit)
                    if inflated < 0:
                        return  # not zlib: python-can says what is wrong
            check_budget(2 * inflated, f"{path}: {inflated} bytes of .blf objects once "
                         f"decompressed", budget=limit)
            f.seek(offset + 16 + body + obj_size % 4)


def _inflate_count(f: Any, n: int, inflated: int, stop: int) -> int:
    """``inflated`` plus the decompressed size of the next ``n`` bytes of ``f`` (zlib),
    counted 1 MiB at a time and no further than ``stop``; -1 when they are not zlib."""
    d = zlib.decompressobj()
    step = 1 << 20
    try:
        while n > 0 and not d.eof:
            chunk = f.read(min(step, n))
            if not chunk:
                break
            n -= len(chunk)
            while chunk and not d.eof:
                inflated += len(d.decompress(chunk, step))
                if inflated > stop:
                    return inflated  # the caller refuses it
                chunk = d.unconsumed_tail
    except zlib.error:
        return -1
    return inflated


def _one_line(exc: BaseException, limit: int = 200) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[:limit] + "…"


def infer_taxel_ids(messages: Iterable[Any], fmt: FrameFormat | None = None) -> np.ndarray:
    """Taxel ids seen in the traffic: every slot a data message of ``fmt`` carries.

    Absent slots sent inside a message, and FD padding, appear as taxels too; a
    taxel-map announcement or the layout gives the exact ids.
    """
    fmt = fmt or FrameFormat()
    ids: set[int] = set()
    for msg in messages:
        try:
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            arb, data, ext = int(msg.arbitration_id), bytes(msg.data), bool(msg.is_extended_id)
        except Exception:
            continue
        if fmt.ids == "extended":
            if not ext or arb >> 24 != fmt.prefix:
                continue
            bus, offset, body = (arb >> 12) & 0xFFF, (arb >> 8) & 0xF, data
        else:
            if ext or not fmt.base_id <= arb <= 0x7FF or len(data) < 2:
                continue
            bus, offset, body = arb - fmt.base_id, data[1], data[2:]
        n = min(len(body) // 2, fmt.values_per_message, SLOTS_PER_MODULE - offset)
        if n <= 0 or offset % fmt.values_per_message:
            continue
        module = fmt.layout_module(bus)
        ids.update(module * SLOTS_PER_MODULE + offset + i for i in range(n))
    if not ids:
        raise InputError("no CySkin data messages found (wrong frame format, or an empty log?)")
    return np.array(sorted(ids), dtype=np.int64)


@dataclass
class Segment:
    """Consecutive sweeps between a label start and end marker (or unlabelled traffic).

    ``values`` float32 ``(T, N)`` raw 16-bit counts, ``timestamps`` float64
    ``(T,)`` seconds (the log's clock), ``missing`` int ``(T,)`` taxels not
    received per sweep, ``info`` the marker's JSON object (``None`` when unlabelled).
    """

    info: dict[str, Any] | None
    timestamps: np.ndarray
    values: np.ndarray
    missing: np.ndarray

    @property
    def label(self) -> str | None:
        return None if self.info is None else str(self.info["label"])

    def __len__(self) -> int:
        return len(self.timestamps)


@dataclass
class CanLog:
    """A CAN log read back: its taxels, labelled segments and what the assembler saw."""

    path: Path
    taxel_ids: np.ndarray
    taxel_source: str  # "given", "announced" or "inferred"
    segments: list[Segment]
    stats: AssemblerStats
    fmt: FrameFormat
    broken_meta: int = 0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def labelled(self) -> list[Segment]:
        return [s for s in self.segments if s.info is not None]

    def sweeps(self) -> tuple[np.ndarray, np.ndarray]:
        """All sweeps in order: timestamps ``(T,)`` and values ``(T, N)``."""
        if not self.segments:
            return np.zeros(0), np.zeros((0, self.taxel_ids.size), np.float32)
        return (np.concatenate([s.timestamps for s in self.segments]),
                np.concatenate([s.values for s in self.segments]))

    def sample_segments(self) -> list[Segment]:
        """The segments that are samples (numbered as in :meth:`to_dataset`): the labelled
        ones, or, in a log without label markers, the unlabelled stretches; empty ones
        left out."""
        return [s for s in (self.labelled or self.segments) if len(s)]

    def iter_sweeps(self, sample: int | None = None) -> Iterator[Sweep]:
        """The log's sweeps as :class:`~tactbench.can.assembler.Sweep` objects, in order.

        ``sample=None``: every sweep of every segment (labelled or not), as the bus
        carried them; ``sample=k``: the sweeps of sample ``k`` of :meth:`to_dataset`.
        Each sweep has ``timestamp`` (s, the log's clock), ``values`` float32 ``(N,)``
        (a copy), ``missing`` (taxels not received), ``label`` (the marker in force,
        ``None`` outside markers) and a running ``sequence`` from 0.
        """
        if sample is None:
            segments = self.segments
        else:
            segments = self.sample_segments()
            if isinstance(sample, bool) or not isinstance(sample, (int, np.integer)) \
                    or not 0 <= sample < len(segments):
                raise InputError(f"sample {sample!r} is out of range: {self.path} has "
                                 f"{len(segments)} samples (0..{len(segments) - 1})")
            segments = [segments[sample]]
        k = 0
        for seg in segments:
            for t, values, missing in zip(seg.timestamps, seg.values, seg.missing):
                yield Sweep(timestamp=float(t), values=values.copy(), sequence=k,
                            counter=k % 256, missing=int(missing), first_timestamp=float(t),
                            label=seg.label)
                k += 1

    def summary(self) -> dict[str, Any]:
        """Counts for ``tactbench data info``: JSON-ready."""
        labels: dict[str, int] = {}
        for s in self.labelled:
            labels[s.label] = labels.get(s.label, 0) + 1
        lengths = [len(s) for s in self.labelled] or [len(s) for s in self.segments]
        return {
            "path": str(self.path), "kind": "can-log", "format": self.fmt.to_dict(),
            "taxels": int(self.taxel_ids.size), "taxel_ids_from": self.taxel_source,
            "sweeps": int(sum(len(s) for s in self.segments)),
            "samples": len(self.labelled), "samples_per_class": dict(sorted(labels.items())),
            "unlabelled_sweeps": int(sum(len(s) for s in self.segments if s.info is None)),
            "frames_per_sample": ({"min": int(min(lengths)), "median": float(np.median(lengths)),
                                   "max": int(max(lengths))} if lengths else None),
            "assembler": self.stats.to_dict(), "broken_meta_messages": self.broken_meta,
            "reader_skipped": len(self.extra.get("reader_skipped", ())),
        }

    def to_dataset(self, *, name: str | None = None, layout: Any = None,
                   normalisation: Any = "fixed") -> Any:
        """The labelled segments as a :class:`tactbench.data.recording.Dataset`.

        Classes are the label names, in the order of the markers' ``class_index``
        when every marker has one (the simulator writes it), else sorted; marker fields ``user``, ``position``,
        ``repetition`` and ``source`` become the samples' fields when present.
        Each sample's timestamps start at 0 (the log's clock is wall time);
        labelled segments without a single sweep are left out. A log without
        label markers gives one sample per unlabelled stretch, of class
        ``"unlabelled"``.
        """
        segments = [s if s.info is not None else
                    Segment({"label": UNLABELLED}, s.timestamps, s.values, s.missing)
                    for s in self.sample_segments()]
        if not segments:
            raise InputError(f"{self.path}: no sweeps in the log")
        classes = _class_order(segments)
        samples = []
        for k, seg in enumerate(segments):
            info = seg.info
            try:
                rec = Recording(values=seg.values, taxel_ids=self.taxel_ids,
                                timestamps=seg.timestamps - seg.timestamps[0])
            except InputError as exc:  # e.g. a damaged log whose clock goes backwards
                raise InputError(f"{self.path}: sample {k} ({seg.label}): {exc}") from None
            samples.append(Sample(recording=rec, label=classes.index(seg.label),
                                  user=str(info.get("user", "")),
                                  position=str(info.get("position", "")),
                                  repetition=int(info.get("repetition", 0)),
                                  source=str(info.get("source", self.path))))
        return Dataset(name or self.path.stem, samples, classes, layout=layout,
                       normalisation=normalisation)


def _class_order(segments: list[Segment]) -> list[str]:
    """Class names in the order markers' ``class_index`` gives, else sorted."""
    names = sorted({s.label for s in segments})
    index: dict[str, int] = {}
    for s in segments:
        k = s.info.get("class_index")
        if not isinstance(k, int) or index.setdefault(s.label, k) != k:
            return names
    if sorted(index.values()) != list(range(len(names))):
        return names  # a subset of the classes, or clashing indices: no order to trust
    return sorted(names, key=index.__getitem__)


class _SegmentBuilder:
    def __init__(self, info: dict[str, Any] | None) -> None:
        self.info = info
        self.sweeps: list[Sweep] = []

    def build(self, n: int) -> Segment:
        return Segment(
            info=self.info,
            timestamps=np.array([s.timestamp for s in self.sweeps], dtype=np.float64),
            values=(np.stack([s.values for s in self.sweeps]) if self.sweeps
                    else np.zeros((0, n), np.float32)),
            missing=np.array([s.missing for s in self.sweeps], dtype=np.int64))


def segment_messages(messages: Iterable[Any], taxels: TaxelMap, *, missing: str = "hold",
                     meta_prefix: int = META_PREFIX, budget: int | None = None,
                     ) -> tuple[list[Segment], AssemblerStats, int]:
    """Split a message stream at label markers and assemble each part's sweeps.

    Returns ``(segments, assembler stats, broken meta messages)``. Unlabelled
    stretches with no sweeps are dropped; labelled ones are kept even if empty.
    The sweeps kept (each ``N`` float32 values, held twice while a segment is built)
    must fit the memory budget (default :func:`tactbench.budget.memory_budget_bytes`):
    a few messages can start thousands of sweeps of 65 536 taxels.
    """
    asm = SweepAssembler(taxels, missing=missing)
    meta = MetaAssembler(meta_prefix)
    segments: list[Segment] = []
    current = _SegmentBuilder(None)
    per_sweep = 2 * 4 * taxels.n_taxels + 200
    limit = memory_budget_bytes() if budget is None else budget
    held = 0

    def keep(sweeps: list[Sweep]) -> None:
        nonlocal held
        if sweeps:
            held += len(sweeps)
            if held * per_sweep > limit:
                check_budget(held * per_sweep, f"assembling more than {held - 1} sweeps of "
                             f"{taxels.n_taxels} taxels", budget=limit)
            current.sweeps.extend(sweeps)

    def close(next_info: dict[str, Any] | None) -> None:
        nonlocal current
        keep(asm.flush())
        if current.info is not None or current.sweeps:
            segments.append(current.build(taxels.n_taxels))
        current = _SegmentBuilder(next_info)

    for msg in messages:
        if is_meta(msg, meta_prefix):
            event: MetaEvent | None = meta.feed(msg)
            if event is None or event.kind == "taxel_map":
                continue
            if event.kind == "label_start":
                close(event.info)
            elif current.info is not None:  # label_end of the open segment
                close(None)
            continue
        keep(asm.feed(msg))
    close(None)
    return segments, asm.stats, meta.broken


def announced_taxel_ids(messages: Iterable[Any],
                        meta_prefix: int = META_PREFIX) -> np.ndarray | None:
    """The first taxel-map announcement in ``messages``, or ``None``."""
    meta = MetaAssembler(meta_prefix)
    for msg in messages:
        if is_meta(msg, meta_prefix):
            event = meta.feed(msg)
            if event is not None and event.kind == "taxel_map":
                return event.taxel_ids
    return None


def read_log(path: str | Path, *, taxel_ids: Any = None, fmt: FrameFormat | None = None,
             missing: str = "hold") -> CanLog:
    """Read a CAN log of CySkin traffic into labelled segments of sweeps.

    Parameters
    ----------
    path : str or Path
        ``.blf``, ``.asc``, ``.log`` (canutils) or ``.trc``.
    taxel_ids : array-like of int, optional
        The layout's taxel ids; default: announced in the log, else inferred.
    fmt : FrameFormat, optional
        The data frames' format (default :class:`FrameFormat()`).
    missing : {"hold", "nan", "zero"}
        Rule for taxels of lost messages (see :mod:`tactbench.can.assembler`).
    """
    path = Path(path)
    fmt = fmt or FrameFormat()
    budget = memory_budget_bytes()
    messages = []
    most = budget // MESSAGE_BYTES
    with reader_warnings() as skipped:
        try:
            for msg in read_messages(path):
                messages.append(msg)
                if len(messages) > most:
                    check_budget(len(messages) * MESSAGE_BYTES,
                                 f"{path}: more than {most} messages", budget=budget)
        except InputError as exc:
            raise type(exc)(f"{exc}{_skipped(skipped)}") from None
    try:
        if taxel_ids is not None:
            ids, source = np.asarray(taxel_ids, dtype=np.int64), "given"
        else:
            ids = announced_taxel_ids(messages)
            source = "announced"
            if ids is None:
                ids = infer_taxel_ids(messages, fmt)
                source = "inferred"
        taxels = TaxelMap(ids, fmt)
        segments, stats, broken = segment_messages(messages, taxels, missing=missing,
                                                   budget=budget)
    except InputError as exc:
        raise type(exc)(f"{path}: {exc}{_skipped(skipped)}") from None
    return CanLog(path, taxels.taxel_ids, source, segments, stats, fmt, broken,
                  extra={"reader_skipped": skipped} if skipped else {})


#: python-can's loggers that report what a log reader skips.
READER_LOGGERS = ("can.io.blf", "can.io.asc", "can.io.canutils", "can.io.trc")


@contextlib.contextmanager
def reader_warnings() -> Iterator[list[str]]:
    """Gather what python-can's log readers warn about (through ``logging``: objects of a
    damaged log they skip) instead of letting it print beside tactbench's one line; the
    list is filled while the block runs."""
    caught: list[str] = []

    class _Catch(logging.Filter):
        def filter(self, record: logging.LogRecord) -> bool:
            if record.levelno >= logging.WARNING:
                caught.append(record.getMessage())
                return False
            return True

    catch = _Catch()
    loggers = [logging.getLogger(name) for name in READER_LOGGERS]
    for logger in loggers:
        logger.addFilter(catch)
    try:
        yield caught
    finally:
        for logger in loggers:
            logger.removeFilter(catch)


def _skipped(warnings: list[str]) -> str:
    if not warnings:
        return ""
    first = " ".join(warnings[0].split())[:80]
    return f" (python-can skipped {len(warnings)} damaged part(s) of it: {first})"
