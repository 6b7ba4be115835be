"""Reports: files, summaries over seeds, and failed cells listed apart from the accuracies."""

from __future__ import annotations

import csv
import dataclasses
import io
import json

import numpy as np
import pytest

from tactbench.runner import run
from tactbench.runner.analysis.summaries import failed_cells, summarise
from tactbench.runner.orchestrate import write_reports
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_reports_are_written(tmp_path, tiny_scene, cache):
    result = run(tiny_scene(seeds=[0]), progress=False, cache=cache)
    paths = write_reports(tmp_path / "out", result.rows)
    for name in ("results.json", "results.csv", "report.md", "cost_vs_accuracy.png"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    # one L: no figure against L
    assert "accuracy_vs_L" not in paths and "per_class_vs_L" not in paths
    assert len(list((tmp_path / "out").glob("confusion_*.png"))) == 2
    doc = json.loads(paths["json"].read_text())
    assert len(doc["rows"]) == 2 and len(doc["summary"]) == 2
    # the two encoders share split and seed: one paired comparison, raw first
    [comp] = doc["comparisons"]
    assert (comp["factor"], comp["a"], comp["b"]) == ("encoder", "raw", "frame-diff")
    assert comp["test_recordings"] == doc["rows"][0]["n_test"]
    # one run gives no verdict; a cell whose model did not learn (this one-epoch CNN on 5
    # test recordings is within noise of chance) gives none either, and says so first
    from tactbench.runner.execution.learning import cell_learning

    said = ("not learned" if any(not cell_learning([r]).learned for r in doc["rows"])
            else "too few runs")
    assert comp["runs"] == 1 and comp["verdict"] == said
    assert all(0 <= r["train_accuracy"] <= 1 and r["learning"] for r in doc["rows"])
    assert "## Paired comparisons over runs" in paths["markdown"].read_text()
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
    from tactbench.runner.analysis.summaries import peak_step

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

    paths = write_reports(tmp_path / "out", result.rows)
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
    return prediction_row(encoder, seed, truth, predicted, L=L, classifier=classifier,
                          indices=indices, n_train=3 * len(truth))


def _clear_win_rows(seeds=range(7), n=40, **kw):
    """B (farneback) right everywhere but one row per seed; A (raw) wrong on ~12 more."""
    truth = [0, 1] * (n // 2)
    rows = []
    for seed in seeds:
        wrong_raw = {seed % n, (seed + 3) % n, (seed + 6) % n, *range(10, 19 + seed % 3)}
        rows.append(_row("raw", seed, truth,
                         [1 - t if i in wrong_raw else t for i, t in enumerate(truth)], **kw))
        rows.append(_row("farneback", seed, truth,
                         [1 - t if i == seed % n else t for i, t in enumerate(truth)], **kw))
    return rows


def test_pairs_differing_in_one_factor_are_compared_run_by_run():
    from scipy import stats

    from tactbench.runner.analysis.comparisons import comparisons

    rows = _clear_win_rows()
    [c] = comparisons(rows)
    assert (c.factor, c.a, c.b, c.where) == \
        ("encoder", "raw", "farneback", {"classifier": "logreg", "L": 5})  # A: first in the run
    by = {(r["encoder"], r["seed"]): r["accuracy"] for r in rows}
    d = [by["farneback", s] - by["raw", s] for s in range(7)]
    assert c.per_run == {str(s): pytest.approx(v) for s, v in enumerate(d)}
    assert c.difference == pytest.approx(sum(d) / 7) and c.runs == 7
    # the interval is the corrected resampled t over runs, n_test/n_train = 1/3
    se = (stats.tvar(d) * (1 / 7 + 1 / 3)) ** 0.5
    half = stats.t.ppf(0.975, 6) * se
    assert (c.low, c.high) == (pytest.approx(c.difference - half),
                               pytest.approx(c.difference + half))
    assert c.permutation_p == pytest.approx(2 / 2 ** 7) and c.p >= c.t_p
    assert c.p_holm == c.p and c.family_size == 1  # a family of one
    assert c.verdict == "B better" and c.b_better_runs == 7
    assert set(c.mcnemar_per_seed) == {str(s) for s in range(7)}
    assert c.discordant_recordings >= 10 and c.test_recordings == 40
    assert set(c.per_class) == {"a", "b"} and c.per_class["a"].low is not None


def test_the_verdict_rests_on_the_corrected_t_alone_as_the_one_rule_says():
    """One rule (P_RULE): p is the corrected t's; the sign-flip p (floor 2/2^5 with 5
    runs) is reported, never governs, and the report states the rule in its words."""
    from tactbench.runner.analysis.comparisons import P_RULE, comparisons
    from tactbench.runner.presentation.tables import COMPARISONS_TEXT

    [c] = comparisons(_clear_win_rows(seeds=range(5)))
    assert c.t_p < 0.05 and c.permutation_p == pytest.approx(2 / 32)
    assert c.p == c.t_p and c.verdict == "B better" and "sign-flip" not in c.note
    assert P_RULE in COMPARISONS_TEXT


def test_primary_comparisons_form_their_own_family_and_come_first():
    """--primary: the named pair is confirmatory, Holm-adjusted in a family of its own;
    everything else is exploratory, in another family; the pair is not repeated."""
    from tactbench.runner.analysis.comparisons import comparisons

    truth = [0, 1] * 20
    rows = []
    for seed in range(6):
        for enc, wrong in (("raw", 8), ("farneback", 2), ("dis", 5), ("tvl1", 6)):
            rows.append(_row(enc, seed, truth, [1 - t if (i + seed) % 40 < wrong else t
                                                for i, t in enumerate(truth)]))
    everything = comparisons(rows)
    comps = comparisons(rows, primary=["encoder=raw..encoder=farneback"])
    primary = [c for c in comps if c.family == "primary"]
    assert [(c.factor, c.a, c.b) for c in primary] == [("encoder", "raw", "farneback")]
    assert primary[0].family_size == 1 and primary[0].p_holm == pytest.approx(primary[0].p)
    explo = [c for c in comps if c.family == "exploratory"]
    assert len(explo) == len(everything) - 1
    assert all(c.family_size == len(explo) for c in explo)
    assert all({c.a, c.b} != {"raw", "farneback"} for c in explo)


def test_seed_means_of_k_folds_take_the_factor_k_over_k_minus_1():
    """Rows of a 5-fold design without fold ids: the t over seed means, TOST, the runs
    needed and the per-class gains all use K/(K − 1), not 1/(K − 1)."""
    from scipy import stats

    from tactbench.runner.analysis.comparisons import comparisons

    rows = _clear_win_rows(seeds=range(6))
    for r in rows:
        r["folds"] = 5
    [c] = comparisons(rows, margin=30)
    d = np.array(list(c.per_run.values()))
    half = stats.t.ppf(0.975, 5) * (stats.tvar(d) * (1 / 6 + 5 / 4)) ** 0.5
    assert "split-seed means" in c.method and c.ratio == c.run_ratio == pytest.approx(1.25)
    assert (c.low, c.high) == (pytest.approx(c.difference - half),
                               pytest.approx(c.difference + half))


def test_a_reader_gets_bayesian_probabilities_power_and_a_named_ceiling():
    from tactbench.runner.analysis.comparisons import comparisons

    [c] = comparisons(_clear_win_rows(seeds=range(6)))
    probs = (c.bayes_a_better, c.bayes_equivalent, c.bayes_b_better)
    assert sum(probs) == pytest.approx(1.0) and c.bayes_b_better > 0.9
    assert c.bayes_margin == 1.0 and c.detectable_effect > 0
    truth = [0, 1] * 20
    perfect = [_row(e, s, truth, truth) for s in range(4) for e in ("raw", "farneback")]
    [top] = comparisons(perfect)
    assert top.ceiling and "ceiling" in top.note


def test_fewer_than_3_runs_give_no_verdict_in_every_output(tmp_path):
    from tactbench.runner.analysis.comparisons import comparisons

    rows = _clear_win_rows(seeds=(0, 1))
    c = comparisons(rows)[0]
    assert c.verdict == "too few runs" and c.p_holm is not None
    paths = write_reports(tmp_path / "out", rows, plots=False)
    report = paths["markdown"].read_text()
    assert "## Paired comparisons over runs" in report and "| too few runs |" in report
    assert "test window: `first`" in report
    assert json.loads(paths["json"].read_text())["comparisons"][0]["verdict"] == \
        "too few runs"


def test_a_few_discordant_recordings_give_no_verdict_however_many_rows():
    from tactbench.runner.analysis.comparisons import comparisons

    truth = [0, 1] * 20
    rows = []
    for seed in range(8):  # B always wins on the same 3 recordings, and only there
        rows.append(_row("raw", seed, truth, [1 - t if i < 3 else t
                                              for i, t in enumerate(truth)]))
        rows.append(_row("farneback", seed, truth, truth))
    [c] = comparisons(rows)
    assert c.b_only == 24 and c.discordant_recordings == 3
    assert c.verdict == "unresolved" and "3 distinct test recording" in c.note


def test_holm_adjusts_within_the_family_and_a_margin_shows_equivalence():
    from tactbench.runner.analysis.comparisons import comparisons

    truth = [0, 1] * 20
    rows = []
    for seed in range(8):  # equal accuracy, different mistakes: a tie
        for enc, shift in (("raw", 0), ("farneback", 20)):
            rows.append(_row(enc, seed, truth, [1 - t if (i + shift + seed) % 40 < 4 else t
                                                for i, t in enumerate(truth)]))
    rows += [dict(r, L=3, key=r["key"] + "-3") for r in rows]
    comps = comparisons(rows, margin=2.0)
    assert len(comps) == 4 and {c.family_size for c in comps} == {4}
    for c in comps:
        assert c.p_holm >= c.p
    enc = [c for c in comps if c.factor == "encoder"]
    assert all(c.difference == 0 for c in enc)
    assert all(c.verdict == "equivalent" and c.equivalence_margin == 2.0 for c in enc)


def test_a_contrast_pairs_two_cells_differing_in_two_factors():
    from tactbench.errors import InputError
    from tactbench.runner.analysis.comparisons import comparisons
    from tactbench.runner.execution.questions import parse_contrast

    rows = _clear_win_rows(seeds=range(6), L=3) + [
        dict(r, L=6, key=r["key"] + "-6") for r in _clear_win_rows(seeds=range(6))
        if r["encoder"] == "raw"]
    comps = comparisons(rows, contrasts=["encoder=raw,L=6..encoder=farneback,L=3"])
    [c] = [c for c in comps if c.factor == "contrast"]
    assert (c.a, c.b, c.where) == ("encoder=raw,L=6", "encoder=farneback,L=3",
                                   {"classifier": "logreg"})
    assert c.difference > 0 and c.runs == 6
    assert len(comps) == 3 and all(x.family_size == 3 for x in comps)
    for bad, match in (("raw..farneback", "factor=value"), ("encoder=raw", "'..'"),
                       ("encoder=raw..L=3", "same factors"), ("seed=1..seed=2", "unknown"),
                       ("encoder=raw..encoder=raw", "itself")):
        with pytest.raises(InputError, match=match):
            parse_contrast(bad)
    with pytest.raises(InputError, match="names no two cells"):
        from tactbench.runner.execution.questions import check_contrasts

        check_contrasts(["encoder=dis..encoder=raw"], [{"encoder": "raw", "classifier": "x",
                                                        "L": 5}])


def test_per_user_accuracy_and_gains_on_a_users_split(tmp_path):
    from tactbench.runner.analysis.comparisons import comparisons

    rows = _clear_win_rows(seeds=range(6))
    users = [f"u{i // 10}" for i in range(40)]  # four users, ten recordings each
    [c] = comparisons(rows, users=users)
    u = c.per_user
    assert u.users == 4 and u.helped + u.hurt <= 4 and u.helped >= 1
    assert set(u.gains) == {"u0", "u1", "u2", "u3"}
    raw = [s for s in summarise(rows, users=users) if s["encoder"] == "raw"][0]
    assert set(raw["per_user_accuracy"]) == set(u.gains)
    report = write_reports(tmp_path, rows, plots=False, users=users)["markdown"].read_text()
    assert "### Per-user gains" in report and "## Per-user accuracy" in report
    # a compact spread, not a column per user; every user's value drawn in the figure
    assert "| encoder | classifier | L | users | median |" in report and "| u0 |" not in report
    paths = write_reports(tmp_path / "plots", rows, users=users)
    assert paths["per_user_accuracy"].stat().st_size > 1000
    assert "per_user_accuracy.png" in paths["markdown"].read_text()


def test_the_variance_is_decomposed_where_runs_vary_split_and_init_apart(tmp_path):
    from tactbench.runner.analysis.comparisons import comparisons
    from tactbench.runner.analysis.summaries import variance_decomposition

    rows = []
    for split in range(3):
        for init in range(2):
            for r in _clear_win_rows(seeds=[split]):
                rows.append(dict(r, init_seed=init, key=f"{r['key']}-{init}"))
    [v] = [v for v in variance_decomposition(rows) if v["encoder"] == "raw"]
    assert (v["split_seeds"], v["init_seeds"]) == (3, 2) and v["init_sd"] == 0
    [c] = comparisons(rows)
    assert c.runs == 3  # a split is the unit; its init seeds are averaged
    report = write_reports(tmp_path, rows, plots=False)["markdown"].read_text()
    assert "## Where each cell's accuracy variance comes from" in report


def test_l_and_classifier_pairs_and_the_seed_interval_in_the_table():
    from tactbench.runner.analysis.comparisons import comparisons
    from tactbench.runner.presentation.tables import markdown_table

    truth = [0, 1] * 10
    rows = [_row("raw", s, truth, truth, L=L, classifier=clf)
            for s in (0, 1, 2) for L in (3, 5) for clf in ("logreg", "taxel-lstm:epochs=3")]
    factors = sorted(c.factor for c in comparisons(rows))
    assert factors == ["L", "L", "classifier", "classifier"]
    rows[0]["accuracy"] = 0.9
    summary = [s for s in summarise(rows) if s["L"] == 3 and s["classifier"] == "logreg"][0]
    low, high = summary["accuracy_ci95"]
    assert low < summary["accuracy_mean"] < high
    assert f"{100 * low:.1f}–{100 * high:.1f}" in markdown_table([summary])
    one_seed = summarise([rows[0]])[0]
    assert one_seed["accuracy_ci95"] is None
    near_one = summarise([_row("raw", s, [0, 1] * 10, [0, 1] * 10 if s else [0, 1] * 9 + [0, 0])
                          for s in (0, 1, 2)])[0]
    assert near_one["accuracy_ci95"][1] == 1.0  # clipped: a mean accuracy is at most 1


def test_only_shared_seeds_and_sequences_are_paired_and_old_rows_are_left_out():
    from tactbench.runner.analysis.comparisons import comparisons

    truth = [0, 1] * 10
    a = _row("raw", 0, truth, truth)
    b = _row("farneback", 0, truth[:10], truth[:10], indices=list(range(5, 15)))
    b["test_predictions"]["labels"] = [truth[i] for i in range(5, 15)]
    extra_seed = _row("farneback", 1, truth, truth)
    c = comparisons([a, b, extra_seed])[0]
    assert c.test_recordings == 10 and c.runs == 1
    old = dict(a)
    del old["test_predictions"]
    assert comparisons([old, b]) == []


def test_a_row_with_broken_predictions_is_a_damaged_row():
    from tactbench.runner.execution.results import check_row

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


# ------------------------------------------------------------ plots


def _scored(encoder, seed, L, wrong_a, wrong_b, *, cost=1.0, classifier="logreg"):
    """A row of 10 + 10 test sequences, ``wrong_a`` / ``wrong_b`` of them misclassified."""
    truth = [0] * 10 + [1] * 10
    predicted = [1] * wrong_a + [0] * (10 - wrong_a) + [0] * wrong_b + [1] * (10 - wrong_b)
    row = _row(encoder, seed, truth, predicted, L=L, classifier=classifier)
    row["per_class_accuracy"] = {"a": 1 - wrong_a / 10, "b": 1 - wrong_b / 10}
    row["confusion"] = [[10 - wrong_a, wrong_a], [wrong_b, 10 - wrong_b]]
    row["encode_ms_per_frame"] = cost
    return row


def _grid(seeds=(0, 1, 2), lengths=(3, 5)):
    rows = []
    for seed in seeds:
        for L in lengths:
            rows.append(_scored("raw", seed, L, 4 - L // 3 + seed % 2, 3, cost=0.01))
            rows.append(_scored("farneback", seed, L, 1, 2 - L // 5 + seed % 2, cost=1.3))
    return rows


def test_pareto_front_by_hand():
    from tactbench.pareto import pareto_front

    points = [(1.0, 0.8),  # 0: front
              (2.0, 0.9),  # 1: front
              (0.5, 0.7),  # 2: front (cheapest)
              (3.0, 0.85),  # 3: beaten by 1 (cheaper and better)
              (2.0, 0.9),  # 4: equal to 1: both on the front
              (1.0, 0.6),  # 5: same cost as 0, worse
              (float("nan"), 0.99),  # 6: no cost, never on the front
              (4.0, 0.95),  # 7: front (best)
              (0.7, 0.7)]  # 8: same accuracy as 2, dearer
    assert pareto_front(points) == [2, 0, 1, 4, 7]
    assert pareto_front([]) == []
    assert pareto_front([(0.0, 0.5)]) == [0]


def test_accuracy_against_l_has_ci_bands_and_the_other_figures_apply(tmp_path, drawn):
    from tactbench.paths import check_output_folder
    from tactbench.runner.execution.results import is_run_output

    rows = _grid()
    paths = write_reports(tmp_path / "out", rows)
    names = sorted(p.name for p in (tmp_path / "out").glob("*.png"))
    assert names == ["accuracy_vs_L.png", "confusion_farneback_logreg_L3.png",
                     "confusion_farneback_logreg_L5.png", "confusion_raw_logreg_L3.png",
                     "confusion_raw_logreg_L5.png", "cost_vs_accuracy.png",
                     "per_class_vs_L.png"]
    # one line per encoder with a band that is the 95 % CI of the mean over seeds
    ax = drawn["accuracy_vs_L"].axes[0]
    by_enc = {s["encoder"]: s for s in summarise(rows) if s["L"] == 3}
    bands = {}
    for line, band in zip(ax.get_lines(), ax.collections):
        enc = line.get_label().split(" / ")[0]
        bands[enc] = band.get_paths()[0].vertices[:, 1]
        assert "3 seeds, band: 95 % CI of the mean over seeds" in line.get_label()
    assert set(bands) == {"raw", "farneback"}
    for enc, ys in bands.items():
        low, high = by_enc[enc]["accuracy_ci95"]
        assert low < high and ys.min() <= 100 * low + 1e-9 and ys.max() >= 100 * high - 1e-9
    report = paths["markdown"].read_text()
    for name in names:
        assert f"({name})" in report
    assert "every line: 3 seeds, band: 95 % CI of the mean over seeds" in report
    # per-class accuracy against L: one panel per class, a line per encoder
    panels = [a for a in drawn["per_class_vs_L"].axes if a.get_visible()]
    assert [a.get_title() for a in panels] == ["a", "b"]
    raw_b = [ln for ln in panels[1].get_lines() if ln.get_label().startswith("raw")][0]
    assert list(raw_b.get_xdata()) == [3, 5]
    assert list(raw_b.get_ydata()) == pytest.approx([70.0, 70.0])
    far_b = [ln for ln in panels[1].get_lines() if ln.get_label().startswith("farneback")][0]
    assert list(far_b.get_ydata()) == pytest.approx([100 - 100 * (2 + 1 / 3) / 10,
                                                     100 - 100 * (1 + 1 / 3) / 10])
    # the next run into the same folder is not refused for the new figures
    check_output_folder(tmp_path / "out", option="out folder", ours=is_run_output)


def test_cost_against_accuracy_draws_the_pareto_front(tmp_path, drawn):
    rows = [_scored("raw", 0, 5, 3, 3, cost=0.0),  # free, 70 %: front
            _scored("farneback", 0, 5, 1, 1, cost=1.3),  # 90 %: front
            _scored("tvl1", 0, 5, 2, 2, cost=40.0),  # dearer and worse than farneback
            _scored("dis", 0, 5, 0, 1, cost=0.5)]  # cheaper and better than farneback
    paths = write_reports(tmp_path, rows)
    ax = drawn["cost_vs_accuracy"].axes[0]
    [step] = [ln for ln in ax.get_lines() if ln.get_label().startswith("Pareto front")]
    assert list(step.get_ydata()) == [70.0, 95.0]
    assert list(step.get_xdata()) == [1e-4, 0.5]  # a cost of 0 drawn at the axis' floor
    assert ax.get_xscale() == "log"
    assert "error bars: no band" in ax.get_title()  # one seed
    report = paths["markdown"].read_text()
    assert "the Pareto front" in report and "raw / logreg L=5 (0 ms, 70.0 %), dis / logreg " \
        "L=5 (0.5 ms, 95.0 %)." in report
    # with one L there is no curve against L, nor any band
    assert not (tmp_path / "accuracy_vs_L.png").exists()
    assert not (tmp_path / "per_class_vs_L.png").exists()
    assert "accuracy_vs_L" not in paths and "per_class_vs_L" not in paths


def test_one_seed_gives_lines_without_bands(tmp_path, drawn):
    rows = _grid(seeds=(0,))
    paths = write_reports(tmp_path, rows)
    ax = drawn["accuracy_vs_L"].axes[0]
    assert len(ax.get_lines()) == 2 and not ax.collections
    assert all("1 seed, no band" in ln.get_label() for ln in ax.get_lines())
    assert "every line: 1 seed, no band" in paths["markdown"].read_text()


def test_the_band_falls_back_to_the_std_and_then_to_none():
    from tactbench.runner.presentation.plots import accuracy_band, band_note

    s = {"seeds": [0, 1], "accuracy_mean": 0.8, "accuracy_std": 0.1,
         "accuracy_ci95": [0.7, 0.9]}
    assert accuracy_band(s) == (0.7, 0.9, "95 % CI of the mean over seeds")
    no_ci = dict(s, accuracy_ci95=None)
    assert accuracy_band(no_ci) == pytest.approx((0.7, 0.9, "± std over seeds"))
    one = {"seeds": [0], "accuracy_mean": 0.8, "accuracy_std": 0.0, "accuracy_ci95": None}
    assert accuracy_band(one) is None
    assert band_note([s, one]) == ("1–2 seeds, band: 95 % CI of the mean over seeds, "
                                   "none where one seed")


def test_published_points_are_drawn_and_tabled_beside_ours(tmp_path, drawn):
    rows = _grid()
    reference = [{"label": "raw", "L": 5, "accuracy": 0.807},
                 {"label": "farneback", "L": 5, "accuracy": 0.891, "err": 0.02},
                 {"label": "farneback", "L": 3, "accuracy": 0.85},
                 {"label": "tvl1", "L": 5, "accuracy": 0.5}]
    paths = write_reports(tmp_path, rows, reference=reference)
    ax = drawn["accuracy_vs_L"].axes[0]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "study (published): raw" in legend and "study (published): farneback" in legend
    published = {c.get_label(): list(c.lines[0].get_ydata()) for c in ax.containers}
    assert published["study (published): farneback"] == pytest.approx([85.0, 89.1])
    report = paths["markdown"].read_text()
    section = report.split("## Published reference points", 1)[1]
    ours = [s for s in summarise(rows) if s["encoder"] == "farneback" and s["L"] == 5][0]
    assert (f"| farneback | 5 | 89.1 ± 2.0 | farneback / logreg | "
            f"{100 * ours['accuracy_mean']:.1f} ± {100 * ours['accuracy_std']:.1f} |") in section
    assert "| tvl1 | 5 | 50.0 | - | - | - |" in section  # nothing of ours to set beside it
    assert "study (published)" in report
    doc = json.loads(paths["json"].read_text())
    assert doc["reference"][1] == {"label": "farneback", "L": 5, "accuracy": 0.891,
                                   "err": 0.02}
    # without plots the table is still there
    assert "## Published reference points" in write_reports(
        tmp_path / "np", rows, plots=False, reference=reference)["markdown"].read_text()


@pytest.mark.parametrize("point, problem", [
    ({"label": "raw", "L": 5, "accuracy": 80.7},
     "reference point 1 (raw): accuracy must be a fraction in [0, 1], got 80.7 "
     "(write 0.807 for 80.7 %)"),
    ({"label": "raw", "accuracy": 0.8}, "reference point 1 lacks L"),
    ({"label": "raw", "L": 0, "accuracy": 0.8}, "L must be a whole number ≥ 1, got 0"),
    ({"label": "raw", "L": 5, "accuracy": 0.8, "err": -1}, "err must be a fraction"),
    ({"label": "raw", "L": 5, "accuracy": 0.8, "sd": 1}, "unknown field(s) sd"),
    ("raw", "must be a mapping"),
])
def test_a_wrong_reference_point_is_one_line_before_any_file(tmp_path, point, problem):
    from tactbench.errors import InputError

    with pytest.raises(InputError) as err:
        write_reports(tmp_path / "out", _grid(seeds=(0,)), reference=[point])
    assert problem in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "out").exists()


def test_failed_cells_only_draw_nothing(tmp_path):
    rows = [dict(_scored("raw", 0, 5, 1, 1), status="failed",
                 error={"type": "MemoryError", "message": "x"})]
    write_reports(tmp_path, rows, reference=[{"label": "raw", "L": 5, "accuracy": 0.8}])
    assert list(tmp_path.glob("*.png")) == []


def test_a_line_with_one_seed_at_some_l_says_where_it_has_no_band(tmp_path, drawn):
    rows = [r for r in _grid(seeds=(0, 1), lengths=(3, 5, 7))
            if r["seed"] == 0 or r["L"] != 7]
    paths = write_reports(tmp_path, rows)
    ax = drawn["accuracy_vs_L"].axes[0]
    assert len(ax.collections) == 2  # a band for each line, where it has one
    for line in ax.get_lines():
        assert line.get_label().endswith(
            "(1–2 seeds, band: 95 % CI of the mean over seeds, none where one seed)")
    assert "none where one seed" in paths["markdown"].read_text()


def test_short_names_keep_the_estimator():
    from tactbench.runner.execution.questions import short_name

    assert short_name("small-cnn-lstm:epochs=4,width=16") == "small-cnn-lstm"
    assert short_name("sklearn:C=10,estimator=SVC") == "sklearn:SVC"
    assert short_name("logreg") == "logreg"


def test_k_fold_users_runs_use_the_corrected_repeated_k_fold_t_over_fold_differences():
    from tactbench.data.splits import user_folds
    from tactbench.runner.analysis.comparisons import comparisons

    users = [f"u{i // 4}" for i in range(40)]  # ten users, four recordings each
    truth = [i % 2 for i in range(40)]
    rows = []
    for seed in range(4):
        folds = user_folds(users, truth, seed=seed, folds=5)
        order = [int(i) for f in folds for i in f.test]  # the cell's pooled fold order
        fold_ids = [k for k, f in enumerate(folds) for _ in f.test]
        for enc, wrong in (("raw", {o for o in order if (o + seed) % 5 == 0}),
                           ("farneback", {o for o in order if (o + seed) % 9 == 0})):
            y = [truth[i] for i in order]
            pred = [1 - truth[i] if i in wrong else truth[i] for i in order]
            r = _row(enc, seed, y, pred, indices=order)
            r["test_predictions"].update(folds=fold_ids, groups=[users[i] for i in order])
            r.update(split="users:folds=5", folds=5, split_seed=seed, n_train=32, n_test=40)
            rows.append(r)
    [c] = comparisons(rows, users=users)
    assert c.method == "corrected repeated 5-fold t (Bouckaert–Frank) over 20 fold differences"
    assert c.df == 19 and c.ratio == pytest.approx(1 / 4)
    assert comparisons(rows) == [dataclasses.replace(c, per_user=None)]  # folds: the rows'
    for r in rows:  # rows made before they kept their folds: the seeds' means
        del r["test_predictions"]["folds"]
    [plain] = comparisons(rows)
    assert plain.df == 3 and plain.difference == pytest.approx(c.difference)
    assert plain.method == ("corrected repeated 5-fold t (Bouckaert–Frank) over 4 split-seed "
                            "means (the rows carry no fold ids)")
    assert c.permutation_p == plain.permutation_p  # the sign-flip is over seeds


def test_a_contrast_side_keeps_the_commas_of_a_spec_with_several_options():
    from tactbench.errors import InputError
    from tactbench.runner.execution.questions import parse_contrast

    a, b = parse_contrast("encoder=farneback:levels=3,winsize=9,L=3"
                          "..encoder=dis:preset=fast,L=6")
    assert a == {"encoder": "farneback:levels=3,winsize=9", "L": "3"}
    assert b == {"encoder": "dis:preset=fast", "L": "6"}
    a, b = parse_contrast("classifier=small-cnn-lstm:width=8,epochs=2"
                          "..classifier=small-cnn-lstm")
    assert a == {"classifier": "small-cnn-lstm:width=8,epochs=2"}
    # a plain value takes no continuation: a stray item is still a mistake
    with pytest.raises(InputError, match="unknown factor 'winsize'"):
        parse_contrast("encoder=raw,winsize=9..encoder=dis,winsize=9")


def test_the_runs_that_computed_the_rows_are_named_one_way():
    from tactbench.runner.analysis.report import computed_by

    def row(key, command, git, finished):
        return {"key": key, "finished": finished, "run": {"command": command, "git": git}}

    rows = [row("b", ".venv/bin/tactbench run -L 5", "abc", "2026-01-02"),
            row("a", "/src/tactbench/__main__.py run -L 5", "abc", "2026-01-01"),
            row("c", "tactbench run -L 5 --seed 0-9", "def", "2026-01-03"),
            {"key": "d", "finished": "2025-12-31"}]  # a row from before runs were recorded
    assert computed_by(rows) == [
        {"command": None, "git": None, "cells": 1},
        {"command": "tactbench run -L 5", "git": "abc", "cells": 2},
        {"command": "tactbench run -L 5 --seed 0-9", "git": "def", "cells": 1}]
