"""tactbench-mlflow: the hook module. Keep it light: mlflow is imported on first use.

- ``tactbench mlflow OUT``: a finished run folder into MLflow (``exporter.export_folder``);
- while a run runs, with ``TACTBENCH_MLFLOW_URI`` set (a tracking URI): each finished
  cell (``cell_finished``), and when the run ends its comparisons, then its parent run
  ended FINISHED (FAILED where a cell could not be logged) (``run_finished``; with
  ``--until answered`` each look's too, ``look_finished``). Without it the hooks do
  nothing: nothing is logged, and nothing leaves the machine, unless the user names a
  tracking URI.
"""

from __future__ import annotations

import atexit
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
    exporter = _live()
    if exporter is not None:
        from tactbench.runner import ResultStore

        # the grid as far as it is known: every cell the folder holds now (a run keeps
        # each cell already there), which finds the parent (exporter.Exporter.parent)
        grid = set(ResultStore(out).keys())
        try:
            exporter.log_cell(out, row, grid)
        except BaseException:
            exporter.live_failed = True  # the parent ends FAILED, not FINISHED
            raise


@hookimpl
def run_finished(summary, out):
    """The run's comparisons and each cell's learning judged over its runs, then its
    parent ended: FINISHED, or FAILED where a cell could not be logged (never left
    RUNNING)."""
    _log_record(summary, out, cells=True)


@hookimpl
def look_finished(look, out):
    _log_record(look, out, cells=False)


def _live():
    """The exporter of ``TACTBENCH_MLFLOW_URI``, or None when it is not set; the first
    one also has the process end, at exit, what a run that never ended left open."""
    uri = os.environ.get(URI_ENV)
    if not uri:
        return None
    from tactbench_mlflow.exporter import Exporter

    exporter = Exporter.connect(uri)
    if exporter not in _OPENED:
        _OPENED.append(exporter)
        if len(_OPENED) == 1:
            atexit.register(end_live_parents)
    return exporter


#: The exporters live logging used in this process (see :func:`end_live_parents`).
_OPENED: list = []


def end_live_parents(status: str = "KILLED") -> None:
    """End, ``status`` (KILLED: the run stopped before it ended: Ctrl-C, an error), every
    parent a live-logged run opened and did not end (run_finished never came); called
    at the process's exit. A store that refuses is left as it is: the process is ending."""
    for exporter in _OPENED:
        try:
            exporter.end(status)
        except Exception:  # noqa: BLE001 — at exit there is no one to tell
            pass


def _log_record(record, out, *, cells):
    """A run's or a look's record (its rows as stored, its comparisons) logged, then the
    parents ended."""
    exporter = _live()
    if exporter is None:
        return
    try:
        exporter.log_record(out, record, cells=cells)
    except BaseException:
        exporter.live_failed = True
        raise
    finally:
        exporter.end("FAILED" if exporter.live_failed else "FINISHED")
        exporter.live_failed = False
