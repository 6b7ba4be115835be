"""A tactbench run folder as MLflow runs, through MLflow's own client.

One *parent* run per run folder (tag ``tactbench.folder``); under it one run per cell
(params: the cell's spec; metrics: accuracy, per-class accuracy and costs; tags: the cell
key, git revision, machine) and one run per paired comparison (metrics: the difference
B − A, its interval ends, p, Holm p, runs, and the verdict as ``verdict_code``: +1 B
better, −1 A better, 0 equivalent, NaN unresolved; tags: the verdict and the keys of the
cells compared). Runs are found again by their keys, so exporting twice adds nothing;
a cell or comparison whose content changed (a failed cell computed again, a comparison
with more runs) replaces its run.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any

from tactbench.errors import TactbenchError, require
from tactbench.machine import describe_machines
from tactbench.runner import render_folder
from tactbench.runner.presentation.frames import comparison_record
from tactbench.runner.execution.results import row_status

#: The experiment runs go to unless another is named.
EXPERIMENT = "tactbench"
#: What installs the library when it is missing.
INSTALL = "tactbench-mlflow (with its dependency mlflow-skinny)"
#: The cell's fields logged as MLflow params.
CELL_PARAMS = ("dataset", "split", "test_window", "encoder", "classifier", "L", "seed",
               "profile", "device", "threads", "status", "n_test")
#: The row's numbers logged as MLflow metrics.
CELL_METRICS = ("accuracy", "encode_ms_per_frame", "train_s", "inference_ms_per_sequence",
                "peak_rss_mb")
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


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(float(value)) else None


class Exporter:
    """An MLflow client on one tracking URI and experiment (:meth:`connect`)."""

    def __init__(self, client: Any, uri: str, experiment_id: str) -> None:
        self.client, self.uri, self.experiment_id = client, uri, experiment_id
        self._parents: dict[str, str] = {}

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
        _CONNECTED[key] = cls(client, uri, experiment_id)
        return _CONNECTED[key]

    # ------------------------------------------------------------------ finding runs

    def _find(self, **tags: str) -> list[Any]:
        where = " and ".join(f"tags.`{k}` = {_quoted(v)}" for k, v in tags.items())
        return self.client.search_runs([self.experiment_id], filter_string=where,
                                       max_results=1000)

    def parent(self, out: str | Path) -> str:
        """The id of the parent run of the run folder ``out`` (made when missing)."""
        folder = str(Path(out).resolve())
        if folder not in self._parents:
            found = self._find(**{"tactbench.kind": "folder",
                                  "tactbench.folder_id": _digest(folder)})
            self._parents[folder] = found[0].info.run_id if found else self._new_run(
                None, {"mlflow.runName": Path(folder).name, "tactbench.kind": "folder",
                       "tactbench.folder": folder, "tactbench.folder_id": _digest(folder)},
                {}, {}, "RUNNING")
        return self._parents[folder]

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

    def _upsert(self, parent: str, key_tags: dict[str, str], digest: str, make) -> bool:
        """Log the run ``make()`` gives ``(tags, params, metrics, status)`` unless a run
        with ``key_tags`` and this ``digest`` is there already; an older one (another
        digest) is deleted first. Whether a run was logged."""
        found = self._find(**key_tags, **{"mlflow.parentRunId": parent})
        if any(r.data.tags.get("tactbench.digest") == digest for r in found):
            return False
        for old in found:
            self.client.delete_run(old.info.run_id)
        tags, params, metrics, status = make()
        self._new_run(parent, {**tags, **key_tags, "tactbench.digest": digest}, params,
                      metrics, status)
        return True

    # ------------------------------------------------------------------ what is logged

    def log_cell(self, out: str | Path, row: dict[str, Any]) -> bool:
        """The cell ``row`` of the run folder ``out`` as a run under its parent; False
        when it was logged already (same key, same content)."""
        parent = self.parent(out)
        return self._upsert(parent, {"tactbench.kind": "cell",
                                     "tactbench.cell_key": str(row["key"])},
                            str(row.get("checksum") or _digest(row)),
                            lambda: cell_run(row))

    def log_comparison(self, out: str | Path, record: dict[str, Any]) -> bool:
        """One comparison (:func:`tactbench.runner.presentation.frames.comparison_record`) as a run."""
        identity = {k: record[k] for k in ("family", "dataset", "split", "factor", "a",
                                           "b", "encoder", "classifier", "L")}
        return self._upsert(self.parent(out), {"tactbench.kind": "comparison",
                                               "tactbench.comparison_key": _digest(identity)},
                            _digest(record), lambda: comparison_run(record))

    def log_report(self, out: str | Path, report: Any, *, cells: bool = True
                   ) -> dict[str, int]:
        """Every row (with ``cells``) and every comparison of ``report``: counts of
        runs ``logged`` and ``unchanged``."""
        done = [self.log_cell(out, row) for row in report.rows] if cells else []
        done += [self.log_comparison(out, comparison_record(c, report.rows))
                 for c in report.comparisons]
        return {"logged": sum(done), "unchanged": len(done) - sum(done)}


def cell_run(row: dict[str, Any]) -> tuple[dict, dict, dict, str]:
    """``(tags, params, metrics, status)`` of a cell's run."""
    run = row.get("run") if isinstance(row.get("run"), dict) else {}
    tags = {"mlflow.runName": f"{row.get('encoder')} × {row.get('classifier')} "
                              f"L={row.get('L')} seed={row.get('seed')}",
            "tactbench.git": str(run.get("git")), "mlflow.source.git.commit": str(run.get("git")),
            "tactbench.machine": describe_machines([row]),
            "tactbench.command": str(run.get("command"))[:5000]}
    if "error" in row:
        tags["tactbench.error"] = f"{row['error'].get('type')}: {row['error'].get('message')}"[:5000]
    params = {k: row[k] for k in CELL_PARAMS if row.get(k) is not None}
    metrics = {k: v for k in CELL_METRICS if (v := _number(row.get(k))) is not None}
    for name, value in (row.get("per_class_accuracy") or {}).items():
        if (number := _number(value)) is not None:
            metrics[f"accuracy_{name}"] = number
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
    logged once (:meth:`Exporter.log_report`)."""
    report = render_folder(out, plots=False, write=False, registry=registry)
    exporter = Exporter.connect(uri, experiment)
    try:
        counts = exporter.log_report(out, report)
        exporter.client.set_terminated(exporter.parent(out), status="FINISHED")
    except TactbenchError:
        raise
    except Exception as exc:
        raise TrackingError(f"MLflow tracking URI {uri} refused a run: "
                            f"{_first_line(exc)}; exporting again finishes it") from None
    return counts


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0][:300] if text else ''}"
