"""Hardening, round five (issue 51): every export is derived from the store when it is
made. Parquet files are rewritten (or removed) by every run and report; every identity
field is a column of results.csv, the data frames and the Parquet; `report --parquet`
beside a folder named cells.parquet is one line before anything is rewritten. The MLflow
export (plugins/tactbench-mlflow) finds its parent by the grid, carries each cell's
learning, maps class names MLflow refuses reversibly, leaves no parent RUNNING, says
what is true of a deleted experiment, and hears nothing of `tactbench reproduce`."""

from __future__ import annotations

import csv
import io
import json
import logging
import sys

import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.runner import Scene, cells_frame, render_folder, run
from tactbench.runner.execution.planning import COMPUTE_FIELDS, IDENTITY_FIELDS
from tactbench.runner.execution.results import ResultStore, row_checksum
from tactbench.runner.presentation.frames import PARQUET_METADATA

GRID = dict(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw", "frame-diff"],
            classifiers=["logreg:max_iter=20"], L=[3], pixel_mm=10, test_per_class=1,
            threads=1, workers=1)


def scene(out, **changes):
    return Scene(**{**GRID, "seeds": [0, 1], "out": str(out), **changes})


def said_by(path):
    """What a Parquet file says it was made from (its schema metadata)."""
    import pyarrow.parquet as pq

    return json.loads(pq.read_schema(path).metadata[PARQUET_METADATA])


# ------------------------------------------------------------------- Parquet, columns


def test_parquet_follows_the_store_through_every_run_and_report(tmp_path):
    pytest.importorskip("pyarrow")
    pd = pytest.importorskip("pandas")
    out = tmp_path / "out"
    run(scene(out), progress=False, plots=False)
    render_folder(out, parquet=True, plots=False)
    assert len(pd.read_parquet(out / "cells.parquet")) == 4
    report = run(scene(out, seeds=[0, 1, 2]), progress=False, plots=False)  # the grid grew
    assert len(pd.read_parquet(out / "cells.parquet")) == 6
    assert said_by(out / "cells.parquet")["cells"] == 6
    assert said_by(out / "comparisons.parquet")["rendered"] == json.loads(
        json.dumps(report.rendered))
    assert {"cells", "comparisons"} <= set(report.paths)
    render_folder(out, margin=3.0, plots=False)  # a report with other statistics options
    assert "re-rendered" in said_by(out / "comparisons.parquet")["rendered"]["how"]
    assert set(pd.read_parquet(out / "comparisons.parquet")["equivalence_margin"]) == {3.0}


def test_stale_parquet_is_removed_where_it_cannot_be_written_again(tmp_path, monkeypatch,
                                                                    caplog):
    pytest.importorskip("pyarrow")
    out = tmp_path / "out"
    run(scene(out, encoders=["raw"]), progress=False, plots=False)
    render_folder(out, parquet=True, plots=False)
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # the extra is gone
    with caplog.at_level(logging.WARNING):
        render_folder(out, plots=False)
    assert not (out / "cells.parquet").exists() and not (out / "comparisons.parquet").exists()
    line = [r.getMessage() for r in caplog.records if "removed" in r.getMessage()]
    assert len(line) == 1 and "cells.parquet, comparisons.parquet removed" in line[0]
    assert "pyarrow is not installed" in line[0]


def test_every_identity_field_is_a_column_of_every_export(tmp_path):
    pytest.importorskip("pyarrow")
    pd = pytest.importorskip("pandas")
    out = tmp_path / "out"
    run(scene(out, encoders=["raw"], seeds=[0], init_seeds=[0, 1]), progress=False,
        plots=False)
    report = render_folder(out, parquet=True, plots=False)
    table = list(csv.DictReader(io.StringIO((out / "results.csv").read_text())))
    fields = set(IDENTITY_FIELDS + COMPUTE_FIELDS)
    assert fields <= set(table[0])
    assert sorted(r["init_seed"] for r in table) == ["0", "1"]  # two cells, told apart
    assert {r["test_window"] for r in table} == {"vote"}  # a default shown, not blank
    assert {r["cpu_kernels"] for r in table} == {"avx2"} and {r["threads"] for r in table} \
        == {"1"}
    assert json.loads(table[0]["imaging"]) == report.rows[0]["imaging"]
    for frame in (cells_frame(report), pd.read_parquet(out / "cells.parquet")):
        assert fields <= set(frame.columns)
        assert sorted(frame["init_seed"].tolist()) == [0, 1]
        assert str(frame["init_seed"].dtype) == "Int64"
    dropped = [c for c in table[0] if c not in ("init_seed", "key", "finished", "accuracy")
               and not c.startswith(("acc_", "train", "encode", "inference", "peak",
                                     "chance", "learning"))]
    assert len({tuple(r[c] for c in dropped) for r in table}) == 1  # only init_seed differs


