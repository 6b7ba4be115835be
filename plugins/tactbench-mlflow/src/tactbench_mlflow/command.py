"""``tactbench mlflow OUT``: a finished run folder into MLflow."""

from __future__ import annotations

import os

import click

from tactbench.cli import get_registry, json_text
from tactbench_mlflow.exporter import EXPERIMENT, export_folder


@click.command("mlflow")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--tracking-uri", metavar="URI", default=None,
              help="Where runs go: sqlite:///mlflow.db, a folder (./mlruns), or a server "
                   "http://HOST:PORT. [default: $MLFLOW_TRACKING_URI, else "
                   "sqlite:///mlflow.db]")
@click.option("--experiment", default=EXPERIMENT, show_default=True,
              help="The MLflow experiment (made when missing).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def mlflow_cmd(folder: str, tracking_uri: str | None, experiment: str, as_json: bool) -> None:
    """Log a run folder to MLflow: a run per cell, a run per comparison, under one parent run.

    Each cell's run has its spec as params, accuracy and costs as metrics, and its key,
    git revision and machine as tags; each comparison's run has the difference B − A, its
    interval ends, p, Holm p and verdict, and the keys of the cells it compared. Runs are
    found again by their keys: exporting twice adds nothing. Nothing leaves this machine
    unless URI names a server.
    """
    uri = tracking_uri or os.environ.get("MLFLOW_TRACKING_URI") or "sqlite:///mlflow.db"
    counts = export_folder(folder, uri, experiment, registry=get_registry())
    if as_json:
        click.echo(json_text({"tracking_uri": uri, "experiment": experiment, **counts}))
    else:
        click.echo(f"{counts['logged']} run(s) logged, {counts['unchanged']} already there; "
                   f"MLflow {uri}, experiment {experiment!r}")
