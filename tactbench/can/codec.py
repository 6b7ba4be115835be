"""Taxel values ↔ CAN messages in tactbench's CySkin frame format.

CySkin names a taxel ``id = module_id * 16 + slot`` (slot 0–15; real modules
use up to 12). A *sweep* is one reading of every taxel; it travels as one
message per (module, run of consecutive slots), all tagged with the sweep's
8-bit sequence counter. Two id schemes (see ``docs/cyskin-can.md``):

``extended`` (default)
    29-bit id ``prefix << 24 | module << 12 | slot_offset << 8 | counter``;
    the payload is only values: classic CAN 4 values (8 bytes), CAN FD up to 16
    (a whole module, 32 bytes).
``standard``
    11-bit id ``base_id + module``; payload ``[counter, slot_offset, values...]``:
    classic CAN 3 values (8 bytes), CAN FD 16 values (34 bytes padded to 48).

Values are unsigned 16-bit, big-endian by default. The number of values in a
message follows from its length; slots a message carries that are not in the
layout are ignored when decoding (FD padding lands there too).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Iterable, NamedTuple

import numpy as np

from tactbench.errors import InputError

SLOTS_PER_MODULE = 16
COUNTER_MODULO = 256
#: Most taxels one bus can carry in any id scheme: 4096 bus modules (the 12 module bits
#: of an extended id) × 16 slots. Taxel-id lists and ranges beyond it are refused.
MAX_TAXELS = 4096 * SLOTS_PER_MODULE
MAX_COUNT = 0xFFFF

#: Payload lengths CAN FD allows (a shorter payload is padded up to the next one).
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


def _int(value: Any, name: str) -> int:
    """An int from an int or a string such as ``"0x1C"`` (spec strings keep hex as text)."""
    if isinstance(value, bool):
        raise InputError(f"frame format option '{name}' must be an integer, got {value!r}")
    if isinstance(value, int):
        return value
    try:
        return int(str(value), 0)
    except ValueError:
        raise InputError(f"frame format option '{name}' must be an integer "
                         f"(decimal or 0x hex), got {value!r}") from None


def _bool(value: Any, name: str) -> bool:
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    raise InputError(f"frame format option '{name}' must be true or false, got {value!r}")


@dataclass(frozen=True)
class FrameFormat:
    """Where module, slot offset and counter live, and how values are packed.

    Parameters
    ----------
    ids : {"extended", "standard"}
        Id scheme (see the module docstring).
    fd : bool
        CAN FD frames (one message per module) instead of classic 8-byte frames.
    prefix : int
        Extended ids: bits 28–24 (0–31) that mark CySkin traffic.
    base_id : int
        Standard ids: the id of bus module 0; module ``m`` uses ``base_id + m``.
    byteorder : {"big", "little"}
        Byte order of the 16-bit values.
    module_map : dict
        ``{bus_module: layout_module}`` when the number a module sends under
        differs from the module id in the taxel ids; empty means identical.
        Modules missing from a non-empty map use their own number.
    """

    ids: str = "extended"
    fd: bool = False
    prefix: int = 0x1C
    base_id: int = 0x100
    byteorder: str = "big"
    module_map: dict[int, int] = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        if self.ids not in ("extended", "standard"):
            raise InputError(f"frame format: ids must be 'extended' or 'standard', "
                             f"got {self.ids!r}")
        if self.byteorder not in ("big", "little"):
            raise InputError(f"frame format: byteorder must be 'big' or 'little', "
                             f"got {self.byteorder!r}")
        if not 0 <= self.prefix < 32:
            raise InputError(f"frame format: prefix must be 0..31 (5 bits), got {self.prefix}")
        if not 0 <= self.base_id <= 0x7FF:
            raise InputError(f"frame format: base_id must be 0..0x7FF, got {self.base_id:#x}")
        targets = list(self.module_map.values())
        if len(set(targets)) != len(targets):
            raise InputError("frame format: module_map maps two bus modules to one module")

    # ---------------------------------------------------------------- building
    @classmethod
    def from_options(cls, options: dict[str, Any]) -> "FrameFormat":
        """Build from loose options (strings allowed: ``{"prefix": "0x1C", "fd": "true"}``)."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise InputError(f"unknown frame format option(s) {', '.join(unknown)}; "
                             f"options: {', '.join(sorted(known))}")
        kw: dict[str, Any] = {}
        for key, value in options.items():
            if key in ("prefix", "base_id"):
                kw[key] = _int(value, key)
            elif key == "fd":
                kw[key] = _bool(value, key)
            elif key == "module_map":
                if not isinstance(value, dict):
                    raise InputError("frame format: module_map must be an object "
                                     "{bus_module: layout_module}")
                kw[key] = {_int(k, "module_map"): _int(v, "module_map")
                           for k, v in value.items()}
            else:
                kw[key] = str(value)
        return cls(**kw)

    @classmethod
    def from_spec(cls, spec: str | None) -> "FrameFormat":
        """Parse ``"ids=standard,base_id=0x200,fd=true"`` (empty → the default format).

        Items may also be separated by ``;`` (for use inside a component spec,
        where ``,`` separates the component's own options).
        """
        if not spec or not spec.strip():
            return cls()
        options: dict[str, str] = {}
        for item in spec.replace(";", ",").split(","):
            key, eq, value = item.partition("=")
            if not eq or not key.strip():
                raise InputError(f"bad frame format item '{item}' in '{spec}': "
                                 f"expected key=value")
            options[key.strip()] = value.strip()
        return cls.from_options(options)

    @classmethod
    def from_json(cls, path: str | Path) -> "FrameFormat":
        """Load from a JSON object with the same keys (``module_map`` keys may be strings)."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise InputError(f"{path}: not valid JSON (line {exc.lineno}): {exc.msg}") from None
        if not isinstance(data, dict):
            raise InputError(f"{path}: expected a JSON object of frame format options")
        try:
            return cls.from_options(data)
        except ValueError as exc:
            raise InputError(f"{path}: {exc}") from None

    @classmethod
    def parse(cls, spec: str | None = "", file: str | Path | None = None) -> "FrameFormat":
        """The format a user gave: a JSON ``file`` when given, else the text ``spec``."""
        return cls.from_json(file) if file else cls.from_spec(spec)

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["module_map"] = {str(k): v for k, v in self.module_map.items()}
        return out

    # ---------------------------------------------------------------- derived
    @property
    def values_per_message(self) -> int:
        """How many 16-bit values one message carries at most."""
        if self.fd:
            return SLOTS_PER_MODULE
        return 4 if self.ids == "extended" else 3

    @property
    def header_bytes(self) -> int:
        return 0 if self.ids == "extended" else 2

    @property
    def value_dtype(self) -> np.dtype:
        return np.dtype(">u2" if self.byteorder == "big" else "<u2")

    @property
    def max_module(self) -> int:
        """Largest bus module number the id scheme can carry."""
        return 0xFFF if self.ids == "extended" else 0x7FF - self.base_id

    def bus_module(self, module: int) -> int:
        """The number ``module`` (from the taxel ids) sends under."""
        if not self.module_map:
            return module
        for bus, layout in self.module_map.items():
            if layout == module:
                return bus
        return module

    def layout_module(self, bus: int) -> int:
        return self.module_map.get(bus, bus)

    def arbitration_id(self, bus_module: int, slot_offset: int, counter: int) -> int:
        if self.ids == "extended":
            return (self.prefix << 24) | (bus_module << 12) | (slot_offset << 8) | counter
        return self.base_id + bus_module


class Chunk(NamedTuple):
    """One message's worth of a sweep: ``module``'s slots from ``slot_offset``.

    ``columns[i]`` is the index into the taxel vector of slot
    ``slot_offset + i``, or -1 when that slot is not in the layout.
    """

    module: int
    slot_offset: int
    columns: np.ndarray


class TaxelMap:
    """How a layout's taxels split into messages under a :class:`FrameFormat`.

    Parameters
    ----------
    taxel_ids : array-like of int, shape (N,)
        CySkin taxel ids (``module * 16 + slot``), unique, in the order values
        are given. Values travel in this order's modules, not in this order.
    fmt : FrameFormat
    """

    def __init__(self, taxel_ids: Iterable[int], fmt: FrameFormat | None = None) -> None:
        self.fmt = fmt or FrameFormat()
        ids = np.asarray(list(taxel_ids) if not isinstance(taxel_ids, np.ndarray)
                         else taxel_ids)
        if ids.ndim != 1 or ids.size == 0:
            raise InputError(f"taxel_ids must be a non-empty 1-D array, got shape {ids.shape}")
        if not np.issubdtype(ids.dtype, np.integer):
            raise InputError(f"taxel_ids must be integers, got dtype {ids.dtype}")
        ids = ids.astype(np.int64)
        if ids.min() < 0:
            raise InputError(f"taxel ids must be ≥ 0, found {int(ids.min())}")
        uniq, counts = np.unique(ids, return_counts=True)
        if (counts > 1).any():
            raise InputError(f"taxel ids must be unique; {int(uniq[counts > 1][0])} repeats")
        self.taxel_ids = ids
        modules = ids // SLOTS_PER_MODULE
        slots = ids % SLOTS_PER_MODULE
        vpm = self.fmt.values_per_message
        too_big = [int(m) for m in np.unique(modules)
                   if self.fmt.bus_module(int(m)) > self.fmt.max_module]
        if too_big:
            raise InputError(f"module {too_big[0]} (taxel id {too_big[0] * 16}+) does not fit "
                             f"the {self.fmt.ids} id scheme (bus modules 0..{self.fmt.max_module})"
                             f"; use a module_map or another id scheme")
        chunks: list[Chunk] = []
        index: dict[tuple[int, int], int] = {}
        order = np.argsort(modules, kind="stable")  # each module's columns, ascending
        firsts, starts = np.unique(modules[order], return_index=True)
        ends = np.append(starts[1:], order.size)
        for module, a, b in zip(firsts, starts, ends):
            in_module = order[a:b]
            # Classic frames start at fixed offsets (0, vpm, 2·vpm, ...): a lost
            # message then always loses the same slots, which keeps the rule simple.
            offsets = np.unique(slots[in_module] // vpm) * vpm
            for offset in offsets:
                cols = np.full(vpm, -1, dtype=np.int64)
                sel = in_module[(slots[in_module] >= offset) & (slots[in_module] < offset + vpm)]
                cols[slots[sel] - offset] = sel
                # Trailing absent slots are not sent.
                last = int(np.flatnonzero(cols >= 0).max()) + 1
                index[(int(module), int(offset))] = len(chunks)
                chunks.append(Chunk(int(module), int(offset), cols[:last].copy()))
        self.chunks = chunks
        self.chunk_index = index
        self.modules = frozenset(c.module for c in chunks)
        #: For each chunk, the positions of present slots and their taxel columns.
        self._present = [np.flatnonzero(c.columns >= 0) for c in chunks]
        self._present_cols = [c.columns[p] for c, p in zip(chunks, self._present)]
        # Decoding runs once per message: keep what it needs at hand.
        self._n_slots = [len(c.columns) for c in chunks]
        self._dense = [len(p) == len(c.columns) for c, p in zip(chunks, self._present)]
        self._dtype = self.fmt.value_dtype

    @property
    def n_taxels(self) -> int:
        return int(self.taxel_ids.size)

    @property
    def n_messages(self) -> int:
        """Messages per sweep."""
        return len(self.chunks)

    def payload_lengths(self) -> list[int]:
        """Bytes of each message's payload, in chunk order (FD padding included)."""
        return [payload_length(len(c.columns), self.fmt) for c in self.chunks]

    def chunk_taxels(self, i: int) -> np.ndarray:
        """Columns (taxel indices) that chunk ``i`` carries."""
        return self._present_cols[i]


