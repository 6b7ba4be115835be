"""Reports name a classifier by its short name, and tell apart two specs of one
classifier (``--classifier small-cnn-lstm --classifier small-cnn-lstm:width=8``) by the
options that differ: in the tables, the comparisons, the figures and their file names.
Rows are built by hand (no training)."""

from __future__ import annotations

import pytest

from tactbench.runner.analysis.comparisons import comparisons
from tactbench.runner.analysis.summaries import failed_cells, summarise
from tactbench.runner.execution.questions import spec_labels
from tactbench.runner.orchestrate import write_reports

#: Two resolved specs of one classifier (profile defaults merged), as rows store them.
WIDE = ("small-cnn-lstm:batch_size=64,epochs=4,head=concat,input_size=16,lr=0.003,"
        "optimizer=adamw,schedule=onecycle,weight_decay=0.01,width=16,"
        "windows_per_epoch=24000")
NARROW = WIDE.replace("width=16", "width=8")


def _row(classifier, seed, wrong, *, encoder="raw", L=5, n=20):
    """A row of ``n`` test sequences (two classes), ``wrong`` of them misclassified (from
    sequence 3 × seed on)."""
    truth = [i % 2 for i in range(n)]
    predicted = [1 - t if (i - 3 * seed) % n < wrong else t for i, t in enumerate(truth)]
    acc = 1 - wrong / n
    return {"key": f"{encoder}-{classifier}-{seed}-{L}", "dataset": "d", "split": "paper",
            "encoder": encoder, "classifier": classifier, "L": L, "seed": seed,
            "status": "ok", "classes": ["a", "b"], "accuracy": acc,
            "per_class_accuracy": {"a": acc, "b": acc}, "confusion": [[9, 1], [1, 9]],
            "encode_ms_per_frame": 1.0, "train_s": 1.0, "inference_ms_per_sequence": 1.0,
            "peak_rss_mb": 1.0, "n_train": 3 * n, "n_test": n,
            "test_predictions": {"indices": list(range(n)), "labels": truth,
                                 "predictions": predicted}}


def _variant_rows(seeds=range(3), lengths=(5,)):
    """WIDE (wrong on 2 of 20), NARROW (wrong on 6) and a logreg (wrong on 4) per run."""
    return [_row(clf, seed, wrong, L=L) for seed in seeds for L in lengths
            for clf, wrong in ((WIDE, 2 + seed % 2), (NARROW, 6 + seed % 2),
                               ("logreg", 4))]


def _table_lines(report: str, header: str) -> list[str]:
    """The body lines of the Markdown table whose header line starts with ``header``."""
    lines = report.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header))
    body = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        body.append(line)
    return body


def test_labels_are_short_names_unless_two_specs_share_one():
    assert spec_labels([WIDE, NARROW, "logreg", "sklearn:estimator=SVC"]) == {
        WIDE: "small-cnn-lstm (width=16)", NARROW: "small-cnn-lstm (width=8)",
        "logreg": "logreg", "sklearn:estimator=SVC": "sklearn:SVC"}
    # several options differ: by key, joined without a comma; a missing one is the default
    assert spec_labels(["cnn:lr=0.1,width=8", "cnn:lr=0.01,width=16", "cnn:lr=0.1"]) == {
        "cnn:lr=0.1,width=8": "cnn (lr=0.1; width=8)",
        "cnn:lr=0.01,width=16": "cnn (lr=0.01; width=16)",
        "cnn:lr=0.1": "cnn (lr=0.1; width=default)"}
    # the estimator is in the short name: two estimators need nothing more
    assert spec_labels(["sklearn:C=1,estimator=SVC", "sklearn:C=1,estimator=RF"]) == {
        "sklearn:C=1,estimator=SVC": "sklearn:SVC", "sklearn:C=1,estimator=RF": "sklearn:RF"}
    # the same options spelled in another order cannot be told apart by options: whole
    assert spec_labels(["cnn:a=1,b=2", "cnn:b=2,a=1"]) == {"cnn:a=1,b=2": "cnn:a=1,b=2",
                                                          "cnn:b=2,a=1": "cnn:b=2,a=1"}
    assert spec_labels([WIDE, WIDE]) == {WIDE: "small-cnn-lstm"}


