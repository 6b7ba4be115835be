"""A cell's identity: the fields that decide its numbers, and the one rule that leaves a
field out of it at its default.

Everything that changes a cell's numbers is in its identity, and :func:`digest` of the
identity is the cell's key. Fields that entered identities later (the test window, the
storage precision, an initialisation seed, the input kind, the torch threads, the CPU
kernels, the device) are left out at their default, :data:`IDENTITY_DEFAULTS`, so that
cells trained before each of them keep their keys: :func:`without_defaults` is that
rule, written once, used where an identity is made (:func:`cell identities
<tactbench.runner.execution.planning.cell_identity>`), read back from a row
(:func:`row_identity`), compared (:func:`~tactbench.runner.execution.results.check_row`)
and migrated (:func:`migrated_identity`).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Mapping

from tactbench.data.windows import UNNAMED_TEST_WINDOW
from tactbench.kernels import (DEFAULT_KERNELS, KERNEL_LEVELS, KERNEL_VARIABLES, KERNELS_ENV,
                               kernels_identity)

#: The row field (and identity field) of a cell whose run trained and tested on a data set
#: of its own, drawn independently of every other run's (``synthetic-forearm:people=per-run``):
#: comparisons over such runs need no overlap correction (docs/statistics.md).
INDEPENDENT_RUNS = "independent_runs"

#: The device a cell computes on where its identity does not say (all cells before the
#: device entered identities, and every CPU cell since).
DEFAULT_DEVICE = "cpu"

#: Identity fields left out of a cell's identity at their default, with that default: the
#: one table of the rule (:func:`without_defaults`).
IDENTITY_DEFAULTS: dict[str, Any] = {
    "test_window": UNNAMED_TEST_WINDOW, "precision": "float32", "init_seed": None,
    "input": None, "run_dataset": None, INDEPENDENT_RUNS: None, "threads": 1,
    "cpu_kernels": DEFAULT_KERNELS, "device": DEFAULT_DEVICE}

#: The fields of a cell identity that a stored row holds and its key hashes. The
#: :data:`COMPUTE_FIELDS` came last (issue 36: threads and kernels; issue 50: the
#: device); a row keyed before them is keyed by the rest (``compute=False``).
IDENTITY_FIELDS = ("schema", "dataset", "dataset_hash", "split", "test_window",
                   "test_per_class", "imaging", "encoder", "encoder_version", "precision",
                   "classifier", "profile", "L", "seed", "init_seed", "input", "run_dataset",
                   INDEPENDENT_RUNS)
COMPUTE_FIELDS = ("threads", "cpu_kernels", "device")


def digest(obj: Any, n: int = 16) -> str:
    """The first ``n`` hex digits of the SHA-256 of ``obj`` as sorted JSON."""
    text = json.dumps(obj, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def without_defaults(identity: Mapping[str, Any]) -> dict[str, Any]:
    """``identity`` less each field of :data:`IDENTITY_DEFAULTS` at its default."""
    return {k: v for k, v in identity.items()
            if not (k in IDENTITY_DEFAULTS and v == IDENTITY_DEFAULTS[k])}


def with_defaults(identity: Mapping[str, Any], field: str) -> Any:
    """The value of ``field`` in ``identity``, its default where it is left out."""
    return identity.get(field, IDENTITY_DEFAULTS.get(field))


def compute_identity(threads: int, device: str = DEFAULT_DEVICE, *,
                     kernels: str | None = None) -> dict[str, Any]:
    """What the computation adds to a cell's identity: the torch threads, the CPU kernels
    (``kernels``, a run's resolved ones; None: :func:`~tactbench.kernels.kernels_identity`)
    and the device kind (``cpu``, ``cuda``: :func:`kind_of`), each only where it is not
    the default; all three change the numbers a cell gives (docs/reliability.md,
    "Numbers across machines")."""
    return without_defaults({"threads": int(threads),
                             "cpu_kernels": kernels_identity() if kernels is None else kernels,
                             "device": str(device)})


def row_identity(row: Mapping[str, Any], *, compute: bool = True) -> dict[str, Any]:
    """The identity a stored ``row`` holds, as a cell identity is made: its
    :data:`IDENTITY_FIELDS` (and, with ``compute``, :data:`COMPUTE_FIELDS`), each left
    out at its default (:func:`without_defaults`). ``digest`` of it is the row's key
    unless the row was copied under another name or edited and re-sealed."""
    fields = IDENTITY_FIELDS + (COMPUTE_FIELDS if compute else ())
    return without_defaults({k: row[k] for k in fields if k in row})


#: The compute fields each earlier form of a key hashed: before issue 50 (no device),
#: before issue 36 (none of them).
EARLIER_KEYS = (("threads", "cpu_kernels"), ())


def row_keys(row: Mapping[str, Any]) -> list[str]:
    """The keys a stored ``row`` may rightly have: :func:`digest` of its identity now,
    then of each earlier form (:data:`EARLIER_KEYS`): a row keyed before a field entered
    identities is its cell's until it is migrated (:func:`migrated_row`)."""
    base = row_identity(row, compute=False)
    compute = row_identity(row)
    return [digest(compute), *(digest({**base, **{k: compute[k] for k in fields
                                                   if k in compute}})
                               for fields in EARLIER_KEYS)]


# ------------------------------------------------------------------ migration of old rows

def recorded_kernels(row: Mapping[str, Any]) -> str:
    """The CPU kernels a row's ``machine`` record says it computed with: a pinned level,
    ``native <cpu> (<isa>)`` for unpinned kernels, ``not recorded`` for rows older than
    the machine record."""
    facts = row.get("machine")
    if not isinstance(facts, dict):
        return "not recorded"
    pinned = facts.get("pinned") or {}
    level = str(pinned.get(KERNELS_ENV, "")).lower()
    if level in KERNEL_LEVELS and all(
            pinned.get(name, "") == value
            for name, value in zip(KERNEL_VARIABLES, KERNEL_LEVELS[level][:-1])):
        return level
    isa = str(facts.get("cpu_kernels") or "unknown").lower()
    return f"native {facts.get('cpu') or 'unknown CPU'} ({isa})"


def kind_of(device: str) -> str:
    """The kind of a device as written: ``cpu``, ``cuda`` (``cuda``, ``cuda:N``), else
    the text itself (``auto``: not resolved, so it matches neither)."""
    name = str(device).strip().lower()
    return "cuda" if name == "cuda" or name.startswith("cuda:") else name


def recorded_device(row: Mapping[str, Any]) -> str:
    """The device kind a row records it trained on (``cpu`` where it records none:
    rows older than the record were CPU cells)."""
    return kind_of(str(row.get("device") or DEFAULT_DEVICE))


def migrated_identity(row: Mapping[str, Any]) -> dict[str, Any]:
    """The identity of a row keyed before the computation (or the device) entered
    identities (its key is one of the earlier :func:`row_keys`): ``row_identity(row,
    compute=False)`` with the threads, kernels and device the row records it was
    trained with, each left out at its default. Its digest is the row's key from now
    on; the results are untouched."""
    base, now = row_identity(row, compute=False), row_identity(row)
    threads = {k: now[k] for k in EARLIER_KEYS[0] if k in now}
    if row.get("key") not in row_keys(row)[:2]:  # keyed before issue 36 too
        threads = {"threads": int(row.get("threads") or 1),
                   "cpu_kernels": recorded_kernels(row)}
    return without_defaults({**base, **threads, "device": recorded_device(row)})


def migrated_row(row: Mapping[str, Any]) -> dict[str, Any] | None:
    """``row`` under the identity it was trained with (:func:`migrated_identity`) and
    that identity's key, or None when its key is already that one. Raises
    :class:`ValueError` for a row whose key is no digest of its identity, old or new
    (copied under another name, or edited): nothing of it can be trusted to move."""
    key = row.get("key")
    identity = migrated_identity(row)
    new = digest(identity)
    if key == new:
        return None
    if key not in row_keys(row)[1:]:
        raise ValueError(f"row {str(key)[:40]!r} is not keyed by its identity")
    kind = identity.get("device", DEFAULT_DEVICE)
    used = {"device_used": row["device"]} if row.get("device") not in (None, kind) else {}
    return {**row, **identity, "device": kind, **used, "key": new}