def payload_length(n_values: int, fmt: FrameFormat) -> int:
    """Payload bytes for ``n_values`` values (with the header, padded for CAN FD)."""
    n = fmt.header_bytes + 2 * n_values
    if fmt.fd:
        return next(length for length in FD_LENGTHS if length >= n)
    return n


# ------------------------------------------------------------------- quantisation
def quantize(values: Any) -> np.ndarray:
    """Sensor values → uint16 counts: rounded, clipped to [0, 65535], NaN → 0.

    Integer-valued inputs in range come back exactly from :func:`dequantize`,
    which is what makes record → replay exact for 16-bit sensor data.
    """
    arr = np.asarray(values, dtype=np.float64)
    arr = np.where(np.isfinite(arr), arr, 0.0)
    return np.clip(np.rint(arr), 0, MAX_COUNT).astype(np.uint16)


def dequantize(counts: np.ndarray) -> np.ndarray:
    return np.asarray(counts, dtype=np.float32)


# ------------------------------------------------------------------- encoding
def encode_payloads(counts: np.ndarray, taxels: TaxelMap,
                    counter: int) -> list[tuple[int, bytes]]:
    """One sweep's ``(arbitration_id, payload)`` pairs, in chunk order.

    ``counts`` is uint16 ``(N,)`` in the order of ``taxels.taxel_ids``;
    ``counter`` is taken modulo 256. Absent slots inside a message are sent as 0.
    """
    counts = np.asarray(counts)
    if counts.shape != (taxels.n_taxels,):
        raise InputError(f"expected {taxels.n_taxels} values, got shape {counts.shape}")
    fmt = taxels.fmt
    counter %= COUNTER_MODULO
    dtype = fmt.value_dtype
    out = []
    for i, chunk in enumerate(taxels.chunks):
        vals = np.zeros(len(chunk.columns), dtype=dtype)
        vals[taxels._present[i]] = counts[taxels._present_cols[i]]
        body = vals.tobytes()
        if fmt.ids == "standard":
            body = bytes((counter, chunk.slot_offset)) + body
        if fmt.fd:
            body = body.ljust(payload_length(len(chunk.columns), fmt), b"\x00")
        bus = fmt.bus_module(chunk.module)
        out.append((fmt.arbitration_id(bus, chunk.slot_offset, counter), body))
    return out


