"""tactbench-mlflow: the hook module. Keep it light: mlflow is imported on first use.

- ``tactbench mlflow OUT``: a finished run folder into MLflow (``exporter.export_folder``);
- while a run runs, with ``TACTBENCH_MLFLOW_URI`` set (a tracking URI): each finished
  cell (``cell_finished``) and, with ``--until answered``, each look's comparisons
  (``look_finished``). Without it the hooks do nothing: nothing is logged, and nothing
  leaves the machine, unless the user names a tracking URI.
"""

from __future__ import annotations

import os

from tactbench import hookimpl

#: The environment variable that turns logging during a run on: a tracking URI.
URI_ENV = "TACTBENCH_MLFLOW_URI"


@hookimpl
def register_commands(cli):
    cli.add_lazy_command("mlflow", "tactbench_mlflow.command:mlflow_cmd",
                         summary="Log a run folder to MLflow: a run per cell, a run per "
                                 "comparison, under one parent run.")


@hookimpl
def cell_finished(row, out):
    uri = os.environ.get(URI_ENV)
    if uri:
        from tactbench_mlflow.exporter import Exporter

        Exporter.connect(uri).log_cell(out, row)


@hookimpl
def look_finished(report, out):
    uri = os.environ.get(URI_ENV)
    if uri:
        from tactbench_mlflow.exporter import Exporter

        Exporter.connect(uri).log_report(out, report, cells=False)
