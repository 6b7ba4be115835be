"""Result rows on disk: one JSON file per cell under ``OUT/cells``, written atomically.

A row is a cell's identity (see :mod:`tactbench.runner.execution.planning`) plus what came of it:

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

``OUT/cells`` is the one store of a run folder: results.json, results.csv and report.md
are rendered from these rows (:func:`tactbench.runner.analysis.report.analyse`, then
:func:`tactbench.runner.presentation.writers.render`) and never read back. :meth:`ResultStore.stored_rows` gives every sound row of a folder in the order of
the scene that computed it (:func:`scene_order`), for a report that the rows alone decide.
"""

from __future__ import annotations

import json
import logging
import os
import re
import shlex
import sys
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from tactbench.data.windows import UNNAMED_TEST_WINDOW
from tactbench.errors import CorruptArtefactError, InputError, is_finite_number
from tactbench.integrity import hash_bytes, read_regular_bytes
from tactbench.runner.execution.identity import IDENTITY_DEFAULTS, INDEPENDENT_RUNS  # noqa: F401
from tactbench.specs import POSITIONAL, parse_spec
from tactbench.paths import (
    Temporary,
    atomic_write_text,
    parse_temporary,
    remove_orphans,
    temp_name,
)


log = logging.getLogger("tactbench.runner.execution.results")

OK = "ok"
FAILED = "failed"

#: Costs a row may hold (numbers; reports average them).
COST_FIELDS = ("encode_ms_per_frame", "train_s", "inference_ms_per_sequence", "peak_rss_mb")

#: A cell file larger than this is not a row tactbench wrote (rows are a few kB).
ROW_MAX_BYTES = 16 << 20



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
        if row.get(field) is not None and not is_finite_number(row[field]):
            return f"has a {field} that is not a finite number"
    status = row.get("status", OK)
    if status == OK:
        if not is_finite_number(row.get("accuracy")) or not 0.0 <= row["accuracy"] <= 1.0:
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
                v is None or (is_finite_number(v) and 0.0 <= v <= 1.0) for v in per_class.values()):
            return "has no per-class accuracy (a number in [0, 1] or null per class)"
        problem = _check_predictions(row.get("test_predictions"), k)
        if problem is not None:
            return problem
    elif status == FAILED:
        if not isinstance(row.get("error"), dict):
            return "is a failed row without its error"
    else:
        return f"has an unknown status {str(status)[:40]!r}"
    planned = json.loads(json.dumps(identity or {}))
    for field, value in planned.items():
        if row.get(field) != value:
            return f"records {field} = {str(row.get(field))[:40]!r}, the cell has {value!r}"
    for field, default in IDENTITY_DEFAULTS.items() if identity is not None else ():
        if field not in planned and row.get(field, default) != default:  # left out: default
            return f"records {field} = {str(row.get(field))[:40]!r}, the cell has {default!r}"
    return None