def encode_sweep(values: Any, taxels: TaxelMap, counter: int, *,
                 timestamp: float = 0.0, channel: Any = None) -> list:
    """One sweep as ``can.Message`` objects (values are quantised with :func:`quantize`)."""
    import can

    fmt = taxels.fmt
    return [can.Message(timestamp=timestamp, arbitration_id=arb, data=body,
                        is_extended_id=fmt.ids == "extended", is_fd=fmt.fd,
                        bitrate_switch=fmt.fd, channel=channel)
            for arb, body in encode_payloads(quantize(values), taxels, counter)]


# ------------------------------------------------------------------- decoding
class Decoded(NamedTuple):
    """A message understood as taxel data: chunk ``chunk`` of sweep ``counter``."""

    counter: int
    chunk: int
    values: np.ndarray  # 16-bit unsigned (wire byte order), one per present slot of the chunk


#: Reasons a message is not taxel data (keys of the assembler's ``rejected`` counts).
REJECT_REASONS = ("error_frame", "remote_frame", "foreign_id", "unknown_module",
                  "unknown_slots", "bad_length")


def decode_message(msg: Any, taxels: TaxelMap) -> Decoded | str:
    """Decode one message, or return why it is not taxel data (one of :data:`REJECT_REASONS`).

    ``msg`` needs the attributes of ``can.Message`` (``arbitration_id``,
    ``is_extended_id``, ``data``, ``is_error_frame``, ``is_remote_frame``);
    anything else about it is never trusted, and nothing here raises.
    """
    try:
        if getattr(msg, "is_error_frame", False):
            return "error_frame"
        if getattr(msg, "is_remote_frame", False):
            return "remote_frame"
        fmt = taxels.fmt
        arb = int(msg.arbitration_id)
        data = bytes(msg.data if msg.data is not None else b"")
        extended = bool(msg.is_extended_id)
    except Exception:  # an object that only looks like a message
        return "bad_length"
    if fmt.ids == "extended":
        if not extended or (arb >> 24) != fmt.prefix:
            return "foreign_id"
        bus = (arb >> 12) & 0xFFF
        offset = (arb >> 8) & 0xF
        counter = arb & 0xFF
        body = data
    else:
        if extended or not fmt.base_id <= arb <= 0x7FF:
            return "foreign_id"
        bus = arb - fmt.base_id
        if len(data) < 2:
            return "bad_length"
        counter, offset = data[0], data[1]
        body = data[2:]
    module = fmt.layout_module(bus) if fmt.module_map else bus
    chunk = taxels.chunk_index.get((module, offset))
    if chunk is None:
        # Unknown module, or a slot offset that does not start a message of this layout.
        return "unknown_slots" if module in taxels.modules else "unknown_module"
    n_slots = taxels._n_slots[chunk]
    if len(body) % 2 and not fmt.fd:
        return "bad_length"
    n_values = len(body) // 2
    # A message must carry every slot the layout expects in it; extra values
    # are FD padding or slots outside the layout, ignored — but never past slot 15.
    if n_values < n_slots or (not fmt.fd and n_values > fmt.values_per_message):
        return "bad_length"
    vals = np.frombuffer(body, dtype=taxels._dtype, count=n_slots)
    if not taxels._dense[chunk]:
        vals = vals[taxels._present[chunk]]
    return Decoded(counter, chunk, vals)
