"""plugins/tactbench-mlflow: cells and comparisons as MLflow runs, read back with MLflow's
own client from a temporary SQLite store."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

pytest.importorskip("mlflow", reason="the tactbench-mlflow plugin (mlflow-skinny) is not "
                                     "installed: pip install -e plugins/tactbench-mlflow")
tactbench_mlflow = pytest.importorskip("tactbench_mlflow")

from mlflow.tracking import MlflowClient  # noqa: E402

from tactbench.cli import cli  # noqa: E402
from tactbench.plugins import collect_registry, make_plugin_manager  # noqa: E402
from tactbench.runner import Scene, run  # noqa: E402
from tactbench_mlflow import URI_ENV, exporter  # noqa: E402


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """A run of 2 encoders × 3 seeds whose cells the plugin's hook logged as they finished
    (TACTBENCH_MLFLOW_URI set), to a fresh SQLite store: ``(folder, uri)``."""
    root = tmp_path_factory.mktemp("mlflow")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    registry = collect_registry(make_plugin_manager(
        entry_points=False, strict=True, extra=[("mlflow", tactbench_mlflow)]))
    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1",
                  encoders=["raw", "frame-diff"], classifiers=["logreg:max_iter=20"],
                  L=[3], seeds=[0, 1, 2], pixel_mm=10, test_per_class=1, threads=1,
                  out=str(root / "out"))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(URI_ENV, uri)
        report = run(scene, registry=registry, progress=False, plots=False)
    return root / "out", uri, report


def runs_of(uri, kind):
    client = MlflowClient(tracking_uri=uri)
    experiment = client.get_experiment_by_name("tactbench")
    return client.search_runs([experiment.experiment_id],
                              filter_string=f"tags.`tactbench.kind` = '{kind}'")


def test_each_finished_cell_is_a_run_under_the_folders_parent(logged):
    out, uri, report = logged
    (parent,) = runs_of(uri, "folder")
    assert parent.data.tags["tactbench.folder"] == str(out.resolve())
    # what the run resolved once (its record, run_finished's summary) tags the parent
    assert parent.data.tags["tactbench.record.paired_test"] == "corrected-t"
    assert '"device": "cpu"' in parent.data.tags["tactbench.record.compute"]
    assert parent.data.tags["tactbench.record.workers"].split()[0].isdigit()
    cells = runs_of(uri, "cell")
    assert len(cells) == 6
    assert {r.data.tags["mlflow.parentRunId"] for r in cells} == {parent.info.run_id}
    by_key = {r["key"]: r for r in report.rows}
    for logged_run in cells:
        row = by_key[logged_run.data.tags["tactbench.cell_key"]]
        assert logged_run.data.params["encoder"] == row["encoder"]
        assert logged_run.data.params["seed"] == str(row["seed"])
        assert logged_run.data.params["L"] == "3"
        assert logged_run.data.metrics["accuracy"] == pytest.approx(row["accuracy"])
        assert "train_s" in logged_run.data.metrics
        assert logged_run.data.tags["tactbench.git"] == str(row["run"]["git"])
        assert row["machine"]["cpu"] in logged_run.data.tags["tactbench.machine"]
        assert logged_run.info.status == "FINISHED"


def test_exporting_the_folder_adds_its_comparisons_and_twice_adds_nothing(logged):
    out, uri, report = logged
    result = CliRunner().invoke(cli, ["mlflow", str(out), "--tracking-uri", uri, "--json"])
    assert result.exit_code == 0, result.output
    # the live run logged its comparison when it ended (run_finished): nothing is new
    assert '"logged": 0' in result.output and '"unchanged": 7' in result.output
    (comparison,) = runs_of(uri, "comparison")
    c = report.comparisons[0]
    metrics, tags = comparison.data.metrics, comparison.data.tags
    assert metrics["difference"] == pytest.approx(c.difference)
    assert (metrics["low"], metrics["high"]) == (pytest.approx(c.low), pytest.approx(c.high))
    assert metrics["p"] == pytest.approx(c.p) and metrics["runs"] == 3
    assert tags["tactbench.verdict"] == c.verdict
    assert tags["mlflow.parentRunId"] == runs_of(uri, "folder")[0].info.run_id
    raw = {r["key"] for r in report.rows if r["encoder"] == "raw"}
    assert set(tags["tactbench.cells_a"].split(",")) == raw
    again = CliRunner().invoke(cli, ["mlflow", str(out), "--tracking-uri", uri])
    assert again.exit_code == 0 and "0 run(s) logged, 7 already there" in again.output
    assert len(runs_of(uri, "cell")) == 6 and len(runs_of(uri, "folder")) == 1


def test_a_file_store_works_too(logged, tmp_path):
    out, _, _ = logged
    store = tmp_path / "mlruns"
    counts = exporter.export_folder(out, str(store))
    assert counts == {"logged": 7, "unchanged": 0}
    assert len(runs_of(store.as_uri(), "cell")) == 6


def test_bad_input_is_one_line_and_logs_nothing(logged, tmp_path):
    out, _, _ = logged
    down = CliRunner().invoke(cli, ["mlflow", str(out), "--tracking-uri",
                                    "http://127.0.0.1:9"])
    assert down.exit_code == 2 and "cannot be used" in down.output
    assert len(down.output.strip().splitlines()) == 1
    (tmp_path / "notes.txt").write_text("not a run")
    uri = f"sqlite:///{tmp_path / 'm.db'}"
    not_run = CliRunner().invoke(cli, ["mlflow", str(tmp_path), "--tracking-uri", uri])
    assert not_run.exit_code == 2 and "holds no cell rows" in not_run.output
    assert not (tmp_path / "m.db").exists()  # refused before the store was opened
