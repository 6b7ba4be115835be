"""A run's results where researchers already look: pandas data frames and Parquet files.

:func:`cells_frame` is one row per cell (its spec, status, accuracy, costs, machine, git
revision), :func:`comparisons_frame` one row per paired comparison (A, B, the difference
B − A with its interval, p and Holm p, verdict, runs, family, and the keys of the cells
compared); both have typed columns (text as pandas ``string``, counts as nullable
``Int64``, measures as ``float64``, the finishing time as UTC timestamps).
:func:`write_parquet` writes both into a run folder as ``cells.parquet`` and
``comparisons.parquet`` (``tactbench report OUT --parquet``), readable by pandas and by
pyarrow alone. pandas and pyarrow are imported here only, on first use: the extra
``tactbench[export]`` installs them, and a missing one is one line
(:class:`~tactbench.errors.MissingExtraError`).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from tactbench.errors import MissingExtraError, require
from tactbench.machine import describe_machines
from tactbench.paths import atomic_write_bytes, discard
from tactbench.runner.analysis.records import COMPARISON_KINDS, comparison_record
from tactbench.runner.execution.results import INDEPENDENT_RUNS
from tactbench.runner.presentation.writers import csv_columns, flat_rows

if TYPE_CHECKING:
    import pandas

    from tactbench.runner.presentation.writers import Report

log = logging.getLogger("tactbench.runner.presentation.frames")

#: The extra that installs pandas and pyarrow.
EXTRA = "export"
#: The Parquet files :func:`write_parquet` writes into a run folder.
PARQUET_FILES = {"cells": "cells.parquet", "comparisons": "comparisons.parquet"}
#: The key of the Parquet schema metadata saying when and from what a file was made.
PARQUET_METADATA = b"tactbench"
#: kind of a column → its pandas dtype.
DTYPES = {"text": "string", "int": "Int64", "float": "float64", "bool": "boolean"}
#: The columns of :func:`cells_frame` that are not text (``acc_<class>`` are floats;
#: ``finished`` a UTC timestamp).
CELL_KINDS = {"split_seed": "int", "L": "int", "seed": "int", "init_seed": "int",
              "test_per_class": "int", "schema": "int", INDEPENDENT_RUNS: "bool",
              "accuracy": "float",
              "train_accuracy": "float", "chance_accuracy": "float",
              "encode_ms_per_frame": "float", "train_s": "float",
              "inference_ms_per_sequence": "float", "peak_rss_mb": "float",
              "n_train_windows": "int", "n_test": "int", "threads": "int"}


def cells_frame(report: "Report") -> "pandas.DataFrame":
    """One row per cell of ``report`` (ok and failed, in the scene's order): the columns
    of results.csv (:func:`~tactbench.runner.presentation.writers.csv_columns`: every
    identity field, status, accuracy, ``acc_<class>``, costs, ``key``, ``error``) with
    ``machine`` (the CPU and its torch kernels) and ``git`` (the revision that computed
    it) at the end; a failed cell has no accuracy or costs (missing values)."""
    pd = require("pandas", EXTRA)
    columns = csv_columns(report.rows)
    columns += ["machine", "git"]
    records = []
    for row, flat in zip(report.rows, flat_rows(report.rows)):
        run = row.get("run") if isinstance(row.get("run"), dict) else {}
        records.append({**flat, "machine": describe_machines([row]), "git": run.get("git")})
    data = {}
    for name in columns:
        values = [r.get(name) for r in records]
        if name == "finished":
            data[name] = pd.to_datetime(pd.Series(values, dtype="string"), utc=True,
                                        format="ISO8601")
            continue
        kind = "float" if name.startswith("acc_") else CELL_KINDS.get(name, "text")
        data[name] = _column(pd, values, kind)
    return pd.DataFrame(data, columns=columns)


def comparisons_frame(report: "Report") -> "pandas.DataFrame":
    """One row per paired comparison of ``report`` (:data:`COMPARISON_KINDS`): ``a`` and
    ``b`` the values compared (of ``factor``, or a contrast's sides), ``encoder``,
    ``classifier`` and ``L`` where both cells share them, ``difference`` = B − A with
    its interval ``low``–``high`` at ``confidence`` (accuracy fractions), ``p`` and
    ``p_holm`` (Holm within ``family``), ``verdict``, ``runs``, and ``cells_a`` /
    ``cells_b``: the keys of the cells (one per run) on each side."""
    pd = require("pandas", EXTRA)
    records = [comparison_record(c, report.rows) for c in report.comparisons]
    data = {name: _column(pd, [r[name] for r in records], kind)
            for name, kind in COMPARISON_KINDS.items()}
    return pd.DataFrame(data, columns=list(COMPARISON_KINDS))


def _column(pd: Any, values: list[Any], kind: str) -> Any:
    """``values`` as a pandas array of ``kind`` (:data:`DTYPES`; ``keys``: lists of text)."""
    if kind == "keys":
        return pd.Series([list(v) for v in values], dtype=object)
    if kind == "text":
        values = [None if v is None else str(v) for v in values]
    elif kind == "float":
        values = [float("nan") if v is None else float(v) for v in values]
    return pd.array(values, dtype=DTYPES[kind])


def write_parquet(report: "Report", out: str | Path) -> dict[str, Path]:
    """Write :func:`cells_frame` and :func:`comparisons_frame` of ``report`` into the
    folder ``out`` as :data:`PARQUET_FILES`; returns their paths. Both tables are made
    before either file is written, and each is written to a temporary file renamed into
    place: a failure leaves the old files (or none), never half of one. Each file says
    when and from how many rows it was made: its schema's :data:`PARQUET_METADATA` key
    holds JSON ``{"rendered": report.rendered, "cells": N, "comparisons": M}``."""
    pa = require("pyarrow", EXTRA)
    parquet = require("pyarrow.parquet", EXTRA)
    tables = {"cells": cells_frame(report), "comparisons": comparisons_frame(report)}
    said = json.dumps({"rendered": report.rendered, "cells": len(report.rows),
                       "comparisons": len(report.comparisons)}, default=str).encode()
    payloads = {}
    for name, frame in tables.items():
        sink = pa.BufferOutputStream()
        table = pa.Table.from_pandas(frame, preserve_index=False)
        table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                               PARQUET_METADATA: said})
        parquet.write_table(table, sink)
        payloads[name] = sink.getvalue().to_pybytes()
    paths = {name: Path(out) / PARQUET_FILES[name] for name in tables}
    for name, data in payloads.items():
        atomic_write_bytes(paths[name], data)
    return paths


def refresh_parquet(report: "Report", out: str | Path, *, write: bool = False
                    ) -> dict[str, Path]:
    """Keep the Parquet exports of the run folder ``out`` true to ``report`` (the store as
    it is now): :func:`write_parquet` with ``write``, and also wherever one is there
    already, so that a run or report that changed the store never leaves a stale one;
    where pandas or pyarrow is missing, those already there are removed, with a warning
    line, rather than left stale. Returns the paths written."""
    there = [p for p in (Path(out) / name for name in PARQUET_FILES.values())
             if p.exists() or p.is_symlink()]
    if not write and not there:
        return {}
    if not write:
        try:
            require("pandas", EXTRA)
            require("pyarrow", EXTRA)
        except MissingExtraError as exc:
            for path in there:
                discard(path)
            log.warning("tactbench: warning: %s removed: the store changed and they cannot "
                        "be written again here (%s)", ", ".join(p.name for p in there), exc)
            return {}
    return write_parquet(report, out)
