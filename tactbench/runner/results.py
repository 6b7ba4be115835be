"""Result rows on disk: one JSON file per cell under ``OUT/cells``, written atomically.

A row is a cell's identity (see :mod:`tactbench.runner.planning`) plus what came of it:

- ``status: "ok"``: the cell trained and was tested; the row holds accuracy,
  per-class accuracy, the confusion matrix and the costs (see ``docs/runner.md``);
- ``status: "failed"``: the cell raised; the row holds ``error`` (``type``,
  ``message``, ``traceback``: the last frames, formatted) instead of results.

Rows written before ``status`` existed are finished rows (``"ok"``). A failed row is not
finished: the next run of the same scene retries it.

Each file records its cell's ``key`` and a ``checksum`` (SHA-256 of the rest of the row
as sorted, compact JSON). Reading verifies both and the row's shape (a JSON object with
``status`` and the fields of its status, and, given the planned identity, that
identity): a damaged row (truncated, edited, another cell's copied under this name) is
reported in one warning line and treated as missing, so the run recomputes the cell.
Rows written before checksums existed have none to verify and are checked for shape
only.

``OUT/results.json`` keeps every row of the report too, as stored (key and checksum
included). ``OUT/cells`` is what git ignores and what a copy of a report folder often
leaves behind, so a run puts back the rows of its planned cells that ``cells`` lacks and
``results.json`` holds (:meth:`ResultStore.restore`), each verified as a cell file is
(and required to have its checksum), instead of computing them again.
"""

from __future__ import annotations

import json
import logging
import math
import os
import sys
from pathlib import Path
from typing import Any, Iterable

from tactbench.errors import CorruptArtefactError, InputError
from tactbench.budget import memory_budget_bytes
from tactbench.integrity import hash_bytes, read_regular_bytes
from tactbench.paths import (
    Temporary,
    atomic_write_text,
    parse_temporary,
    remove_orphans,
    temp_name,
)

log = logging.getLogger("tactbench.runner.results")

OK = "ok"
FAILED = "failed"

#: Costs a row may hold (numbers; reports average them).
COST_FIELDS = ("encode_ms_per_frame", "train_s", "inference_ms_per_sequence", "peak_rss_mb")

#: A cell file larger than this is not a row tactbench wrote (rows are a few kB).
ROW_MAX_BYTES = 16 << 20

#: The report document of an out folder that keeps every row (written by
#: :func:`tactbench.runner.writers.write_reports`, which imports this module).
REPORT_JSON = "results.json"

#: Identity fields that a cell's identity leaves out at their default (see
#: :func:`tactbench.runner.planning.cell_identity`), with that default.
IDENTITY_DEFAULTS = {"test_window": "first", "precision": "float32", "init_seed": None,
                     "input": None}


def row_status(row: dict[str, Any]) -> str:
    """``"ok"`` or ``"failed"`` (rows from before the field existed are ``"ok"``)."""
    return row.get("status", OK)


