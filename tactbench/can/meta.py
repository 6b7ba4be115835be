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
    problem = marker_problem(info)
    if problem:
        raise InputError(problem.replace("marker without a label", "a marker needs a 'label'"))
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


#: Deepest nesting of JSON arrays and objects a marker may have. tactbench writes flat
#: objects; the limit keeps a hostile marker (16 000 nested ``[``) from reaching the
#: JSON parser, which recurses.
MAX_MARKER_DEPTH = 8
#: Marker fields the readers turn into text (a sample's class, user, ...): JSON scalars.
TEXT_FIELDS = ("label", "user", "position", "source")
_INT64 = (-(1 << 63), (1 << 63) - 1)


def marker_problem(info: Any) -> str | None:
    """Why ``info`` is not a usable marker (``None`` if it is).

    A marker is a JSON object with a ``label``; ``label``, ``user``, ``position`` and
    ``source`` are strings or finite numbers, ``repetition`` an integer (int64).
    """
    if not isinstance(info, dict) or "label" not in info:
        return "marker without a label"
    for key in TEXT_FIELDS:
        if key in info and not _scalar(info[key]):
            return f"marker field {key!r} must be a string or a number"
    rep = info.get("repetition", 0)
    if isinstance(rep, bool) or not isinstance(rep, int) or not _INT64[0] <= rep <= _INT64[1]:
        return "marker field 'repetition' must be an integer"
    return None


def _scalar(value: Any) -> bool:
    if isinstance(value, float):
        return value == value and abs(value) != float("inf")
    return isinstance(value, (str, int))


def json_depth(text: str, limit: int = MAX_MARKER_DEPTH) -> int:
    """Nesting depth of the arrays and objects in JSON ``text``, counted without
    recursion; stops counting (returns ``limit + 1``) once past ``limit``."""
    depth = deepest = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > limit:
                return limit + 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    return deepest


def parse_marker(payload: bytes) -> dict[str, Any]:
    """A label marker's info from its payload; :class:`InputError` if it is not one
    (not UTF-8 JSON, nested deeper than :data:`MAX_MARKER_DEPTH`, see
    :func:`marker_problem`)."""
    text = payload.decode("utf-8")
    if json_depth(text) > MAX_MARKER_DEPTH:
        raise InputError(f"marker nested deeper than {MAX_MARKER_DEPTH} levels")
    info = json.loads(text)
    problem = marker_problem(info)
    if problem:
        raise InputError(problem)
    return info


class MetaAssembler:
    """Reassemble meta messages from their parts; broken ones are counted, never raised.

    Broken: an unknown kind, a missing part, a taxel map whose length is not a multiple
    of 4, a marker that is not UTF-8 JSON, is nested deeper than
    :data:`MAX_MARKER_DEPTH`, or has fields of the wrong type (:func:`marker_problem`),
    and anything that only looks like a message.
    """

    def __init__(self, prefix: int = META_PREFIX) -> None:
        self.prefix = prefix
        self._parts: dict[tuple[int, int], dict[int, bytes]] = {}
        self.broken = 0

    def feed(self, msg: Any) -> MetaEvent | None:
        try:
            arb = int(msg.arbitration_id)
            data = bytes(msg.data)
            timestamp = float(msg.timestamp)
        except Exception:  # an object that only looks like a message
            self.broken += 1
            return None
        kind, last = (arb >> 20) & 0xF, bool((arb >> 19) & 1)
        part, seq = (arb >> 8) & 0x7FF, arb & 0xFF
        if kind not in KINDS:
            self.broken += 1
            return None
        key = (kind, seq)
        parts = self._parts.setdefault(key, {})
        parts[part] = data
        if not last:
            return None
        del self._parts[key]
        if sorted(parts) != list(range(part + 1)):
            self.broken += 1
            return None
        payload = b"".join(parts[i] for i in range(part + 1))
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
                if not ids:
                    raise InputError("taxel map without taxels")
                return MetaEvent("taxel_map", timestamp, taxel_ids=np.array(ids, np.int64))
            return MetaEvent(KINDS[kind], timestamp, info=parse_marker(payload))
        except (ValueError, UnicodeDecodeError, RecursionError):
            self.broken += 1
            return None