def test_two_variants_of_a_classifier_are_told_apart_in_the_results_table(tmp_path):
    rows = _variant_rows()
    report = write_reports(tmp_path / "out", rows, plots=False)["markdown"].read_text()
    table = _table_lines(report, "| encoder | classifier | input |")
    shown = [line.split(" | ")[1] for line in table]
    assert sorted(shown) == ["logreg", "small-cnn-lstm (width=16)", "small-cnn-lstm (width=8)"]
    per_class = _table_lines(report, "| encoder | classifier | L | a | b |")
    assert sorted(line.split(" | ")[1] for line in per_class) == sorted(shown)


def test_two_variants_are_told_apart_in_the_paired_comparisons(tmp_path):
    from tactbench.runner.presentation.tables import comparison_rows

    rows = _variant_rows(seeds=range(6))
    comps = comparisons(rows)
    [c] = [c for c in comps if {c.a, c.b} == {WIDE, NARROW}]
    [table_row] = [r for r in comparison_rows(comps) if {r[1], r[2]} == {
        "small-cnn-lstm (width=16)", "small-cnn-lstm (width=8)"}]
    wide_first = table_row[1] == "small-cnn-lstm (width=16)"
    assert wide_first == (c.a == WIDE)
    assert table_row[-1] == "small-cnn-lstm (width=16) better"  # wrong on fewer, every run
    # the unique classifier keeps its short name beside them
    assert any(r[1] == "logreg" or r[2] == "logreg" for r in comparison_rows(comps))
    report = write_reports(tmp_path / "out", rows, plots=False)["markdown"].read_text()
    body = _table_lines(report, "| factor | A | B | where |")
    assert any("| small-cnn-lstm (width=16) | small-cnn-lstm (width=8) |" in line
               or "| small-cnn-lstm (width=8) | small-cnn-lstm (width=16) |" in line
               for line in body)


def test_a_contrast_names_the_variant_of_each_side():
    from tactbench.runner.presentation.tables import comparison_rows

    rows = _variant_rows(seeds=range(4), lengths=(3, 5))
    # by the short name: every variant at L=5 against every variant at L=3, each named
    comps = comparisons(rows, contrasts=["classifier=small-cnn-lstm,L=5.."
                                         "classifier=small-cnn-lstm,L=3"])
    pairs = {(c.a, c.b) for c in comps if c.factor == "contrast"}
    assert pairs == {(f"classifier=small-cnn-lstm ({a}),L=5",
                      f"classifier=small-cnn-lstm ({b}),L=3")
                     for a in ("width=16", "width=8") for b in ("width=16", "width=8")}
    # by the label the reports show: that variant only
    comps = comparisons(rows, contrasts=["classifier=small-cnn-lstm (width=16),L=5.."
                                         "classifier=small-cnn-lstm (width=8),L=3"])
    [c] = [c for c in comps if c.factor == "contrast"]
    assert (c.a, c.b) == ("classifier=small-cnn-lstm (width=16),L=5",
                                "classifier=small-cnn-lstm (width=8),L=3")
    [row] = comparison_rows([c])
    assert row[1:4] == ["small-cnn-lstm (width=16) L=5", "small-cnn-lstm (width=8) L=3",
                        "raw"]