def ok_rows(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of cells that finished: the ones accuracy tables are made of."""
    return [r for r in rows if row_status(r) == OK]


def failed_rows(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of cells that raised."""
    return [r for r in rows if row_status(r) == FAILED]


def row_checksum(row: dict[str, Any]) -> str:
    """The checksum of a row: SHA-256 of everything but ``checksum``, as sorted JSON."""
    body = {k: v for k, v in row.items() if k != "checksum"}
    return hash_bytes(json.dumps(body, sort_keys=True, separators=(",", ":")).encode())


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def check_row(row: Any, key: str, identity: dict[str, Any] | None = None) -> str | None:
    """What is wrong with ``row`` as the row of cell ``key``, or None when nothing is."""
    if not isinstance(row, dict):
        return f"holds a JSON {type(row).__name__}, not a row"
    if row.get("key") != key:
        return f"is the row of cell {str(row.get('key'))[:40]!r}, not of this cell"
    if "checksum" in row and row["checksum"] != row_checksum(row):
        return "does not match its checksum (edited or damaged)"
    for field, kind in (("encoder", str), ("classifier", str), ("L", int), ("seed", int)):
        if not isinstance(row.get(field), kind) or isinstance(row.get(field), bool):
            return f"has no {field} ({kind.__name__})"
    for field in ("dataset", "split", "peak_step"):  # optional; text where present
        if row.get(field) is not None and not isinstance(row[field], str):
            return f"has a {field} that is not text"
    for field in COST_FIELDS:
        if row.get(field) is not None and not _number(row[field]):
            return f"has a {field} that is not a finite number"
    status = row.get("status", OK)
    if status == OK:
        if not _number(row.get("accuracy")) or not 0.0 <= row["accuracy"] <= 1.0:
            return f"has no accuracy in [0, 1] (got {str(row.get('accuracy'))[:40]})"
        classes, confusion = row.get("classes"), row.get("confusion")
        if not isinstance(classes, list) or not all(isinstance(c, str) for c in classes):
            return "has no list of class names"
        k = len(classes)
        if not isinstance(confusion, list) or len(confusion) != k or not all(
                isinstance(line, list) and len(line) == k and all(
                    isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in line)
                for line in confusion):
            return f"has no {k} × {k} confusion matrix of counts"
        per_class = row.get("per_class_accuracy")
        if not isinstance(per_class, dict) or not all(
                v is None or (_number(v) and 0.0 <= v <= 1.0) for v in per_class.values()):
            return "has no per-class accuracy (a number in [0, 1] or null per class)"
        problem = _check_predictions(row.get("test_predictions"), k)
        if problem is not None:
            return problem
    elif status == FAILED:
        if not isinstance(row.get("error"), dict):
            return "is a failed row without its error"
    else:
        return f"has an unknown status {str(status)[:40]!r}"
    for field, value in json.loads(json.dumps(identity or {})).items():
        if row.get(field) != value:
            return f"records {field} = {str(row.get(field))[:40]!r}, the cell has {value!r}"
    return None


def _check_predictions(tp: Any, k: int) -> str | None:
    """Problems of a row's per-sequence predictions (optional: older rows lack them)."""
    if tp is None:
        return None
    if not isinstance(tp, dict) or set(tp) != {"indices", "labels", "predictions"}:
        return "has test_predictions that are not {indices, labels, predictions}"
    lists = [tp["indices"], tp["labels"], tp["predictions"]]
    if not all(isinstance(v, list) for v in lists) or len({len(v) for v in lists}) != 1:
        return "has test_predictions that are not three lists of one length"
    for name, values, top in (("indices", lists[0], None), ("labels", lists[1], k),
                              ("predictions", lists[2], k)):
        if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0
                   and (top is None or n < top) for n in values):
            return f"has test_predictions {name} that are not class/sequence numbers"
    if len(set(lists[0])) != len(lists[0]):
        return "has test_predictions that name a test sequence twice"
    return None


def _failed(row: dict[str, Any], kind: str, message: str) -> dict[str, Any]:
    """``row`` as a failed row of error ``kind``: its scores and large fields left out."""
    row = {k: v for k, v in row.items() if k not in (
        "checksum", "confusion", "per_class_accuracy", "test_predictions", "accuracy",
        "classes") and len(json.dumps(v)) < 4096}
    row.update(status=FAILED, error={"type": kind, "traceback": "", "message": message})
    return row


