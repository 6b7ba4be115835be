"""A tactbench run folder as MLflow runs, through MLflow's own client.

One *parent* run per grid of a run folder (tags ``tactbench.folder`` and
``tactbench.grid_id``, the digest of :func:`~tactbench.runner.execution.planning.
grid_identity`), found again only when every cell run under it is a cell of the grid
(:meth:`Exporter.parent`: a new grid in a reused folder, differing in any identity field of
any cell, gets a parent of its own; more seeds keep it); under it one run
per cell (params: every field of the cell's identity and its learning status; metrics:
accuracy, per-class accuracy (:func:`class_metric`), train accuracy, the chance levels
and costs; tags: the cell key, git revision, machine, the cell's learning judged over its
runs) and one run per paired comparison (metrics: the difference B − A, its interval
ends, p, Holm p, runs, and the verdict as ``verdict_code``: +1 B better, −1 A better, 0
equivalent, NaN unresolved; tags: the verdict and the keys of the cells compared). Runs
are found again by their keys, so exporting twice adds nothing; a cell or comparison
whose content changed (a failed cell computed again, a comparison with more runs)
replaces its run. A parent is RUNNING only while an export or a live-logged run writes
under it: the end of either, or its failure, ends it (FINISHED, or FAILED).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from pathlib import Path
from typing import Any

from tactbench.data.windows import UNNAMED_TEST_WINDOW
from tactbench.errors import TactbenchError, require
from tactbench.machine import describe_machines
from tactbench.runner import (cell_learning, comparison_record, flat_rows, grid_identity,
                              render_folder, row_evidence, row_identity, row_status)

#: The experiment runs go to unless another is named.
EXPERIMENT = "tactbench"
#: What installs the library when it is missing.
INSTALL = "tactbench-mlflow (with its dependency mlflow-skinny)"
#: The cell's fields logged as MLflow params (with every identity field of results.csv,
#: :data:`IDENTITY_PARAMS`).
CELL_PARAMS = ("device", "status", "n_test", "learning")
#: Every identity field, as results.csv has it (a field left out at its default shows
#: the default): cells differing in one (an init seed) never look alike.
IDENTITY_PARAMS = ("dataset", "dataset_hash", "split", "test_window", "test_per_class",
                   "imaging", "encoder", "encoder_version", "precision", "classifier",
                   "profile", "L", "seed", "init_seed", "input", "run_dataset",
                   "independent_runs", "threads", "cpu_kernels", "schema")
#: The row's numbers logged as MLflow metrics.
CELL_METRICS = ("accuracy", "train_accuracy", "train_chance", "chance_accuracy",
                "encode_ms_per_frame", "train_s", "inference_ms_per_sequence", "peak_rss_mb")
#: The tag of a cell's run holding the cell's learning judged over all its runs (the
#: report's †: learned, did not learn, did not transfer, not above chance).
CELL_LEARNING_TAG = "tactbench.cell_learning"
#: What a class name keeps as it is in a metric name (``accuracy_<class>``); every other
#: character, and ``.``, is written ``.XX`` per UTF-8 byte (:func:`metric_class`).
_KEPT = re.compile(r"[A-Za-z0-9_\- ]")
#: MLflow's longest metric, param and tag name (``MAX_ENTITY_KEY_LENGTH`` of
#: ``mlflow.utils.validation``) and its longest tag value kept whole
#: (``MAX_TAG_VAL_LENGTH``; a longer one is cut).
MAX_NAME, MAX_TAG_VALUE = 250, 8000
#: Where a shortened metric name's readable head ends and the hash of its class name
#: begins: never written by :func:`metric_class`, whose ``.`` is followed by two hex digits.
HASHED = "._"
#: The tag of a cell's run that gives back the class name of a shortened metric name:
#: ``tactbench.names.<hash>`` (:func:`class_metric`).
NAMES_TAG = "tactbench.names."
#: The comparison's numbers logged as metrics.
COMPARISON_METRICS = ("difference", "low", "high", "p", "p_holm", "runs", "accuracy_a",
                      "accuracy_b", "equivalence_p")
VERDICT_CODES = {"B better": 1.0, "A better": -1.0, "equivalent": 0.0}
_CONNECTED: dict[tuple[str, str], "Exporter"] = {}


class TrackingError(TactbenchError):
    """The MLflow tracking URI cannot be reached or refused a write: one line naming it."""


def _quoted(value: str) -> str:
    return "'" + value.replace("\\", "\\\\").replace("'", "\\'") + "'"


def _digest(value: Any) -> str:
    text = json.dumps(value, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def metric_class(name: str) -> str:
    """A class name as MLflow takes it in a metric name, reversibly
    (:func:`class_of_metric`): letters, digits, ``_``, ``-`` and spaces kept; every other
    character, ``.`` included, written ``.XX``, the hex of each of its UTF-8 bytes
    (``tap+hold`` → ``tap.2Bhold``, ``swipe (left)`` → ``swipe .28left.29``)."""
    return "".join(ch if _KEPT.fullmatch(ch) else "".join(f".{b:02X}" for b in ch.encode())
                   for ch in str(name))


def class_metric(name: str) -> tuple[str, dict[str, str]]:
    """The metric name of the accuracy of class ``name`` and the tags that read it back:
    ``accuracy_`` + :func:`metric_class` (no tags), or, where that is longer than MLflow
    takes (:data:`MAX_NAME` characters), its first characters (never half an escape),
    :data:`HASHED` and the first 16 hex digits of the SHA-256 of the class name, with the
    tag ``tactbench.names.<those digits>`` holding the class name
    (:func:`class_of_metric` reads both). A class name longer than a tag keeps
    (:data:`MAX_TAG_VALUE`) is one line: its metric could not be read back."""
    full = f"accuracy_{metric_class(name)}"
    if len(full) <= MAX_NAME:
        return full, {}
    if len(str(name)) > MAX_TAG_VALUE:
        raise TactbenchError(f"class name {str(name)[:60]!r}... has {len(str(name))} "
                             f"characters; an MLflow tag keeps {MAX_TAG_VALUE}, so its "
                             f"accuracy could not be named reversibly: shorten it")
    hashed = hashlib.sha256(str(name).encode()).hexdigest()[:16]
    head = full[:MAX_NAME - len(HASHED) - len(hashed)]
    dot = head.rfind(".", len(head) - 2)  # an escape (.XX) cut short: left out whole
    head = head[:dot] if dot >= 0 else head
    return head + HASHED + hashed, {NAMES_TAG + hashed: str(name)}


def class_of_metric(text: str, tags: dict[str, str] | None = None) -> str:
    """The class name :func:`metric_class` wrote as ``text`` (a metric name without its
    ``accuracy_``), or, for a shortened name (:func:`class_metric`), the one the run's
    ``tags`` hold for its hash."""
    if HASHED in text:
        hashed = text.rsplit(HASHED, 1)[1]
        if tags is None or NAMES_TAG + hashed not in tags:
            raise ValueError(f"{text[:60]!r}... is a shortened name: its run's tag "
                             f"{NAMES_TAG + hashed} holds the class name")
        return tags[NAMES_TAG + hashed]
    raw, i = bytearray(), 0
    while i < len(text):
        if text[i] == ".":
            raw.append(int(text[i + 1:i + 3], 16))
            i += 3
        else:
            raw += text[i].encode()
            i += 1
    return raw.decode()


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(float(value)) else None


class Exporter:
    """An MLflow client on one tracking URI and experiment (:meth:`connect`)."""

    def __init__(self, client: Any, uri: str, experiment_id: str) -> None:
        self.client, self.uri, self.experiment_id = client, uri, experiment_id
        # the parent this exporter writes under per (folder, grid id), with its cells' keys
        self._parents: dict[tuple[str, str], tuple[str, set[str]]] = {}
        self._opened: set[str] = set()  # the parents it set RUNNING: end() ends them
        self.live_failed = False  # a live-logged cell was refused: its parent ends FAILED

    @classmethod
    def connect(cls, uri: str, experiment: str = EXPERIMENT) -> "Exporter":
        """The exporter of ``uri`` (a local path or ``file:`` URI, ``sqlite:///FILE``,
        ``http(s)://`` a server) and ``experiment`` (made when missing), checked by one
        request before anything is written: :class:`TrackingError` when it fails."""
        key = (uri, experiment)
        if key in _CONNECTED:
            return _CONNECTED[key]
        if "://" not in uri or uri.startswith("file:"):
            # the file store is in maintenance in MLflow 3 and refused unless allowed;
            # the user named it, so it is allowed here
            os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
        os.environ.setdefault("MLFLOW_HTTP_REQUEST_MAX_RETRIES", "1")
        os.environ.setdefault("MLFLOW_HTTP_REQUEST_TIMEOUT", "10")
        tracking = require("mlflow.tracking", INSTALL)
        try:
            client = tracking.MlflowClient(tracking_uri=uri)
            found = client.get_experiment_by_name(experiment)
            experiment_id = (found.experiment_id if found is not None
                             else client.create_experiment(experiment))
        except Exception as exc:  # MLflow raises many kinds: each is this one line
            raise TrackingError(f"MLflow tracking URI {uri} cannot be used: "
                                f"{_first_line(exc)}") from None
        if found is not None and found.lifecycle_stage == "deleted":
            raise TrackingError(
                f"MLflow experiment {experiment!r} at {uri} is deleted (id "
                f"{found.experiment_id}), and a deleted experiment takes no runs: restore it "
                f"(mlflow experiments restore --experiment-id {found.experiment_id}) or "
                f"name another experiment; nothing was logged")
        _CONNECTED[key] = cls(client, uri, experiment_id)
        return _CONNECTED[key]

    # ------------------------------------------------------------------ finding runs

    def _find(self, **tags: str) -> list[Any]:
        where = " and ".join(f"tags.`{k}` = {_quoted(v)}" for k, v in tags.items())
        return self.client.search_runs([self.experiment_id], filter_string=where,
                                       max_results=1000)

    def parent(self, out: str | Path, row: dict[str, Any], grid_cells: set[str]) -> str:
        """The id of the parent run of the grid of ``row`` in the run folder ``out``
        (made, RUNNING, when missing; found ended, it is RUNNING again while this
        exporter writes under it). ``grid_cells``: the keys of every cell of the grid (a
        folder's rows; during a run, the cells its folder holds so far).

        A parent is the grid's when it is of this folder, has the grid's shared identity
        (:func:`~tactbench.runner.execution.planning.grid_identity`, tag
        ``tactbench.grid_id``) and every cell run under it is a cell of the grid: a
        cell's key digests every field of its identity, so a grid that differs in any
        field of any cell (an encoder's version or option, an input, a pixel size) holds
        none of the old parent's cells and gets a parent of its own, while a run that
        only adds cells to the folder's grid (seeds, init seeds: the cells already there
        stay in it) keeps its parent."""
        folder = str(Path(out).resolve())
        grid = grid_identity(row)
        keys = {"tactbench.kind": "folder", "tactbench.folder_id": _digest(folder),
                "tactbench.grid_id": _digest(grid)}
        place, cells = (folder, keys["tactbench.grid_id"]), {*grid_cells, str(row["key"])}
        held = self._parents.get(place)
        if held is None or not held[1] <= cells:  # a parent of another grid of the folder
            held = self._grid_parent(keys, grid, cells)
            if held is None:
                held = (self._new_run(None, {
                    "mlflow.runName": Path(folder).name, "tactbench.folder": folder,
                    "tactbench.grid": json.dumps(grid, sort_keys=True, default=str)[:5000],
                    **keys}, {}, {}, "RUNNING"), set())
            self._parents[place] = held
            self._opened.add(held[0])
        held[1].add(str(row["key"]))
        return held[0]

    def _grid_parent(self, keys: dict[str, str], grid: dict[str, Any], cells: set[str]
                     ) -> tuple[str, set[str]] | None:
        """The parent run of this grid already logged (``(run id, keys of its cell
        runs)``), set RUNNING; None when there is none. A parent logged before parents
        had a grid (no ``tactbench.grid_id``) is adopted (given the grid's tags) when its
        cell runs are all of the grid by their params too (dataset, split, test window,
        profile, threads), so that exporting again after an upgrade adds nothing."""
        folder_only = {k: v for k, v in keys.items() if k != "tactbench.grid_id"}
        for parent in self._find(**folder_only):
            tags = parent.data.tags
            legacy = "tactbench.grid_id" not in tags
            if not legacy and tags["tactbench.grid_id"] != keys["tactbench.grid_id"]:
                continue
            runs = self._find(**{"tactbench.kind": "cell",
                                 "mlflow.parentRunId": parent.info.run_id})
            held = {r.data.tags.get("tactbench.cell_key") for r in runs}
            if not held <= cells or legacy and not (
                    runs and all(_of_grid(r.data.params, grid) for r in runs)):
                continue
            run_id = parent.info.run_id
            if legacy:
                self.client.set_tag(run_id, "tactbench.grid_id", keys["tactbench.grid_id"])
                self.client.set_tag(run_id, "tactbench.grid",
                                    json.dumps(grid, sort_keys=True, default=str)[:5000])
            if parent.info.status != "RUNNING":
                self.client.update_run(run_id, status="RUNNING")
            return run_id, held
        return None

    def end(self, status: str = "FINISHED") -> None:
        """End every parent run this exporter made or found RUNNING (``status``:
        FINISHED, or FAILED after a refused write), so that none is left RUNNING."""
        for run_id in sorted(self._opened):
            self.client.set_terminated(run_id, status=status)
        self._opened.clear()
        self._parents.clear()

    def _new_run(self, parent: str | None, tags: dict[str, str], params: dict[str, Any],
                 metrics: dict[str, float], status: str = "FINISHED") -> str:
        """A run with everything logged in one batch; removed again if the batch fails."""
        entities = require("mlflow.entities", INSTALL)
        if parent is not None:
            tags = {**tags, "mlflow.parentRunId": parent}
        run = self.client.create_run(self.experiment_id, tags=tags,
                                     run_name=tags.get("mlflow.runName"))
        run_id = run.info.run_id
        try:
            self.client.log_batch(
                run_id, params=[entities.Param(k, str(v)) for k, v in params.items()],
                metrics=[entities.Metric(k, v, 0, 0) for k, v in metrics.items()])
            if status != "RUNNING":
                self.client.set_terminated(run_id, status=status)
        except BaseException:
            self.client.delete_run(run_id)
            raise
        return run_id

    def _upsert(self, parent: str, key_tags: dict[str, str], digest: str, make
                ) -> tuple[bool, Any]:
        """Log the run ``make()`` gives ``(tags, params, metrics, status)`` unless a run
        with ``key_tags`` and this ``digest`` is there already; an older one (another
        digest) is deleted first. ``(True, None)`` when a run was logged, ``(False, the
        run there)`` when not."""
        found = self._find(**key_tags, **{"mlflow.parentRunId": parent})
        same = [r for r in found if r.data.tags.get("tactbench.digest") == digest]
        if same:
            return False, same[0]
        for old in found:
            self.client.delete_run(old.info.run_id)
        tags, params, metrics, status = make()
        self._new_run(parent, {**tags, **key_tags, "tactbench.digest": digest}, params,
                      metrics, status)
        return True, None

    # ------------------------------------------------------------------ what is logged

    def log_cell(self, out: str | Path, row: dict[str, Any], grid_cells: set[str],
                 judged: str | None = None) -> bool:
        """The cell ``row`` of the run folder ``out`` as a run under its grid's parent
        (:meth:`parent`; ``grid_cells``: the keys of the grid's cells; ``judged``: the
        cell's learning over all its runs, where known); False when it was logged
        already (same key, same content)."""
        parent = self.parent(out, row, grid_cells)
        logged, there = self._upsert(parent, {"tactbench.kind": "cell",
                                              "tactbench.cell_key": str(row["key"])},
                                     str(row.get("checksum") or _digest(row)),
                                     lambda: cell_run(row, judged))
        if there is not None and judged is not None \
                and there.data.tags.get(CELL_LEARNING_TAG) != judged:
            # the row is the same; the judgement over the cell's runs grew with them
            self.client.set_tag(there.info.run_id, CELL_LEARNING_TAG, judged)
        return logged

    def log_comparison(self, out: str | Path, record: dict[str, Any],
                       row: dict[str, Any], grid_cells: set[str]) -> bool:
        """One comparison (:func:`tactbench.runner.comparison_record`) as a run under the
        parent of the grid of ``row`` (:meth:`parent`)."""
        identity = {k: record[k] for k in ("family", "dataset", "split", "factor", "a",
                                           "b", "encoder", "classifier", "L")}
        return self._upsert(self.parent(out, row, grid_cells),
                            {"tactbench.kind": "comparison",
                             "tactbench.comparison_key": _digest(identity)},
                            _digest(record), lambda: comparison_run(record))[0]

    def log_record(self, out: str | Path, record: dict[str, Any], *, cells: bool = True
                   ) -> dict[str, int]:
        """Every row (with ``cells``) and every comparison of a run's or a look's
        ``record`` (what the ``run_finished`` and ``look_finished`` hooks receive,
        :func:`tactbench.runner.run_summary`, :func:`tactbench.runner.look_record`):
        counts of runs ``logged`` and ``unchanged``."""
        rows = record["rows"]
        if not rows:
            return {"logged": 0, "unchanged": 0}
        judged = cells_learning(rows)
        grid = {str(row["key"]) for row in rows}  # the folder's grid: every cell
        done = [self.log_cell(out, row, grid, judged.get(_cell_of(row))) for row in rows
                ] if cells else []
        done += [self.log_comparison(out, c, rows[0], grid) for c in record["comparisons"]]
        self.tag_record(record.get("record"))
        return {"logged": sum(done), "unchanged": len(done) - sum(done)}

    def tag_record(self, resolved: dict[str, Any] | None) -> None:
        """What the run resolved once (its record, ``RunRecord.to_json``: computation,
        workers, paired test, primary questions) as tags of each parent run it logged
        to; nothing for a record of a folder exported after the fact (no run record)."""
        if not resolved:
            return
        workers = resolved.get("workers") or {}
        tags = {"tactbench.record.compute": json.dumps(resolved.get("compute"), sort_keys=True),
                "tactbench.record.workers": f"{workers.get('count')} ({workers.get('limit')})",
                "tactbench.record.paired_test": str(resolved.get("paired_test")),
                "tactbench.record.primary": json.dumps(
                    (resolved.get("design") or {}).get("primary") or [])[:5000]}
        for run_id in sorted(self._opened):
            for name, value in tags.items():
                self.client.set_tag(run_id, name, value)


def _of_grid(params: dict[str, str], grid: dict[str, Any]) -> bool:
    """Whether a cell run's params (as logged before parents had a grid) are of ``grid``."""
    logged = {"test_window": UNNAMED_TEST_WINDOW, "threads": "1", **params}
    return all(logged.get(f) == str(grid.get(f)) for f in ("dataset", "split", "test_window",
                                                           "profile", "threads"))


def _cell_of(row: dict[str, Any]) -> tuple:
    """The cell a row is a run of (one per seed): its identity but the seed."""
    return tuple(sorted((k, json.dumps(v, sort_keys=True, default=str))
                        for k, v in row_identity(row).items() if k != "seed"))


def cells_learning(rows: list[dict[str, Any]]) -> dict[tuple, str]:
    """Each cell's learning judged over all its runs (the report's †:
    :func:`~tactbench.runner.execution.learning.cell_learning`), by :func:`_cell_of`."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(_cell_of(row), []).append(row)
    judged = {cell: cell_learning(group) for cell, group in groups.items()}
    return {cell: j.status for cell, j in judged.items() if j is not None}


def cell_run(row: dict[str, Any], judged: str | None = None
             ) -> tuple[dict, dict, dict, str]:
    """``(tags, params, metrics, status)`` of a cell's run: params every identity field
    (as results.csv has it) and the run's learning status, metrics its accuracy, train
    accuracy, chance levels, ``accuracy_<class>`` (:func:`class_metric`) and costs;
    ``judged``: the cell's learning over all its runs (tag ``tactbench.cell_learning``)."""
    run = row.get("run") if isinstance(row.get("run"), dict) else {}
    tags = {"mlflow.runName": f"{row.get('encoder')} × {row.get('classifier')} "
                              f"L={row.get('L')} seed={row.get('seed')}",
            "tactbench.git": str(run.get("git")), "mlflow.source.git.commit": str(run.get("git")),
            "tactbench.machine": describe_machines([row]),
            "tactbench.command": str(run.get("command"))[:5000]}
    if "error" in row:
        tags["tactbench.error"] = f"{row['error'].get('type')}: {row['error'].get('message')}"[:5000]
    if judged is not None:
        tags[CELL_LEARNING_TAG] = judged
    flat = flat_rows([row])[0]
    params = {k: flat.get(k) for k in IDENTITY_PARAMS}  # each one, None too: "None"
    params.update({k: v for k in CELL_PARAMS if (v := flat.get(k, row.get(k))) is not None})
    metrics = {k: v for k in CELL_METRICS if (v := _number(row.get(k))) is not None}
    evidence = row_evidence(row) if "chance_accuracy" not in metrics else None
    if evidence is not None:  # a row made before it recorded its chance level
        metrics["chance_accuracy"] = evidence[2]
    for name, value in (row.get("per_class_accuracy") or {}).items():
        if (number := _number(value)) is not None:
            metric, names = class_metric(name)  # too long for MLflow: shortened, tagged
            metrics[metric] = number
            tags.update(names)
    status = "FINISHED" if row_status(row) == "ok" else "FAILED"
    return tags, params, metrics, status


def comparison_run(record: dict[str, Any]) -> tuple[dict, dict, dict, str]:
    """``(tags, params, metrics, status)`` of a comparison's run."""
    where = ", ".join(f"{k}={record[k]}" for k in ("encoder", "classifier", "L")
                      if record.get(k) is not None)
    tags = {"mlflow.runName": f"{record['a']} → {record['b']}" + (f" ({where})" if where
                                                                  else ""),
            "tactbench.verdict": str(record["verdict"]), "tactbench.family": record["family"],
            "tactbench.cells_a": ",".join(record["cells_a"]),
            "tactbench.cells_b": ",".join(record["cells_b"])}
    params = {k: record[k] for k in ("family", "factor", "a", "b", "encoder", "classifier",
                                     "L", "method", "confidence", "dataset", "split")
              if record.get(k) is not None}
    metrics = {k: v for k in COMPARISON_METRICS if (v := _number(record.get(k))) is not None}
    metrics["verdict_code"] = VERDICT_CODES.get(record["verdict"], float("nan"))
    return tags, params, metrics, "FINISHED"


def export_folder(out: str | Path, uri: str, experiment: str = EXPERIMENT,
                  registry: Any = None) -> dict[str, int]:
    """The finished run folder ``out`` into MLflow at ``uri``: read (nothing written
    there; a folder that is not a run is one line), then every cell and comparison
    logged once (:meth:`Exporter.log_record`)."""
    report = render_folder(out, plots=False, write=False, registry=registry)
    record = {"rows": report.rows,
              "comparisons": [comparison_record(c, report.rows) for c in report.comparisons]}
    exporter = Exporter.connect(uri, experiment)
    try:
        counts = exporter.log_record(out, record)
    except BaseException as exc:
        failure = _end_failed(exporter)
        if isinstance(exc, TactbenchError) or not isinstance(exc, Exception):
            raise
        raise TrackingError(f"MLflow tracking URI {uri} refused a run: {_first_line(exc)}; "
                            f"the runs logged before it are kept, {failure}") from None
    exporter.end("FINISHED")
    return counts


def _end_failed(exporter: Exporter) -> str:
    """End the exporter's parents FAILED after a refused write; what became of them."""
    try:
        exporter.end("FAILED")
    except Exception as exc:  # the store refuses that too: say so, never that it ended
        return f"and the folder's parent run could not be ended ({_first_line(exc)})"
    return "and the folder's parent run is marked FAILED"


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0][:300] if text else ''}"
