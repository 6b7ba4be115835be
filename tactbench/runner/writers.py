"""The files of a run's out folder: results.json, results.csv, report.md and the figures.

:data:`OUT_FILES` lists every top-level file a run writes besides ``confusion_*.png``
(the out-folder check of :mod:`tactbench.runner.planning` reads it from here).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any, Iterable, Sequence

from tactbench.paths import atomic_write_text
from tactbench.runner.plots import FIGURES, caption, check_reference, write_plots
from tactbench.runner.store import ok_rows, row_status
from tactbench.runner.summaries import comparisons, summarise
from tactbench.runner.tables import (
    comparisons_markdown,
    failed_cells_markdown,
    markdown_table,
    per_class_markdown,
    reference_markdown,
)

#: Every top-level file a run writes (``confusion_*.png`` besides, one per cell).
OUT_FILES = ("results.json", "results.csv", "report.md",
             *(f"{name}.png" for name in FIGURES))


def rows_csv(rows: Sequence[dict[str, Any]]) -> str:
    """Flat CSV: one line per cell, per-class accuracies as ``acc_<class>`` columns.

    A failed cell's line has ``status`` ``failed``, its error in ``error`` and no
    accuracy or costs.
    """
    classes: list[str] = []
    for r in rows:
        for c in r["classes"]:
            if c not in classes:
                classes.append(c)
    columns = ["dataset", "dataset_hash", "split", "split_seed", "encoder", "encoder_version",
               "classifier", "profile", "L", "seed", "status", "accuracy",
               *[f"acc_{c}" for c in classes],
               "encode_ms_per_frame", "train_s", "inference_ms_per_sequence", "peak_rss_mb",
               "peak_step", "n_train_windows", "n_test", "device", "threads", "finished", "key",
               "error"]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    for r in rows:
        flat = {**r, "status": row_status(r)}
        for c in classes:
            flat[f"acc_{c}"] = r.get("per_class_accuracy", {}).get(c)
        if "error" in r:
            flat["error"] = f"{r['error'].get('type')}: {r['error'].get('message')}"
        writer.writerow(flat)
    return buf.getvalue()


def write_reports(out: str | Path, rows: Sequence[dict[str, Any]], *,
                  meta: dict[str, Any] | None = None, plots: bool = True,
                  reference: Iterable[dict[str, Any]] | None = None) -> dict[str, Path]:
    """Write results.json, results.csv, report.md and the plots into ``out``.

    ``rows``: every row of the run, ok and failed (failed cells are listed in report.md,
    kept in the JSON and CSV, and left out of summaries and plots). ``reference``: the
    published points to set beside ours (:func:`check_reference`): drawn in
    ``accuracy_vs_L.png``, tabled in report.md and kept in results.json.
    """
    out = Path(out)
    reference = check_reference(reference)  # a mistake is refused before any file
    out.mkdir(parents=True, exist_ok=True)
    summaries = summarise(rows)
    comps = comparisons(rows)
    paths = {"json": out / "results.json", "csv": out / "results.csv",
             "markdown": out / "report.md"}
    doc = {"meta": meta or {}, "summary": summaries, "comparisons": comps,
           "rows": list(rows)}
    if reference:
        doc["reference"] = reference
    atomic_write_text(paths["json"], json.dumps(doc, indent=2))
    atomic_write_text(paths["csv"], rows_csv(rows))
    figures: dict[str, Path] = {}
    if plots and summaries:
        figures = write_plots(out, summaries, reference=reference)
        paths.update(figures)
    atomic_write_text(paths["markdown"], markdown_report(summaries, rows, meta or {},
                                                         figures, comps,
                                                         reference=reference))
    return paths


def markdown_report(summaries, rows, meta, figures, comps=(), *, reference=()) -> str:
    """report.md: run facts, the accuracy/cost table, per-class accuracy, paired
    comparisons, published reference points, failed cells, figures with captions."""
    done = ok_rows(rows)
    failed = failed_cells_markdown(rows)
    first = done[0] if done else (rows[0] if rows else {})
    n_failed = len(rows) - len(done)
    lines = [
        "# tactbench report", "",
        f"- dataset: `{first.get('dataset', '?')}` (content hash "
        f"`{str(first.get('dataset_hash', '?'))[:16]}`)",
        f"- split: `{first.get('split', '?')}`; test window: "
        f"`{first.get('test_window', 'first')}` (the L frames each test sequence is "
        f"classified on); profile: `{first.get('profile', '?')}`; "
        f"device: `{first.get('device', '?')}`",
        f"- cells: {len(rows)}" + (f" ({n_failed} failed, listed below)" if n_failed else "")
        + f"; command: `{meta.get('command', '')}`",
        f"- git: `{meta.get('git')}`; versions: "
        + ", ".join(f"{k} {v}" for k, v in first.get("versions", {}).items()),
        "",
        "Accuracy is mean ± standard deviation over seeds, with a 95 % t-interval of the "
        "mean over seeds (test set: "
        f"{first.get('n_test', '?')} sequences per seed). Encode cost is per frame on one "
        "core; train seconds are wall time; inference is per test sequence, batched. "
        "Peak MB is the peak resident memory of the process that ran the cell; peak step "
        "is the step that set it (load encoding, windows, fit, predict, save model, or "
        "\"before this cell\": earlier work in the same process, such as a serial run's "
        "encoding).",
        "", markdown_table(summaries), "", "## Per-class accuracy (%, mean over seeds)", "",
        per_class_markdown(summaries), "",
    ]
    if comps:
        lines += ["## Paired comparisons", "",
                  "Every two cells that differ in one factor, compared on the same test "
                  "sequences under the same seeds: the mean difference of accuracy B − A "
                  "(points) with a 95 % bootstrap interval over test sequences, how many "
                  "seeds agree on its sign, and McNemar's exact p-value on the pooled paired "
                  "predictions. A difference whose interval spans zero is *unresolved*, not "
                  "a win (see docs/statistics.md).", "", comparisons_markdown(comps), ""]
    if reference:
        lines += ["## Published reference points", "",
                  "The study's published accuracies (as given to the report), each beside "
                  "our cells of the same encoder (or `encoder / classifier`) and L.", "",
                  reference_markdown(reference, summaries), ""]
    if failed:
        lines += ["## Failed cells", "",
                  f"{n_failed} cell(s) raised; their rows (with the traceback's last frames) "
                  "are in `cells/`, and the next run of the same command retries them.", "",
                  failed, ""]
    if figures:
        lines += ["## Figures", ""]
    for name, path in figures.items():
        lines += [f"![{name}]({path.name})", "", f"*{caption(name, summaries, reference)}*",
                  ""]
    return "\n".join(lines)

