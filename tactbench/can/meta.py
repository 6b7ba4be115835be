"""tactbench's meta frames: label markers and taxel-map announcements on the bus.

Neither is part of CySkin's traffic; tactbench's simulator sends them and the
recorder writes them, so a log says which stretch of sweeps is which gesture and
which taxels exist. A real bus without them is read just as well (one unlabelled
segment, taxels inferred from the traffic).

Meta frames use 29-bit ids, whatever the data frames use::

    meta_prefix << 24 | kind << 20 | last << 19 | part << 8 | seq

``kind`` 1 = label start, 2 = label end (payload: a UTF-8 JSON object, cut into
8-byte parts), 3 = taxel map (payload: ``(module, slot mask)`` pairs of
big-endian uint16, two per frame); ``part`` numbers the frames of one meta
message (0–2047), ``last`` marks its final frame, ``seq`` (0–255) tells
messages apart.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from tactbench.can.codec import SLOTS_PER_MODULE
from tactbench.errors import InputError

META_PREFIX = 0x1D
LABEL_START, LABEL_END, TAXEL_MAP = 1, 2, 3
KINDS = {LABEL_START: "label_start", LABEL_END: "label_end", TAXEL_MAP: "taxel_map"}
MAX_PARTS = 2048


def meta_id(kind: int, part: int, last: bool, seq: int, prefix: int = META_PREFIX) -> int:
    return (prefix << 24) | (kind << 20) | (int(last) << 19) | (part << 8) | (seq % 256)


def is_meta(msg: Any, prefix: int = META_PREFIX) -> bool:
    try:
        return bool(msg.is_extended_id) and (int(msg.arbitration_id) >> 24) == prefix \
            and not msg.is_error_frame and not msg.is_remote_frame
    except Exception:
        return False


def _frames(kind: int, payload: bytes, seq: int, timestamp: float, prefix: int) -> list:
    import can

    parts = [payload[i:i + 8] for i in range(0, len(payload), 8)] or [b""]
    if len(parts) > MAX_PARTS:
        raise InputError(f"meta message too long: {len(payload)} bytes "
                         f"(at most {8 * MAX_PARTS})")
    return [can.Message(timestamp=timestamp, is_extended_id=True, data=part,
                        arbitration_id=meta_id(kind, i, i == len(parts) - 1, seq, prefix))
            for i, part in enumerate(parts)]


def marker_messages(start: bool, info: dict[str, Any], seq: int, *, timestamp: float = 0.0,
                    prefix: int = META_PREFIX) -> list:
    """A label start/end marker as CAN messages; ``info`` needs at least ``"label"``."""
    if "label" not in info:
        raise InputError("a marker needs a 'label'")
    text = json.dumps(info, separators=(",", ":"), sort_keys=True).encode()
    return _frames(LABEL_START if start else LABEL_END, text, seq, timestamp, prefix)


def taxel_map_messages(taxel_ids: Iterable[int], seq: int, *, timestamp: float = 0.0,
                       prefix: int = META_PREFIX) -> list:
    """The layout's taxel ids as ``(module, slot mask)`` pairs."""
    ids = np.asarray(list(taxel_ids), dtype=np.int64)
    masks: dict[int, int] = {}
    for tid in ids:
        module, slot = divmod(int(tid), SLOTS_PER_MODULE)
        masks[module] = masks.get(module, 0) | (1 << slot)
    if any(m > 0xFFFF for m in masks):
        raise InputError("taxel ids too large for a taxel-map announcement (module > 65535)")
    payload = b"".join(m.to_bytes(2, "big") + masks[m].to_bytes(2, "big") for m in sorted(masks))
    return _frames(TAXEL_MAP, payload, seq, timestamp, prefix)


@dataclass(frozen=True)
class MetaEvent:
    """A complete meta message: ``kind`` ("label_start", "label_end", "taxel_map")."""

    kind: str
    timestamp: float
    info: dict[str, Any] | None = None  # for markers
    taxel_ids: np.ndarray | None = None  # for taxel maps, sorted


class MetaAssembler:
    """Reassemble meta messages from their parts; broken ones are counted, never raised."""

    def __init__(self, prefix: int = META_PREFIX) -> None:
        self.prefix = prefix
        self._parts: dict[tuple[int, int], dict[int, bytes]] = {}
        self.broken = 0

    def feed(self, msg: Any) -> MetaEvent | None:
        arb = int(msg.arbitration_id)
        kind, last = (arb >> 20) & 0xF, bool((arb >> 19) & 1)
        part, seq = (arb >> 8) & 0x7FF, arb & 0xFF
        if kind not in KINDS:
            self.broken += 1
            return None
        key = (kind, seq)
        parts = self._parts.setdefault(key, {})
        parts[part] = bytes(msg.data)
        if not last:
            return None
        del self._parts[key]
        if sorted(parts) != list(range(part + 1)):
            self.broken += 1
            return None
        payload = b"".join(parts[i] for i in range(part + 1))
        timestamp = float(msg.timestamp)
        try:
            if kind == TAXEL_MAP:
                if len(payload) % 4:
                    raise InputError("taxel map payload not a multiple of 4 bytes")
                ids = []
                for i in range(0, len(payload), 4):
                    module = int.from_bytes(payload[i:i + 2], "big")
                    mask = int.from_bytes(payload[i + 2:i + 4], "big")
                    ids += [module * SLOTS_PER_MODULE + s for s in range(SLOTS_PER_MODULE)
                            if mask >> s & 1]
                return MetaEvent("taxel_map", timestamp, taxel_ids=np.array(ids, np.int64))
            info = json.loads(payload.decode())
            if not isinstance(info, dict) or "label" not in info:
                raise InputError("marker without a label")
            return MetaEvent(KINDS[kind], timestamp, info=info)
        except (ValueError, UnicodeDecodeError):
            self.broken += 1
            return None
