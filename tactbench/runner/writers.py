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

from tactbench.data.windows import UNNAMED_TEST_WINDOW
from tactbench.machine import describe_machines
from tactbench.paths import atomic_write_text
from tactbench.runner.comparisons import comparisons
from tactbench.runner.plots import FIGURES, caption, check_reference, write_plots
from tactbench.runner.results import ok_rows, row_status
from tactbench.runner.summaries import spec_labels, summarise, variance_decomposition
from tactbench.runner.tables import (
    comparisons_section,
    failed_cells_markdown,
    markdown_table,
    per_class_markdown,
    per_user_accuracy_markdown,
    reference_markdown,
    variance_markdown,
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
                  reference: Iterable[dict[str, Any]] | None = None,
                  contrasts: Sequence[str] = (), margin: float | None = None,
                  users: Sequence[str] | None = None) -> dict[str, Path]:
    """Write results.json, results.csv, report.md and the plots into ``out``.

    ``rows``: every row of the run, ok and failed (failed cells are listed in report.md,
    kept in the JSON and CSV, and left out of summaries and plots). ``reference``: the
    published points to set beside ours (:func:`check_reference`): drawn in
    ``accuracy_vs_L.png``, tabled in report.md and kept in results.json. ``contrasts``
    and ``margin`` (points): see :func:`tactbench.runner.comparisons.comparisons`;
    ``users``: the user of each dataset sample (by index), for per-user results.
    """
    out = Path(out)
    reference = check_reference(reference)  # a mistake is refused before any file
    out.mkdir(parents=True, exist_ok=True)
    doc = results_document(rows, meta=meta, reference=reference, contrasts=contrasts,
                           margin=margin, users=users)
    paths = {"json": out / "results.json", "csv": out / "results.csv",
             "markdown": out / "report.md"}
    atomic_write_text(paths["json"], json.dumps(doc, indent=2))
    atomic_write_text(paths["csv"], rows_csv(rows))
    figures: dict[str, Path] = {}
    if plots and doc["summary"]:
        figures = write_plots(out, doc["summary"], reference=reference,
                              labels=run_labels(rows, doc["summary"]))
        paths.update(figures)
    atomic_write_text(paths["markdown"], markdown_report(
        doc["summary"], rows, meta or {}, figures, doc["comparisons"], reference=reference,
        variance=doc["variance"]))
    return paths


def results_document(rows: Sequence[dict[str, Any]], *, meta: dict[str, Any] | None = None,
                     reference: Sequence[dict[str, Any]] = (), contrasts: Sequence[str] = (),
                     margin: float | None = None, users: Sequence[str] | None = None
                     ) -> dict[str, Any]:
    """results.json's content: ``meta``, ``summary``, ``comparisons`` (with the contrasts
    and margin they were made with in ``statistics``), ``variance``, ``rows`` and, when
    given, ``reference``. Everything but ``rows`` and ``meta`` is computed from the rows,
    so a stored document can be recomputed (``benchmarks/reports.py --from-stored``)."""
    rows = list(rows)
    doc = {"meta": meta or {}, "summary": summarise(rows, users=users),
           "comparisons": [c.to_dict() for c in comparisons(
               rows, contrasts=contrasts, margin=margin, users=users)],
           "statistics": {"unit": "run (one split seed)", "contrasts": list(contrasts),
                          "margin": margin, "per_user": users is not None},
           "variance": variance_decomposition(rows), "rows": rows}
    if reference:
        doc["reference"] = list(reference)
    return doc


def run_labels(rows: Sequence[dict[str, Any]], summaries: Sequence[dict[str, Any]] = ()
               ) -> dict[str, str]:
    """The name every report of a run shows for each of its classifiers: its short name,
    with the options that tell it apart where the run has several specs of one
    (:func:`tactbench.runner.summaries.spec_labels`, over every row, failed ones too)."""
    return spec_labels([*(r["classifier"] for r in rows),
                        *(s["classifier"] for s in summaries)])


def markdown_report(summaries, rows, meta, figures, comps=(), *, reference=(),
                    variance=()) -> str:
    """report.md: run facts, the accuracy/cost table, per-class accuracy, paired
    comparisons over runs (with per-class and per-user gains), the variance
    decomposition, published reference points, failed cells, figures with captions."""
    labels = run_labels(rows, summaries)
    done = ok_rows(rows)
    failed = failed_cells_markdown(rows)
    first = done[0] if done else (rows[0] if rows else {})
    n_failed = len(rows) - len(done)
    lines = [
        "# tactbench report", "",
        f"- dataset: `{first.get('dataset', '?')}` (content hash "
        f"`{str(first.get('dataset_hash', '?'))[:16]}`)",
        f"- split: `{first.get('split', '?')}`; test window: "
        f"`{first.get('test_window', UNNAMED_TEST_WINDOW)}` (the L frames each test sequence is "
        f"classified on); profile: `{first.get('profile', '?')}`; "
        f"device: `{first.get('device', '?')}`",
        f"- cells: {len(rows)}" + (f" ({n_failed} failed, listed below)" if n_failed else "")
        + f"; command: `{meta.get('command', '')}`",
        f"- git: `{meta.get('git')}`; versions: "
        + ", ".join(f"{k} {v}" for k, v in first.get("versions", {}).items()),
        f"- machine: {describe_machines(rows)} (see docs/reliability.md, 'Numbers "
        f"across machines')",
        "",
        "Accuracy is mean ± standard deviation over seeds, with a 95 % t-interval of the "
        "mean over seeds (test set: "
        f"{first.get('n_test', '?')} sequences per seed). Encode cost is per frame on one "
        "core; train seconds are wall time; inference is per test sequence, batched. "
        "Peak MB is the peak resident memory of the process that ran the cell; peak step "
        "is the step that set it (load encoding, windows, fit, predict, save model, or "
        "\"before this cell\": earlier work in the same process, such as a serial run's "
        "encoding).",
        "", markdown_table(summaries, labels), "",
        "## Per-class accuracy (%, mean over seeds)", "", per_class_markdown(summaries, labels),
        "",
    ]
    lines += comparisons_section(comps, labels)
    by_user = per_user_accuracy_markdown(summaries, labels)
    if by_user:
        lines += ["## Per-user accuracy (%, mean over the runs testing the user)", "",
                  by_user, ""]
    if variance:
        lines += ["## Where the variance comes from", "",
                  "Runs vary the split and the initialisation separately; each cell's "
                  "accuracy variance split into split, initialisation and test sampling "
                  "(p(1 − p)/n_test), as standard deviations in points.", "",
                  variance_markdown(variance, labels), ""]
    if reference:
        lines += ["## Published reference points", "",
                  "The study's published accuracies (as given to the report), each beside "
                  "our cells of the same encoder (or `encoder / classifier`) and L.", "",
                  reference_markdown(reference, summaries, labels), ""]
    if failed:
        lines += ["## Failed cells", "",
                  f"{n_failed} cell(s) raised; their rows (with the traceback's last frames) "
                  "are in `cells/`, and the next run of the same command retries them.", "",
                  failed, ""]
    if figures:
        lines += ["## Figures", ""]
    for name, path in figures.items():
        lines += [f"![{name}]({path.name})", "",
                  f"*{caption(name, summaries, reference, labels)}*", ""]
    return "\n".join(lines)