def _check_predictions(tp: Any, k: int) -> str | None:
    """Problems of a row's per-sequence predictions (optional: older rows lack them, and
    rows made before folds and groups were stored lack those two lists)."""
    if tp is None:
        return None
    if not isinstance(tp, dict) or not {"indices", "labels", "predictions"} <= set(tp) \
            or not set(tp) <= {"indices", "labels", "predictions", "folds", "groups"}:
        return "has test_predictions that are not {indices, labels, predictions[, folds, " \
               "groups]}"
    lists = list(tp.values())
    if not all(isinstance(v, list) for v in lists) or len({len(v) for v in lists}) != 1:
        return "has test_predictions that are not lists of one length"
    for name, top in (("indices", None), ("labels", k), ("predictions", k), ("folds", None)):
        if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0
                   and (top is None or n < top) for n in tp.get(name, ())):
            return f"has test_predictions {name} that are not class/sequence/fold numbers"
    if not all(isinstance(g, str) for g in tp.get("groups", ())):
        return "has test_predictions groups that are not text"
    if len(set(tp["indices"])) != len(tp["indices"]):
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

    def clean(self) -> list[Temporary]:
        """Remove temporary row files whose writing process is gone; returns them."""
        return remove_orphans(self.cells)

    def rows(self, keys: Iterable[str]) -> list[dict[str, Any]]:
        """The stored rows of ``keys``, in that order, skipping cells without a sound one."""
        return [row for key in keys if (row := self.get(key)) is not None]

    def keys(self) -> list[str]:
        """The keys of every cell file in ``OUT/cells`` (sound or not), sorted."""
        if not self.cells.is_dir():
            return []
        return sorted(p.stem for p in self.cells.glob("*.json") if not p.name.startswith("."))

    def stored_rows(self, *, quiet: bool = False) -> list[dict[str, Any]]:
        """Every sound row of the folder, ok and failed, in :func:`scene_order`; a damaged
        one is named in a warning and left out (as :meth:`get` does) — or, ``quiet``, left
        out without a word, for a second read of a folder whose damage was already said."""
        if not quiet:
            return scene_order(self.rows(self.keys()))
        sound = []
        for key in self.keys():
            try:
                row = self.read(key)
            except CorruptArtefactError:
                continue
            if row is not None:
                sound.append(row)
        return scene_order(sound)

    # ------------------------------------------------------- runs sharing an out folder

    def check_grid(self, keys: Iterable[str],
                   identities: dict[str, dict[str, Any]] | None = None) -> None:
        """Refuse (:class:`InputError`) a grid of cells ``keys`` that leaves out cells
        stored in this out folder (another grid's): the first half of :meth:`claim`,
        which writes nothing, so that ``tactbench plan`` refuses what ``run`` would, in
        the same line."""
        planned = set(keys)
        stray = [key for key in self.keys() if key not in planned]
        if stray:
            first = _describe(self.path(stray[0]), identities)
            raise InputError(f"out folder {self.out} holds {len(stray)} cell(s) of another "
                             f"grid ({first}) that this run does not plan, and its report "
                             f"would leave them out; give a new --out, or a grid that "
                             f"includes them")

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
        whose report this run would replace. Only ``cells/`` counts: results.json is
        rendered from it and never read. Two runs at once must plan the same grid; of
        two different ones, the later is refused, naming the first.
        """
        keys = sorted(set(keys))
        out = self.out
        self.check_grid(keys, identities)
        self.cells.mkdir(parents=True, exist_ok=True)
        mine = self.cells / temp_name("run")
        atomic_write_text(mine, json.dumps({"keys": keys, "command": command_line()}))
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


def command_line(argv: Sequence[str] | None = None) -> str:
    """The command line a row, a claim and a report record, as a user would type it
    again: ``tactbench ARGS`` however tactbench was started (its script, ``python -m
    tactbench``), else the program's name and its arguments (a script, a notebook's
    kernel); quoted where an argument needs it. The one place it is written."""
    argv = list(sys.argv if argv is None else argv)
    if not argv:
        return "python"
    program = Path(argv[0])
    if program.name == "tactbench" or (program.name == "__main__.py"
                                       and program.parent.name == "tactbench"):
        return shlex.join(["tactbench", *argv[1:]])
    return shlex.join([program.name, *argv[1:]])


def _describe(path: Path, identities: dict[str, dict[str, Any]] | None = None) -> str:
    """``encoder × classifier L=.. seed=.. from `command``` for a stored cell file, as
    far as it reads; with the planned ``identities``, also how it differs from the
    nearest."""
    try:
        row = json.loads(read_regular_bytes(path, limit=ROW_MAX_BYTES))
        label = (f"{row['encoder']} × {str(row['classifier']).split(':')[0]} L={row['L']} "
                 f"seed={row['seed']}")
        command = (row.get("run") or {}).get("command")
        label += f", from `{command}`" if command else ""
    except Exception:  # noqa: BLE001 — only a description; the file is named instead
        return path.name
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


# ------------------------------------------------------------------ the order of a report


def row_scene(row: dict[str, Any]) -> dict[str, Any] | None:
    """The scene (as its fields) that planned ``row``, ``run.scene``; None when the row
    records none (written before rows did, or not a mapping where one belongs)."""
    run = row.get("run")
    scene = run.get("scene") if isinstance(run, dict) else None
    return scene if isinstance(scene, dict) else None


def latest_scene(rows: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """The scene (as its fields, ``run.scene``) recorded by the row finished last, ``{}``
    when no row records one. One out folder holds one grid and every run plans every cell
    already there (:meth:`ResultStore.claim`), so this scene covers every row."""
    stamped = [((str(r.get("finished", "")), str(r.get("key", ""))), scene) for r in rows
               if (scene := row_scene(r)) is not None]
    return max(stamped, key=lambda pair: pair[0])[1] if stamped else {}


def scene_order(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` in the order their scene planned them: encoders, classifiers, L, seeds and
    initialisation seeds as the scene lists them, so that a report made from a folder's
    cells alone says ``farneback − raw`` where the run listed raw first.

    The scene is :func:`latest_scene`'s. A cell's spec is placed
    at the scene's spec that names it with the most matching options (a classifier's
    row spec adds its profile's); what no scene names (rows without one) comes after,
    in sorted order.
    """
    rows = list(rows)
    scene = latest_scene(rows)
    lengths = scene.get("L") or scene.get("lengths") or []  # "lengths": older scenes

    def place(value: Any, listed: Sequence[Any] | None) -> int:
        listed = list(listed or [])
        return listed.index(value) if value in listed else len(listed)

    def sort_key(row: dict[str, Any]) -> tuple:
        init = row.get("init_seed")
        return (_spec_place(row["encoder"], scene.get("encoders")), row["encoder"],
                _spec_place(row["classifier"], scene.get("classifiers")), row["classifier"],
                place(row["L"], lengths), row["L"], place(row["seed"], scene.get("seeds")),
                row["seed"], place(init, scene.get("init_seeds")), -1 if init is None else init)

    return sorted(rows, key=sort_key)


