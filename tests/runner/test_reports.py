"""Reports: files, summaries over seeds, and failed cells listed apart from the accuracies."""

from __future__ import annotations

import csv
import io
import json

import pytest

from tactbench.runner import run
from tactbench.runner.reports import failed_cells, summarise, write_reports

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_reports_are_written(tmp_path, tiny_scene, cache):
    result = run(tiny_scene(seeds=[0]), progress=False, cache=cache)
    paths = write_reports(tmp_path / "out", result.rows, meta={"command": "test"})
    for name in ("results.json", "results.csv", "report.md", "accuracy_vs_L.png",
                 "cost_vs_accuracy.png"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    assert len(list((tmp_path / "out").glob("confusion_*.png"))) == 2
    doc = json.loads(paths["json"].read_text())
    assert len(doc["rows"]) == 2 and len(doc["summary"]) == 2
    csv_lines = paths["csv"].read_text().splitlines()
    assert len(csv_lines) == 3 and "acc_" in csv_lines[0]
    summary = summarise(result.rows)[0]
    assert abs(sum(summary["confusion_normalised"][0]) - 1.0) < 1e-9
    report = paths["markdown"].read_text()
    assert "Failed cells" not in report
    # the peak memory and the step that set it, in the table and the CSV
    assert "| peak MB | peak step |" in report
    for s in summarise(result.rows):
        assert s["peak_step"] in {row["peak_step"] for row in result.rows}
        assert f"| {s['peak_rss_mb_mean']:.0f} | {s['peak_step']} |" in report
    assert "peak_step" in csv_lines[0].split(",")


def test_the_peak_step_of_a_summary_is_the_most_common_over_seeds():
    from tactbench.runner.reports import peak_step

    assert peak_step([{"peak_step": "fit"}, {"peak_step": "predict"},
                      {"peak_step": "predict"}]) == "predict"
    assert peak_step([{"peak_step": "fit"}, {"peak_step": "windows"}]) == "fit"  # tie: first
    assert peak_step([{"accuracy": 1.0}]) == "-"  # rows written before steps were recorded


def test_failed_cells_are_listed_and_left_out_of_the_accuracies(
        tmp_path, tiny_scene, cache, fake_registry, monkeypatch):
    monkeypatch.setenv("TACTBENCH_TEST_FAIL", "1")
    scene = tiny_scene(encoders=["raw"], classifiers=["logreg:max_iter=20", "failing"],
                       seeds=[0, 1])
    result = run(scene, registry=fake_registry, progress=False, cache=cache)
    assert len(result.failed) == 2

    (summary,) = summarise(result.rows)  # the failing classifier has no accuracy to show
    assert summary["classifier"].startswith("logreg") and summary["seeds"] == [0, 1]
    assert [(f["classifier"], f["seed"], f["error"]) for f in failed_cells(result.rows)] == [
        ("failing", "0", "RuntimeError: deliberate failure in fit"),
        ("failing", "1", "RuntimeError: deliberate failure in fit")]

    paths = write_reports(tmp_path / "out", result.rows, meta={"command": "test"})
    report = paths["markdown"].read_text()
    assert "cells: 4 (2 failed, listed below)" in report
    failed_part = report.split("## Failed cells", 1)[1]
    for row in result.failed:
        assert f"cells/{row['key']}.json" in failed_part
    assert failed_part.count("| raw | failing | 3 |") == 2
    assert "RuntimeError: deliberate failure in fit" in failed_part
    table = list(csv.DictReader(io.StringIO(paths["csv"].read_text())))
    assert sorted(r["status"] for r in table) == ["failed", "failed", "ok", "ok"]
    assert {r["accuracy"] for r in table if r["status"] == "failed"} == {""}
    doc = json.loads(paths["json"].read_text())
    assert len(doc["rows"]) == 4 and len(doc["summary"]) == 1
    assert len(list((tmp_path / "out").glob("confusion_*.png"))) == 1


def test_only_failed_cells_give_a_report_without_plots(tmp_path):
    rows = [{"key": "k", "status": "failed", "dataset": "d", "split": "paper",
             "encoder": "raw", "classifier": "failing:x=1", "L": 3, "seed": 0,
             "classes": ["a", "b"], "error": {"type": "MemoryError", "message": ""}}]
    paths = write_reports(tmp_path, rows)
    assert summarise(rows) == [] and "accuracy_vs_L" not in paths
    assert "| raw | failing | 3 | 0 | MemoryError: " in paths["markdown"].read_text()