def test_report_parquet_beside_a_folder_named_cells_parquet_is_one_line(tmp_path):
    out = tmp_path / "out"
    run(scene(out, encoders=["raw"]), progress=False, plots=False)
    (out / "cells.parquet").mkdir()
    before = {name: (out / name).read_bytes() for name in ("results.csv", "report.md",
                                                            "results.json")}
    result = CliRunner().invoke(cli, ["report", str(out), "--parquet", "--no-plots"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "holds a cells.parquet tactbench did not write" in lines[0]
    assert "nothing was written" in lines[0]
    assert {name: (out / name).read_bytes() for name in before} == before
    plain = CliRunner().invoke(cli, ["run", "--out", str(out), "--dataset", GRID["dataset"],
                                     "--encoder", "raw", "--classifier", "logreg"])
    assert plain.exit_code == 2 and "cells.parquet" in plain.output  # a run refuses it too


# ------------------------------------------------------------------------------ MLflow

mlflow = pytest.importorskip("mlflow", reason="the tactbench-mlflow plugin (mlflow-skinny) "
                                              "is not installed")
tactbench_mlflow = pytest.importorskip("tactbench_mlflow")

from mlflow.tracking import MlflowClient  # noqa: E402

from tactbench.plugins import collect_registry, make_plugin_manager  # noqa: E402
from tactbench_mlflow import URI_ENV, exporter  # noqa: E402


@pytest.fixture(autouse=True)
def _file_store(monkeypatch):
    """MLflow's file store (a folder: fast to make, nothing to migrate), which MLflow 3
    refuses unless allowed."""
    monkeypatch.setenv("MLFLOW_ALLOW_FILE_STORE", "true")


def mlflow_registry():
    return collect_registry(make_plugin_manager(entry_points=False, strict=True,
                                                extra=[("mlflow", tactbench_mlflow)]))


def runs_of(uri, kind, experiment="tactbench"):
    client = MlflowClient(tracking_uri=uri)
    found = client.get_experiment_by_name(experiment)
    return client.search_runs([found.experiment_id],
                              filter_string=f"tags.`tactbench.kind` = '{kind}'")


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """A run logged live (TACTBENCH_MLFLOW_URI set) to a fresh file store: (out, uri,
    report)."""
    root = tmp_path_factory.mktemp("mlflow5")
    uri = (root / "mlruns").as_uri()
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(URI_ENV, uri)
        mp.setenv("MLFLOW_ALLOW_FILE_STORE", "true")
        report = run(scene(root / "out"), registry=mlflow_registry(), progress=False,
                     plots=False)
    return root / "out", uri, report


def test_a_live_logged_run_ends_its_parent_and_carries_learning(live):
    out, uri, report = live
    (parent,) = runs_of(uri, "folder")
    assert parent.info.status == "FINISHED"  # was left RUNNING after the run ended
    assert json.loads(parent.data.tags["tactbench.grid"])["dataset"] == "synthetic-forearm"
    cells = runs_of(uri, "cell")
    assert len(cells) == 4 and len(runs_of(uri, "comparison")) == 1
    by_key = {r["key"]: r for r in report.rows}
    for logged in cells:
        row = by_key[logged.data.tags["tactbench.cell_key"]]
        assert logged.data.params["learning"] == row["learning"]
        assert logged.data.metrics["train_accuracy"] == pytest.approx(row["train_accuracy"])
        assert logged.data.metrics["chance_accuracy"] == pytest.approx(row["chance_accuracy"])
        assert logged.data.tags["tactbench.cell_learning"] in ("learned", "did not learn",
                                                               "did not transfer",
                                                               "not above chance")
        assert logged.data.params["init_seed"] == "None"  # every identity field a param
        assert logged.data.params["cpu_kernels"] == "avx2"


def test_a_live_run_that_never_ends_has_its_parent_ended_at_exit(live, tmp_path,
                                                                 monkeypatch):
    out, _, report = live
    uri = (tmp_path / "mlruns").as_uri()
    monkeypatch.setenv(URI_ENV, uri)
    tactbench_mlflow.cell_finished(report.rows[0], out)  # then Ctrl-C: no run_finished
    (parent,) = runs_of(uri, "folder")
    assert parent.info.status == "RUNNING"
    tactbench_mlflow.end_live_parents()  # what the process does at exit
    (parent,) = runs_of(uri, "folder")
    assert parent.info.status == "KILLED"


def test_a_new_grid_in_a_reused_folder_gets_a_parent_of_its_own(live, tmp_path):
    out, uri, _ = live
    reused = tmp_path / "out"
    run(scene(reused), progress=False, plots=False)
    store = (tmp_path / "mlruns").as_uri()
    exporter.export_folder(reused, store)
    for path in (reused / "cells").glob("*.json"):  # the folder is cleared ...
        path.unlink()
    run(scene(reused, test_per_class=2, encoders=["raw"]), progress=False, plots=False)
    exporter.export_folder(reused, store)  # ... and holds another grid
    parents = runs_of(store, "folder")
    assert len(parents) == 2 and {p.info.status for p in parents} == {"FINISHED"}
    newest = [p for p in parents if json.loads(p.data.tags["tactbench.grid"])
              ["test_per_class"] == 2][0]
    under = [r for r in runs_of(store, "cell")
             if r.data.tags["mlflow.parentRunId"] == newest.info.run_id]
    assert {r.data.tags["tactbench.cell_key"] for r in under} == set(ResultStore(reused).keys())


def test_a_parent_logged_before_grids_is_adopted_not_doubled(live, tmp_path):
    out, _, _ = live
    uri = (tmp_path / "mlruns").as_uri()
    exporter.export_folder(out, uri)
    (parent,) = runs_of(uri, "folder")
    client = MlflowClient(tracking_uri=uri)
    for tag in ("tactbench.grid_id", "tactbench.grid"):  # as an earlier version logged it
        client.delete_tag(parent.info.run_id, tag)
    exporter.Exporter.connect(uri)._parents.clear()
    assert exporter.export_folder(out, uri) == {"logged": 0, "unchanged": 5}
    (again,) = runs_of(uri, "folder")
    assert again.info.run_id == parent.info.run_id and "tactbench.grid_id" in again.data.tags


def test_grids_differing_only_in_pixel_size_get_two_parents_more_seeds_keep_one(tmp_path,
                                                                               monkeypatch):
    from tactbench.runner import grid_identity

    reused, store = tmp_path / "out", (tmp_path / "mlruns").as_uri()
    one = scene(reused, encoders=["raw"], seeds=[0])
    first = run(one, progress=False, plots=False)
    exporter.export_folder(reused, store)
    monkeypatch.setenv(URI_ENV, store)  # the next runs logged live, then exported again
    more = run(scene(reused, encoders=["raw"], seeds=[0, 1]), registry=mlflow_registry(),
               progress=False, plots=False)  # adds a seed: the same grid
    (parent,) = runs_of(store, "folder")
    assert {r.data.tags["mlflow.parentRunId"] for r in runs_of(store, "cell")} == {
        parent.info.run_id} and len(runs_of(store, "cell")) == 2
    for path in (reused / "cells").glob("*.json"):  # the folder is cleared ...
        path.unlink()
    other = run(scene(reused, encoders=["raw"], seeds=[0], pixel_mm=5),
                registry=mlflow_registry(), progress=False, plots=False)
    # ... and holds a grid that differs in the pixel size alone (a field of one imaging
    # kind: its shared identity is the first grid's)
    assert grid_identity(other.rows[0]) == grid_identity(first.rows[0])
    assert exporter.export_folder(reused, store)["logged"] == 0  # the live run logged it
    parents = runs_of(store, "folder")
    assert len(parents) == 2 and {p.info.status for p in parents} == {"FINISHED"}
    under = {p.info.run_id: {r.data.tags["tactbench.cell_key"] for r in runs_of(store, "cell")
                             if r.data.tags["mlflow.parentRunId"] == p.info.run_id}
             for p in parents}
    assert under[parent.info.run_id] == {r["key"] for r in more.rows}
    (new,) = set(under) - {parent.info.run_id}
    assert under[new] == {r["key"] for r in other.rows} == set(ResultStore(reused).keys())


@pytest.mark.parametrize("name", ["tap+hold", "swipe (left)", "v1.2", "a/b", "..", "ü",
                                  "x%2E", " lead", "tap.2Bhold"])
def test_class_names_mlflow_refuses_are_mapped_reversibly(name):
    from mlflow.utils.validation import path_not_unique, validate_param_and_metric_name

    metric = f"accuracy_{exporter.metric_class(name)}"
    assert validate_param_and_metric_name(metric) and not path_not_unique(metric)
    assert exporter.class_of_metric(exporter.metric_class(name)) == name


@pytest.mark.parametrize("name", ["g" * 300, "+" * 300, "a" + "+" * 299, "ab" + "+" * 298,
                                  "ü" * 300, "x" * 242, "x" * 300 + "+"])
def test_class_names_too_long_for_mlflow_are_shortened_reversibly(name):
    from mlflow.utils.validation import (MAX_ENTITY_KEY_LENGTH, MAX_TAG_VAL_LENGTH,
                                         path_not_unique, validate_param_and_metric_name)

    assert (exporter.MAX_NAME, exporter.MAX_TAG_VALUE) == (MAX_ENTITY_KEY_LENGTH,
                                                           MAX_TAG_VAL_LENGTH)
    metric, tags = exporter.class_metric(name)
    assert len(metric) <= MAX_ENTITY_KEY_LENGTH and len(metric) >= MAX_ENTITY_KEY_LENGTH - 2
    assert validate_param_and_metric_name(metric) and not path_not_unique(metric)
    assert all(len(k) <= MAX_ENTITY_KEY_LENGTH for k in tags)
    assert exporter.class_of_metric(metric.removeprefix("accuracy_"), tags) == name
    head = metric.removeprefix("accuracy_").rsplit(exporter.HASHED, 1)[0]
    assert exporter.metric_class(name).startswith(head)  # readable, no escape cut in half
    other, _ = exporter.class_metric(name[:-1] + "?")
    assert other != metric  # a name differing in its last character: another metric
    with pytest.raises(ValueError, match="tactbench.names."):
        exporter.class_of_metric(metric.removeprefix("accuracy_"))
    assert exporter.class_metric("x" * 241) == ("accuracy_" + "x" * 241, {})  # 250: fits


def test_a_class_name_longer_than_a_tag_is_one_line():
    with pytest.raises(exporter.TactbenchError, match="has 8001 characters"):
        exporter.class_metric("k" * 8001)


def test_a_folder_with_such_class_names_is_exported_whole(live, tmp_path):
    out = tmp_path / "out"
    run(scene(out, encoders=["raw"], seeds=[0]), progress=False, plots=False)
    (path,) = (out / "cells").glob("*.json")
    row = json.loads(path.read_text())  # the classes renamed as a folder dataset names them
    long = "press " * 50  # 300 characters: a metric name MLflow refuses (over 250)
    names = ["tap+hold", "swipe (left)", long, *row["classes"][3:]]
    renamed = dict(zip(row["classes"], names))
    row["classes"] = names
    row["per_class_accuracy"] = {renamed[k]: v for k, v in row["per_class_accuracy"].items()}
    row["checksum"] = row_checksum(row)
    path.write_text(json.dumps(row))
    uri = (tmp_path / "mlruns").as_uri()
    exporter.export_folder(out, uri)
    (cell,) = runs_of(uri, "cell")
    assert cell.data.metrics["accuracy_tap.2Bhold"] == row["per_class_accuracy"]["tap+hold"]
    assert "accuracy_swipe .28left.29" in cell.data.metrics
    (shortened,) = [m for m in cell.data.metrics if exporter.HASHED in m]
    assert len(shortened) <= 250 and cell.data.metrics[shortened] == \
        row["per_class_accuracy"][long]
    assert exporter.class_of_metric(shortened.removeprefix("accuracy_"),
                                    cell.data.tags) == long
    assert runs_of(uri, "folder")[0].info.status == "FINISHED"


def test_a_refused_write_marks_the_parent_failed_and_says_only_that(live, tmp_path,
                                                                    monkeypatch):
    out, _, _ = live
    uri = (tmp_path / "mlruns").as_uri()

    def refuse(*_args, **_kwargs):
        raise RuntimeError("the server said no")

    monkeypatch.setattr(exporter.Exporter, "log_comparison", refuse)
    with pytest.raises(exporter.TrackingError) as caught:
        exporter.export_folder(out, uri)
    message = str(caught.value)
    assert "the server said no" in message and "parent run is marked FAILED" in message
    assert "finishes it" not in message
    (parent,) = runs_of(uri, "folder")
    assert parent.info.status == "FAILED"
    monkeypatch.undo()
    exporter.export_folder(out, uri)  # the cause gone, exporting again ends it FINISHED
    assert runs_of(uri, "folder")[0].info.status == "FINISHED"


def test_a_deleted_experiment_is_one_true_line(live, tmp_path):
    out, _, _ = live
    uri = (tmp_path / "mlruns").as_uri()
    client = MlflowClient(tracking_uri=uri)
    client.delete_experiment(client.create_experiment("gone"))
    result = CliRunner().invoke(cli, ["mlflow", str(out), "--tracking-uri", uri,
                                      "--experiment", "gone"])
    assert result.exit_code == 2
    (line,) = result.output.strip().splitlines()
    assert "experiment 'gone'" in line and "is deleted" in line and "restore" in line
    assert "finishes it" not in line


def test_reproduce_logs_nothing_to_mlflow(live, tmp_path, monkeypatch):
    from tactbench.commands.reproduce import reproduce

    out, _, _ = live
    folder = tmp_path / "out"
    run(scene(folder, encoders=["raw"], seeds=[0]), progress=False, plots=False)
    uri = (tmp_path / "mlruns").as_uri()
    monkeypatch.setenv(URI_ENV, uri)
    results = reproduce(str(folder), everything=True, progress=False,
                        registry=mlflow_registry())
    assert len(results) == 1
    assert not (tmp_path / "mlruns").exists()  # no parent, no cell, no store made