def _spec_place(spec: str, listed: Sequence[str] | None) -> int:
    """The index of the spec in ``listed`` that names ``spec`` with the most matching
    options (none differing); ``len(listed)`` when none names it."""
    listed = [s for s in (listed or []) if isinstance(s, str)]
    try:
        name, options = parse_spec(spec)
    except InputError:
        return len(listed)
    best, place = -1, len(listed)
    for i, given in enumerate(listed):
        try:
            given_name, given_options = parse_spec(given)
        except InputError:
            continue
        if given_name != name:
            continue
        matched = 0
        for key, value in given_options.items():
            if key == POSITIONAL:  # "sklearn:SVC" → estimator=SVC
                if value not in options.values():
                    break
            elif key in options and options[key] != value:
                break
            matched += 1
        else:
            if matched > best:
                best, place = matched, i
    return place


# ---------------------------------------------------------------- what a run writes

#: The figures a report draws (:mod:`tactbench.runner.presentation.plots`), one PNG each.
FIGURES = ("accuracy_vs_L", "cost_vs_accuracy", "per_class_vs_L", "per_user_accuracy")
#: Every top-level file a run writes (``confusion_*.png`` besides, one per cell; the
#: Parquet tables of ``tactbench report --parquet``, :mod:`tactbench.runner.presentation.frames`).
OUT_FILES = ("run-record.json", "results.json", "results.csv", "report.md", "cells.parquet",
             "comparisons.parquet", *(f"{name}.png" for name in FIGURES))
#: The folders a run writes at the top of its out folder.
OUT_FOLDERS = ("cells", "models")
#: report.md begins with this line; a report.md without it is not tactbench's.
REPORT_HEADER = "# tactbench report"
_CONFUSION = re.compile(r"confusion_.+\.png")


def run_folder_entries(out: str | Path) -> Callable[[Path], bool]:
    """What the out folder ``out`` may hold for a run to go on: what a run writes
    (:func:`is_run_output`); and, in a folder an earlier run made (its ``cells/`` holds
    rows), anything else beside it too (a plugin's state file, a benchmark's notes),
    which a run never writes over. A run's own names stay checked there: a report.md
    tactbench did not write is refused in both."""
    earlier = bool(ResultStore(out).keys())
    taken = {*OUT_FILES, *OUT_FOLDERS}

    def ours(path: Path) -> bool:
        return is_run_output(path) or (earlier and path.name not in taken
                                       and not _CONFUSION.fullmatch(path.name))

    return ours


def is_run_output(path: Path) -> bool:
    """Whether ``path``, at the top of an out folder, is one a run writes (and may write
    again): ``cells/``, ``models/``, :data:`OUT_FILES`, ``confusion_*.png`` (a file by
    such a name, never a folder); a report.md only when it begins with
    :data:`REPORT_HEADER`."""
    name = path.name
    if name in OUT_FOLDERS:
        return path.is_dir() or not path.exists()
    if name == "report.md" and (path.exists() or path.is_symlink()):
        if not path.is_file():  # a FIFO, a device, a dangling link: not ours, never opened
            return False
        with open(path, "rb") as fh:
            return fh.read(len(REPORT_HEADER)) == REPORT_HEADER.encode()
    if name in OUT_FILES or _CONFUSION.fullmatch(name):
        return not path.is_dir()  # a folder by a file's name is not what a run wrote
    return False
