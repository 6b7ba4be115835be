"""The resolved record of a run: what a run decides once, before its first cell, frozen,
stored with the run and read — never worked out again — by every look, ``report``,
``reproduce``, ``plan`` and plugin.

A :class:`RunRecord` holds

- the **design** (:class:`~tactbench.runner.execution.scene.Design`: the primary
  questions, the seed order, the looks and their schedule, the budget), made by
  :func:`~tactbench.runner.execution.scene.design_of`, and each primary question's
  **family** (the names of the comparisons it expands to over the grid's cells);
- the **computation** (:class:`Compute`: torch threads per cell, the CPU kernels, the
  device kind), made by :func:`resolve_compute`, which every cell identity of the run
  takes its compute fields from;
- the **workers** (:class:`~tactbench.runner.execution.workers.Workers`: how many cells
  at once, what limited them, the devices they own, each worker's forecast peak and the
  whole run's), decided by :func:`~tactbench.runner.execution.workers.run_workers`;
- the **paired test** every comparison is made with, and what a cell identity leaves out
  at its default (:data:`~tactbench.runner.execution.identity.IDENTITY_DEFAULTS`).

Each value is computed in the one function named above; :func:`resolve_record` only
gathers them. A run writes its record to ``OUT/run-record.json`` (:data:`RECORD_FILE`)
with a checksum, before its first cell; :func:`read_record` verifies it when it is read
back. A folder written before records existed has none: :func:`record_of_rows` reads
what its rows stored instead (the scene of the latest row, the compute fields of its
identity), with no workers (they were not recorded).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Mapping, Sequence

from tactbench.errors import InputError
from tactbench.integrity import hash_bytes, read_regular_bytes
from tactbench.kernels import kernels_identity, pin_cpu_kernels
from tactbench.machine import cpu_model, memory_bytes, usable_cores
from tactbench.paths import atomic_write_text
from tactbench.runner.execution.devices import resolve_kind
from tactbench.runner.execution.identity import (IDENTITY_DEFAULTS, compute_identity,
                                                 with_defaults)
from tactbench.runner.execution.results import latest_scene, ok_rows
from tactbench.runner.execution.scene import Design, design_of
from tactbench.runner.execution.workers import Workers, run_workers

if TYPE_CHECKING:
    from tactbench.runner.execution.planning import Plan
    from tactbench.runner.execution.scene import Scene

log = logging.getLogger("tactbench.runner")

#: Where a run folder keeps its record.
RECORD_FILE = "run-record.json"
#: The record's format; a record of another format is read as none (the rows' then).
RECORD_SCHEMA = 1
#: A record is a few kilobytes; a larger file is refused before it is read.
MAX_RECORD_BYTES = 1 << 20
#: The paired test where a run names none (the analysis's ``DEFAULT_PAIRED_TEST``;
#: written here too since execution does not import analysis, and tested equal).
DEFAULT_PAIRED_TEST = "corrected-t"


@dataclass(frozen=True)
class Compute:
    """How a run's cells compute: ``threads`` (torch threads per cell), ``cpu_kernels``
    (:func:`~tactbench.kernels.kernels_identity`) and ``device`` (its kind, ``cpu`` or
    ``cuda``, ``auto`` resolved here)."""

    threads: int
    cpu_kernels: str
    device: str

    def identity(self) -> dict[str, Any]:
        """What these add to a cell's identity, each left out at its default
        (:func:`~tactbench.runner.execution.identity.compute_identity`)."""
        return compute_identity(self.threads, self.device, kernels=self.cpu_kernels)


def resolve_compute(scene: "Scene") -> Compute:
    """The :class:`Compute` of a run of ``scene`` on this machine: the one place threads,
    kernels and device are resolved for a run (the kernels pinned first)."""
    pin_cpu_kernels()
    return Compute(int(scene.threads), kernels_identity(),
                   resolve_kind(scene.device, scene.executor))


@dataclass(frozen=True)
class RunRecord:
    """The resolved record of a run (see the module docstring): frozen, stored as
    :data:`RECORD_FILE`, read by every look, report, reproduction, plan and plugin."""

    design: Design
    compute: Compute
    paired_test: str = DEFAULT_PAIRED_TEST
    #: each primary question → the names of the comparisons it expands to
    families: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    workers: Workers | None = None  # None: a folder from before records (not recorded)
    identity_defaults: Mapping[str, Any] = field(default_factory=lambda: dict(IDENTITY_DEFAULTS))
    scene: Mapping[str, Any] = field(default_factory=dict)  # the scene's fields as given
    machine: Mapping[str, Any] = field(default_factory=dict)  # cpu, cores, memory_mb
    made: str = ""  # when (UTC, ISO 8601); "" for a record read from rows
    source: str = RECORD_FILE  # where it was read from: the file, or "rows"

    @property
    def primary(self) -> tuple[str, ...]:
        return self.design.primary

    @property
    def seed_order(self) -> tuple[int, ...]:
        return self.design.seed_order

    @property
    def looks(self) -> tuple[int, ...]:
        return self.design.looks

    def to_json(self) -> dict[str, Any]:
        """The record as JSON values (what :data:`RECORD_FILE` holds, without its
        checksum, and what the ``run_finished`` and ``look_finished`` hooks receive as
        ``record``)."""
        doc = {"schema": RECORD_SCHEMA, "design": asdict(self.design),
               "compute": asdict(self.compute), "paired_test": self.paired_test,
               "families": {q: list(v) for q, v in self.families.items()},
               "workers": None if self.workers is None else {
                   **asdict(self.workers), "run_peak_mb": self.workers.run_peak_mb},
               "identity_defaults": dict(self.identity_defaults),
               "scene": dict(self.scene), "machine": dict(self.machine), "made": self.made}
        return json.loads(json.dumps(doc))  # tuples as lists: as it is read back

    @classmethod
    def from_json(cls, doc: Mapping[str, Any], source: str = RECORD_FILE) -> "RunRecord":
        """The record of :meth:`to_json`'s document; a malformed one raises
        :class:`InputError` naming what is wrong."""
        try:
            design, scene = doc["design"], dict(doc["scene"])
            workers = doc.get("workers")
            if workers is not None:
                workers = {k: v for k, v in workers.items() if k != "run_peak_mb"}
                if workers.get("devices") is not None:
                    workers["devices"] = tuple(workers["devices"])
                workers = Workers(**workers)
            compute = doc["compute"]
            record = cls(
                design=Design(primary=tuple(design["primary"]),
                              seed_order=tuple(int(s) for s in design["seed_order"]),
                              looks=tuple(int(n) for n in design["looks"]),
                              budget=design.get("budget"),
                              budget_seconds=design.get("budget_seconds")),
                compute=Compute(int(compute["threads"]), str(compute["cpu_kernels"]),
                                str(compute["device"])),
                paired_test=str(doc["paired_test"]),
                families={str(q): tuple(v) for q, v in dict(doc["families"]).items()},
                workers=workers, identity_defaults=dict(doc["identity_defaults"]),
                scene=scene, machine=dict(doc["machine"]),
                made=str(doc["made"]), source=source)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"{source}: not a run record ({type(exc).__name__}: {exc})"
                             ) from None
        # the design is its scene's (design_of checks the stored fields as a scene does):
        # a record edited and sealed again cannot hand the looks a design of its own
        if record.design != design_of(scene):
            raise InputError(f"{source}: its design is not its scene's (edited)")
        return record


def resolve_record(scene: "Scene", *, plan: "Plan", rows: Iterable[Mapping[str, Any]] = (),
                   parent_peak_mb: float = 0.0, paired_test: str | None = None,
                   families: Mapping[str, Sequence[str]] | None = None,
                   compute: Compute | None = None) -> RunRecord:
    """The record of a run of ``scene`` on this machine, made once before its first cell:
    its design (``scene.design``), ``compute`` (the plan's, :func:`resolve_compute`), the
    workers (:func:`~tactbench.runner.execution.workers.run_workers` over ``rows``, the
    stored rows of its folder, the ``plan`` and the run's own process at
    ``parent_peak_mb``), the ``paired_test`` by name and each primary question's
    ``families`` (the analysis's names, given by the caller that composes the rooms)."""
    return RunRecord(
        design=scene.design, compute=compute or plan.compute,
        paired_test=paired_test or DEFAULT_PAIRED_TEST,
        families={q: tuple(v) for q, v in (families or {}).items()},
        workers=run_workers(scene, rows, plan=plan, parent_peak_mb=parent_peak_mb),
        scene=json.loads(json.dumps(asdict(scene))),
        machine={"cpu": cpu_model(), "cores": usable_cores(),
                 "memory_mb": round(memory_bytes() / (1 << 20), 1)},
        made=time.strftime("%Y-%m-%dT%H:%M:%S%z"))


def record_checksum(doc: Mapping[str, Any]) -> str:
    """SHA-256 of a record's document less its ``checksum``, as sorted compact JSON."""
    body = {k: v for k, v in doc.items() if k != "checksum"}
    return hash_bytes(json.dumps(body, sort_keys=True, separators=(",", ":")).encode())


def write_record(out: str | Path, record: RunRecord) -> Path:
    """Write ``record`` into the run folder ``out`` (atomically, with its checksum)."""
    doc = record.to_json()
    doc["checksum"] = record_checksum(doc)
    path = Path(out) / RECORD_FILE
    atomic_write_text(path, json.dumps(doc, indent=1, sort_keys=True) + "\n")
    return path


def read_record(out: str | Path) -> RunRecord | None:
    """The record stored in the run folder ``out``, verified (its checksum, its format);
    None where there is none. A damaged or foreign one is named in one warning line and
    read as none, so that the folder's rows decide (:func:`record_of_rows`)."""
    path = Path(out) / RECORD_FILE
    if not (path.exists() or path.is_symlink()):
        return None
    try:
        doc = json.loads(read_regular_bytes(path, limit=MAX_RECORD_BYTES, what="run record"))
        if not isinstance(doc, dict) or doc.get("schema") != RECORD_SCHEMA:
            raise InputError(f"{path}: not a run record of format {RECORD_SCHEMA}")
        if doc.get("checksum") != record_checksum(doc):
            raise InputError(f"{path} does not match its checksum (edited or damaged)")
        return RunRecord.from_json(doc, source=str(path))
    except (InputError, OSError, ValueError, RecursionError) as exc:
        log.warning("tactbench: warning: %s; the folder's rows are read instead "
                    "(the next run writes the record again)", exc)
        return None


def record_of_rows(rows: Sequence[Mapping[str, Any]]) -> RunRecord:
    """The record of a folder without one (written before records existed, or its record
    damaged): the design of the scene its latest row stored, the compute fields of that
    row's identity, the paired test that scene named; no workers (not recorded)."""
    scene = latest_scene(rows)
    done = ok_rows(rows) or list(rows)
    latest = max(done, key=lambda r: (str(r.get("finished", "")), str(r.get("key", ""))),
                 default={})
    compute = Compute(int(with_defaults(latest, "threads")),
                      str(with_defaults(latest, "cpu_kernels")),
                      str(with_defaults(latest, "device")))
    return RunRecord(design=design_of(scene), compute=compute,
                     paired_test=str(scene.get("paired_test") or DEFAULT_PAIRED_TEST),
                     scene=dict(scene), source="rows")


def folder_record(out: str | Path, rows: Sequence[Mapping[str, Any]]) -> RunRecord:
    """The record of the run folder ``out``: its stored one (:func:`read_record`), else
    the one its ``rows`` say (:func:`record_of_rows`)."""
    return read_record(out) or record_of_rows(rows)


__all__ = ["RECORD_FILE", "Compute", "RunRecord", "resolve_compute", "resolve_record",
           "write_record", "read_record", "record_of_rows", "folder_record"]