def test_two_variants_get_their_own_confusion_figures_and_lines(tmp_path, drawn):
    rows = _variant_rows(lengths=(3, 5))
    paths = write_reports(tmp_path / "out", rows)
    names = sorted(p.name for p in (tmp_path / "out").glob("confusion_*.png"))
    assert names == [f"confusion_raw_{c}_L{L}.png" for c in
                     ("logreg", "small-cnn-lstm-width-16", "small-cnn-lstm-width-8")
                     for L in (3, 5)]
    report = paths["markdown"].read_text()
    assert ("Confusion matrix of raw / small-cnn-lstm (width=8), L=3" in report
            and "Confusion matrix of raw / small-cnn-lstm (width=16), L=3" in report)
    # each variant is its own line against L (not one line through both), and own point
    lines = {ln.get_label().split(" (3 seeds")[0]: list(ln.get_xdata())
             for ln in drawn["accuracy_vs_L"].axes[0].get_lines()}
    assert lines == {f"raw / {c}": [3, 5] for c in (
        "logreg", "small-cnn-lstm (width=16)", "small-cnn-lstm (width=8)")}
    points = {t.get_text() for t in drawn["cost_vs_accuracy"].axes[0].texts}
    assert {"raw / small-cnn-lstm (width=16) L=5", "raw / small-cnn-lstm (width=8) L=5",
            "raw / logreg L=5"} <= points
    assert drawn["confusion_raw_small-cnn-lstm-width-8_L3"].axes[0].get_title() == \
        "raw / small-cnn-lstm (width=8), L=3"


def test_encoders_that_slug_alike_do_not_overwrite_each_others_confusion_figure():
    from tactbench.runner.presentation.plots import confusion_names

    summaries = summarise([_row("logreg", 0, 2, encoder="x:mode=a.b"),
                           _row("logreg", 0, 4, encoder="x:mode=a-b"),
                           _row("logreg", 0, 4, encoder="farneback:winsize=9"),
                           _row("logreg", 0, 4, encoder="farneback")])
    names = confusion_names(summaries)
    assert len(set(names)) == 4
    by_encoder = dict(zip((s["encoder"] for s in summaries), names))
    assert by_encoder["farneback"] == "confusion_farneback_logreg_L5"
    assert by_encoder["farneback:winsize=9"] == "confusion_farneback-winsize-9_logreg_L5"
    assert by_encoder["x:mode=a.b"].startswith("confusion_x-mode-a-b_logreg_L5_")


def test_a_failed_variant_is_listed_under_its_label():
    failed = dict(_row(NARROW, 0, 0), status="failed",
                  error={"type": "RuntimeError", "message": "out of memory"})
    for key in ("accuracy", "test_predictions"):
        failed.pop(key)
    listed = failed_cells([_row(WIDE, 0, 2), failed, _row("logreg", 0, 2)])
    assert [f["classifier"] for f in listed] == ["small-cnn-lstm (width=8)"]


@pytest.mark.parametrize("classifier", ["logreg", WIDE])
def test_a_run_with_unique_names_shows_short_names_as_before(tmp_path, classifier):
    rows = [_row(classifier, seed, 2 + seed % 2, encoder=enc, L=L) for seed in range(3)
            for enc in ("raw", "farneback") for L in (3, 5)]
    short = classifier.split(":")[0]
    paths = write_reports(tmp_path / "out", rows)
    report = paths["markdown"].read_text()
    assert "(width=" not in report
    assert {line.split(" | ")[1] for line in _table_lines(
        report, "| encoder | classifier | input |")} == {short}
    assert sorted(p.name for p in (tmp_path / "out").glob("confusion_*.png")) == [
        f"confusion_{e}_{short}_L{L}.png" for e in ("farneback", "raw") for L in (3, 5)]


def test_a_cell_names_its_variant_in_progress_and_peak_steps():
    from tactbench.runner.execution.planning import Cell

    labels = spec_labels([WIDE, NARROW, "sklearn:C=1,estimator=SVC"])
    assert Cell("raw", NARROW, 5, 0, "k").label(labels) == \
        "raw × small-cnn-lstm (width=8) L=5 seed=0"
    # a classifier no other spec shares is named as ever, with labels or without
    assert Cell("raw", "sklearn:C=1,estimator=SVC", 5, 0, "k").label(labels) == \
        "raw × sklearn L=5 seed=0" == Cell("raw", "sklearn:C=1,estimator=SVC", 5, 0,
                                           "k").label()