class ResultStore:
    """One JSON file per cell under ``OUT/cells``, written atomically, verified on read."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.cells = self.out / "cells"
        #: (mtime_ns, size) of results.json, its read error, its rows: see _report_rows
        self._report_cache: tuple[tuple[int, int], Exception | None, list] | None = None

    def path(self, key: str) -> Path:
        """Where the row of cell ``key`` is (or will be) kept."""
        return self.cells / f"{key}.json"

    def read(self, key: str, identity: dict[str, Any] | None = None,
             ) -> dict[str, Any] | None:
        """The verified row of cell ``key``; None when there is none; raises
        :class:`CorruptArtefactError` when the file is not a sound row of this cell
        (``identity``: the cell's planned identity, checked field by field)."""
        path = self.path(key)
        try:
            size = path.stat().st_size
            if size > ROW_MAX_BYTES:
                raise CorruptArtefactError(path, f"{size} bytes, not a cell row")
            row = json.loads(read_regular_bytes(path, limit=ROW_MAX_BYTES, what="cell row"))
        except FileNotFoundError:
            return None
        except IsADirectoryError:
            raise CorruptArtefactError(path, "is a folder, not a cell row") from None
        except InputError as exc:  # a FIFO, a device, a dangling link: never opened
            raise CorruptArtefactError(path, str(exc).replace(f"{path} ", "", 1)) from None
        except (ValueError, RecursionError) as exc:  # UnicodeDecodeError is a ValueError
            raise CorruptArtefactError(path, f"is not valid JSON ({exc})") from None
        problem = check_row(row, key, identity)
        if problem is not None:
            raise CorruptArtefactError(path, problem)
        return row

    def get(self, key: str, identity: dict[str, Any] | None = None,
            ) -> dict[str, Any] | None:
        """The row of cell ``key``, ok or failed; None when there is none, or when it is
        damaged (then a warning names the file and the problem; the cell is recomputed)."""
        try:
            return self.read(key, identity)
        except CorruptArtefactError as exc:
            log.warning("tactbench: warning: cell row %s %s; the cell is computed again",
                        exc.artefact, exc.problem)
            return None

    def finished(self, key: str, identity: dict[str, Any] | None = None) -> bool:
        """Whether cell ``key`` has a sound ``ok`` row (a failed one is retried)."""
        row = self.get(key, identity)
        return row is not None and row_status(row) == OK

    def put(self, row: dict[str, Any]) -> dict[str, Any]:
        """Write ``row`` (with its ``key``) and its checksum, atomically; returns the row
        as stored. A row too large to be read back (:data:`ROW_MAX_BYTES`, even as
        compact JSON: a confusion of thousands of classes) is stored as a failed row
        saying so, so that the run reports it and exits 1 instead of dropping it."""
        # the checksum of the row as it will be read back (tuples as lists, ...)
        row = json.loads(json.dumps({k: v for k, v in row.items() if k != "checksum"}))
        problem = check_row(row, str(row.get("key"))) if row_status(row) == OK else None
        if problem is not None:  # never stored to be dropped at report time: a failed row
            row = _failed(row, "UnsoundRowError", f"the cell's result row {problem} (a "
                          f"plugin's output the checks did not catch?); no score is given")
        row["checksum"] = row_checksum(row)
        text = json.dumps(row, indent=2)
        if len(text) > ROW_MAX_BYTES // 4:  # rows are a few kB: large ones compact
            text = json.dumps(row, separators=(",", ":"))
        if len(text.encode()) > ROW_MAX_BYTES:
            big = len(text.encode())
            row = _failed(row, "RowTooLargeError", f"the cell's result row is {big} bytes, "
                          f"over the {ROW_MAX_BYTES}-byte limit of a cell row (too many "
                          f"classes or test sequences to store); nothing was kept")
            row["checksum"] = row_checksum(row)
            text = json.dumps(row, indent=2)
        atomic_write_text(self.path(row["key"]), text)
        return row

    def restore(self, identities: dict[str, dict[str, Any]]) -> list[str]:
        """Put back the rows of planned cells that ``OUT/cells`` lacks and
        ``OUT/results.json`` holds; returns their keys.

        ``identities``: planned cell key → identity. A row is put back only when it is a
        sound ``ok`` row of that cell (:func:`check_row` with the planned identity) and
        has its checksum (results.json is a document people copy, merge and edit); any
        other is named in one warning line and its cell is computed again.
        """
        missing = {k: v for k, v in identities.items()
                   if not (self.path(k).exists() or self.path(k).is_symlink())}
        if not missing:
            return []
        report = self.out / REPORT_JSON
        restored: list[str] = []
        for row in self._report_rows(warn=True):
            key = row["key"]
            if key not in missing or row_status(row) != OK:
                continue
            problem = check_row(row, key, missing[key]) if "checksum" in row \
                else "has no checksum to verify it"
            if problem is not None:
                log.warning("tactbench: warning: the row of cell %s in %s %s; the cell is "
                            "computed again", key, report, problem)
                continue
            self.put(row)
            restored.append(key)
            del missing[key]
        return restored

    def _report_rows(self, *, warn: bool = False) -> list[dict[str, Any]]:
        """The rows (dicts with a string ``key``) of ``OUT/results.json``, unverified;
        none when it is absent or unreadable (``warn``: said in one warning line). A run
        asks twice (:meth:`claim`, then :meth:`restore`); the file, a report's every row
        with its predictions, is parsed once while it stays the same."""
        report = self.out / REPORT_JSON
        try:
            st = report.stat()
        except OSError:
            return []
        stamp = (st.st_mtime_ns, st.st_size)
        if self._report_cache is None or self._report_cache[0] != stamp:
            try:
                doc, error = json.loads(read_regular_bytes(
                    report, limit=memory_budget_bytes(), what="results.json")), None
            except (OSError, ValueError, RecursionError) as exc:
                doc, error = None, exc
            rows = doc.get("rows") if isinstance(doc, dict) else None
            self._report_cache = (stamp, error, [
                row for row in (rows if isinstance(rows, list) else [])
                if isinstance(row, dict) and isinstance(row.get("key"), str)])
        _, error, rows = self._report_cache
        if error is not None and warn:
            log.warning("tactbench: warning: %s cannot be read (%s); its rows are not "
                        "reused", report, error)
        return rows

    def clean(self) -> list[Temporary]:
        """Remove temporary row files whose writing process is gone; returns them."""
        return remove_orphans(self.cells)

    def rows(self, keys: Iterable[str]) -> list[dict[str, Any]]:
        """The stored rows of ``keys``, in that order, skipping cells without a sound one."""
        return [row for key in keys if (row := self.get(key)) is not None]

    # ------------------------------------------------------- runs sharing an out folder

    def claim(self, keys: Iterable[str],
              identities: dict[str, dict[str, Any]] | None = None) -> Path:
        """Refuse a grid that would drop another grid's cells from the report of this out
        folder, then mark the folder as used by this run (delete the returned file when
        the run ends; a claim whose process is gone is ignored, then cleaned). With
        ``identities`` (planned key → identity) the refusal also says how a stored cell
        differs from the nearest planned one (``its test_window is 'first', this run's
        'vote'``): what keeps it from being reused.

        The rule: one out folder holds one grid, and a run may extend it (more seeds,
        L, encoders) but not leave out cells already there: those are another grid's,
        whose report this run would replace. Two runs at once must plan the same grid;
        of two different ones, the later is refused, naming the first.
        """
        keys = sorted(set(keys))
        planned = set(keys)
        out = self.out
        stray = sorted(p.stem for p in self.cells.glob("*.json")
                       if not p.name.startswith(".") and p.stem not in planned) \
            if self.cells.is_dir() else []
        if stray:
            first = _describe(self.path(stray[0]), identities)
            raise InputError(f"out folder {out} holds {len(stray)} cell(s) of another grid "
                             f"({first}) that this run does not plan, and its report "
                             f"would leave them out; give a new --out, or a grid that "
                             f"includes them")
        # the rows only results.json keeps (git ignores cells/): the same rule
        kept = [row for row in self._report_rows()
                if row["key"] not in planned and not self.path(row["key"]).exists()]
        if kept:
            raise InputError(f"out folder {out}: its {REPORT_JSON} holds {len(kept)} row(s) "
                             f"of another grid ({_describe(kept[0], identities)}) that this "
                             f"run does not plan, and its report would replace them; give "
                             f"a new --out, or a grid that includes them")
        self.cells.mkdir(parents=True, exist_ok=True)
        mine = self.cells / temp_name("run")
        atomic_write_text(mine, json.dumps({"keys": keys, "command": _command()}))
        for claim in sorted(self.cells.glob(".run.tmp-*"), key=_claim_order):
            info = parse_temporary(claim)
            if claim == mine or info is None or info.pid == os.getpid() \
                    or info.state != "in progress":
                continue
            if _claim_order(claim) > _claim_order(mine):
                continue  # started after this run: that one is refused, not this one
            try:
                other = json.loads(read_regular_bytes(claim, limit=1 << 20))
            except (OSError, ValueError):
                continue  # gone meanwhile, or being written
            if isinstance(other, dict) and other.get("keys") != keys:
                mine.unlink(missing_ok=True)
                raise InputError(f"out folder {out} is in use by another run of a "
                                 f"different grid (process {info.pid}: "
                                 f"{str(other.get('command'))[:200]}); give a new --out, "
                                 f"or wait for it to finish")
        return mine


def _claim_order(path: Path) -> tuple[int, str]:
    try:
        return path.stat().st_mtime_ns, path.name
    except OSError:
        return 0, path.name


def _command() -> str:
    return " ".join(["tactbench", *sys.argv[1:]])


def _describe(path: Path | dict[str, Any],
              identities: dict[str, dict[str, Any]] | None = None) -> str:
    """``encoder × classifier L=.. seed=.. from `command``` for a stored row (a cell file
    or a row of results.json), as far as it reads; with the planned ``identities``, also
    how it differs from the nearest."""
    try:
        row = path if isinstance(path, dict) else json.loads(
            read_regular_bytes(path, limit=ROW_MAX_BYTES))
        label = (f"{row['encoder']} × {str(row['classifier']).split(':')[0]} L={row['L']} "
                 f"seed={row['seed']}")
        command = (row.get("run") or {}).get("command")
        label += f", from `{command}`" if command else ""
    except Exception:  # noqa: BLE001 — only a description; the file is named instead
        return path.get("key", "a row") if isinstance(path, dict) else path.name
    differences = min((identity_differences(row, i) for i in (identities or {}).values()),
                      key=len, default=[])
    if differences:
        label += "; " + ", ".join(
            f"its {field} is {_short(mine)}, this run's {_short(planned)}"
            for field, mine, planned in differences[:3])
        label += ", …" if len(differences) > 3 else ""
    return label


def identity_differences(row: dict[str, Any], identity: dict[str, Any],
                         ) -> list[tuple[str, Any, Any]]:
    """``(field, row's value, identity's value)`` for each identity field in which a
    stored ``row`` differs from a planned cell ``identity`` (a field an identity leaves
    out at its default, :data:`IDENTITY_DEFAULTS`, counts as that default on both
    sides)."""
    identity = json.loads(json.dumps(identity))  # tuples as lists, as a row reads back
    fields = [*identity, *(f for f in IDENTITY_DEFAULTS if f not in identity)]
    differences = []
    for field in fields:
        default = IDENTITY_DEFAULTS.get(field)
        mine, planned = row.get(field, default), identity.get(field, default)
        if mine != planned:
            differences.append((field, mine, planned))
    return differences


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:39] + "…"
