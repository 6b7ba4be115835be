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
    # the two encoders share split and seed: one paired comparison, raw first
    [comp] = doc["comparisons"]
    assert (comp["factor"], comp["a"], comp["b"]) == ("encoder", "raw", "frame-diff")
    assert comp["sequences"] == doc["rows"][0]["n_test"]
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


# ------------------------------------------------------------ paired comparisons


def _row(encoder, seed, truth, predicted, *, L=5, classifier="logreg", indices=None):
    indices = list(range(len(truth))) if indices is None else indices
    acc = sum(t == p for t, p in zip(truth, predicted)) / len(truth)
    return {"key": f"{encoder}-{seed}-{L}", "dataset": "d", "split": "paper",
            "encoder": encoder, "classifier": classifier, "L": L, "seed": seed,
            "status": "ok", "classes": ["a", "b"], "accuracy": acc,
            "per_class_accuracy": {"a": acc, "b": acc}, "confusion": [[1, 0], [0, 1]],
            "encode_ms_per_frame": 1.0, "train_s": 1.0, "inference_ms_per_sequence": 1.0,
            "peak_rss_mb": 1.0,
            "test_predictions": {"indices": indices, "labels": list(truth),
                                 "predictions": list(predicted)}}


def test_pairs_differing_in_one_factor_are_compared_sequence_by_sequence():
    from tactbench.runner.reports import comparisons

    truth = [0, 1] * 20
    rows = []
    for seed in (0, 1, 2):
        wrong_raw = {seed, seed + 3, seed + 6, 10, 11, 12, 13, 14, 15, 16}  # ~25 % wrong
        rows.append(_row("raw", seed, truth,
                         [1 - t if i in wrong_raw else t for i, t in enumerate(truth)]))
        rows.append(_row("farneback", seed, truth,
                         [1 - t if i == seed else t for i, t in enumerate(truth)]))
    comps = comparisons(rows, n_resamples=999)
    assert len(comps) == 1
    c = comps[0]
    assert (c["factor"], c["a"], c["b"], c["classifier"], c["L"]) == \
        ("encoder", "raw", "farneback", "logreg", 5)  # A: the first in the run
    # the mean difference is the mean over seeds of accuracy B − A
    by = {(r["encoder"], r["seed"]): r["accuracy"] for r in rows}
    expected = sum(by["farneback", s] - by["raw", s] for s in range(3)) / 3
    assert c["difference"] == pytest.approx(expected)
    assert c["low"] > 0 and c["verdict"] == "B better" and c["b_better_seeds"] == 3
    assert c["a_only"] == 0 and c["b_only"] == 27 and c["mcnemar_p"] < 1e-6
    assert c["resampling"] == "sequences jointly across seeds"


def test_a_difference_whose_interval_spans_zero_is_unresolved_in_every_output(tmp_path):
    from tactbench.runner.reports import comparisons

    truth = [0, 1] * 20
    rows = []
    for seed in (0, 1):
        rows.append(_row("raw", seed, truth, [1 - t if i in (seed, 5) else t
                                              for i, t in enumerate(truth)]))
        rows.append(_row("farneback", seed, truth, [1 - t if i in (seed + 1, 7) else t
                                                    for i, t in enumerate(truth)]))
    c = comparisons(rows, n_resamples=999)[0]
    assert c["low"] <= 0 <= c["high"] and c["verdict"] == "unresolved"
    paths = write_reports(tmp_path / "out", rows, plots=False)
    report = paths["markdown"].read_text()
    assert "## Paired comparisons" in report and "| unresolved |" in report
    assert json.loads(paths["json"].read_text())["comparisons"][0]["verdict"] == "unresolved"


def test_only_shared_seeds_and_sequences_are_paired_and_old_rows_are_left_out():
    from tactbench.runner.reports import comparisons

    truth = [0, 1] * 10
    a = _row("raw", 0, truth, truth)
    b = _row("farneback", 0, truth[:10], truth[:10], indices=list(range(5, 15)))
    b["test_predictions"]["labels"] = [truth[i] for i in range(5, 15)]
    extra_seed = _row("farneback", 1, truth, truth)
    c = comparisons([a, b, extra_seed], n_resamples=999)[0]
    assert c["sequences"] == 10 and c["seeds"] == 1
    old = dict(a)
    del old["test_predictions"]
    assert comparisons([old, b]) == []


def test_l_and_classifier_pairs_and_the_seed_interval_in_the_table():
    from tactbench.runner.reports import comparisons, markdown_table

    truth = [0, 1] * 10
    rows = [_row("raw", s, truth, truth, L=L, classifier=clf)
            for s in (0, 1, 2) for L in (3, 5) for clf in ("logreg", "taxel-lstm:epochs=3")]
    factors = sorted(c["factor"] for c in comparisons(rows, n_resamples=999))
    assert factors == ["L", "L", "classifier", "classifier"]
    rows[0]["accuracy"] = 0.9
    summary = [s for s in summarise(rows) if s["L"] == 3 and s["classifier"] == "logreg"][0]
    low, high = summary["accuracy_ci95"]
    assert low < summary["accuracy_mean"] < high
    assert f"{100 * low:.1f}–{100 * high:.1f}" in markdown_table([summary])
    one_seed = summarise([rows[0]])[0]
    assert one_seed["accuracy_ci95"] is None


def test_a_row_with_broken_predictions_is_a_damaged_row():
    from tactbench.runner.store import check_row

    row = _row("raw", 0, [0, 1], [0, 1])
    row["key"] = "k"
    assert check_row(row, "k") is None
    for bad in ("x", {"indices": [0], "labels": [0]},
                {"indices": [0, 1], "labels": [0], "predictions": [0, 1]},
                {"indices": [0, 0], "labels": [0, 1], "predictions": [0, 1]},
                {"indices": [0, 1], "labels": [0, 2], "predictions": [0, 1]},
                {"indices": [0, 1], "labels": [0, 1], "predictions": [0, True]}):
        row["test_predictions"] = bad
        assert "test_predictions" in check_row(row, "k")
