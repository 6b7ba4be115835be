"""Reports from result rows: summary over seeds, tables, CSV/JSON/Markdown, plots.

Every accuracy is reported beside what it cost (encode ms per frame, train seconds,
inference ms per sequence, peak memory): users choose on both.

Rows of failed cells (``status: "failed"``, see :mod:`tactbench.runner.store`) are left
out of every accuracy table and plot, and listed on their own with their error.

Cells that share a dataset and split are compared *paired* (:func:`comparisons`): every
pair of summaries that differs in one factor (encoder, classifier or L) gets the mean
difference of accuracy with a bootstrap interval over test sequences, the seeds agreeing
on its sign and McNemar's exact p-value, from the per-sequence predictions each row keeps
(``row["test_predictions"]``); see :mod:`tactbench.runner.stats` and
``docs/statistics.md``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import statistics
from pathlib import Path
from typing import Any, Iterable, Sequence

from tactbench.errors import InputError
from tactbench.paths import atomic_write_text
from tactbench.runner.store import failed_rows, ok_rows, row_status
from tactbench.runner.system import describe_machines

GROUP_KEYS = ("dataset", "split", "encoder", "classifier", "L")
#: The factors a paired comparison may differ in (the rest of GROUP_KEYS is shared).
FACTORS = ("encoder", "classifier", "L")
CONFIDENCE = 0.95


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    if not vals:
        return float("nan"), float("nan")
    if len(vals) == 1:
        return vals[0], 0.0
    return statistics.fmean(vals), statistics.stdev(vals)


def short_name(spec: str) -> str:
    """``small-cnn-lstm:epochs=4,...`` → ``small-cnn-lstm``; a component's ``estimator``
    stays in the name (``sklearn:C=10,estimator=SVC`` → ``sklearn:SVC``), as it says what
    the component is."""
    name, _, rest = spec.partition(":")
    for item in rest.split(","):
        key, _, value = item.partition("=")
        if key.strip() == "estimator" and value.strip():
            return f"{name}:{value.strip()}"
    return name


def summarise(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """One summary per (dataset, split, encoder, classifier, L), over seeds.

    Accuracy and costs as mean and sample standard deviation; per-class accuracy as
    means; the confusion matrix row-normalised per seed, then averaged. Failed cells
    are left out (:func:`failed_cells_markdown` lists them).
    """
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in ok_rows(rows):
        groups.setdefault(tuple(row[k] for k in GROUP_KEYS), []).append(row)
    out = []
    for key, members in groups.items():
        members.sort(key=lambda r: r["seed"])
        classes = members[0]["classes"]
        acc_mean, acc_std = _mean_std([r["accuracy"] for r in members])
        per_class = {c: _mean_std([r["per_class_accuracy"].get(c) for r in members])[0]
                     for c in classes}
        k = len(classes)
        confusion = [[0.0] * k for _ in range(k)]
        for r in members:
            for i, line in enumerate(r["confusion"]):
                total = sum(line) or 1
                for j, v in enumerate(line):
                    confusion[i][j] += v / total / len(members)
        summary = dict(zip(GROUP_KEYS, key))
        interval = _seed_interval([r["accuracy"] for r in members])
        summary.update({
            "seeds": [r["seed"] for r in members],
            "accuracy_mean": acc_mean, "accuracy_std": acc_std,
            "accuracy_ci95": interval,
            "per_class_accuracy": per_class,
            "confusion_normalised": confusion,
            "classes": classes,
        })
        for cost in ("encode_ms_per_frame", "train_s", "inference_ms_per_sequence",
                     "peak_rss_mb"):
            summary[cost + "_mean"], summary[cost + "_std"] = _mean_std(
                [r.get(cost) for r in members])
        summary["peak_step"] = peak_step(members)
        out.append(summary)
    out.sort(key=lambda s: (s["dataset"], s["split"], s["L"], short_name(s["classifier"]),
                            s["encoder"]))
    return out


def _seed_interval(accuracies: Sequence[float]) -> list[float] | None:
    """95 % t-interval of the mean accuracy over seeds (None for one seed)."""
    from tactbench.runner.stats import seed_summary

    vals = [float(a) for a in accuracies if a is not None and not math.isnan(a)]
    if len(vals) < 2:
        return None
    res = seed_summary(vals, confidence=CONFIDENCE)
    # an accuracy lies in [0, 1]; the t-interval of a mean near either end can pass it
    return None if res.low is None else [max(0.0, res.low), min(1.0, res.high)]


def comparisons(rows: Iterable[dict[str, Any]], *, n_resamples: int | None = None
                ) -> list[dict[str, Any]]:
    """Paired comparisons of every two summaries that differ in one of :data:`FACTORS`.

    Only seeds both cells finished, and test sequences both predicted, are compared
    (rows without ``test_predictions``, written before they were kept, are left out).
    Each entry: ``factor``, ``a``/``b`` (the two cells' factor values), the shared
    ``dataset``, ``split`` and other factors, and the fields of
    :class:`tactbench.runner.stats.PairedDifference` (``difference`` = accuracy of B − A).
    A is the cell that comes first in the run (the scene's order), so a run listing
    ``raw`` before ``farneback`` reports farneback − raw.
    """
    import numpy as np

    from tactbench.runner.stats import N_RESAMPLES, paired_difference, pairs_differing_in_one_factor

    groups: dict[tuple, dict[int, dict[str, Any]]] = {}
    for row in ok_rows(rows):
        if not row.get("test_predictions"):
            continue
        groups.setdefault(tuple(row[k] for k in GROUP_KEYS), {})[int(row["seed"])] = row
    blocks: dict[tuple, list[tuple]] = {}
    for key in groups:  # first-appearance order within each (dataset, split)
        blocks.setdefault(key[:2], []).append(key)
    out = []
    for (dataset, split), keys in blocks.items():
        cells = [dict(zip(FACTORS, key[2:])) for key in keys]
        for pair in pairs_differing_in_one_factor(cells):
            ga, gb = groups[keys[pair.a]], groups[keys[pair.b]]
            y, pa, pb, seeds, seqs = [], [], [], [], []
            for seed in sorted(set(ga) & set(gb)):
                ta, tb = _predictions(ga[seed]), _predictions(gb[seed])
                for index in sorted(set(ta) & set(tb)):
                    if ta[index][0] != tb[index][0]:  # same sequence, other label: not paired
                        continue
                    y.append(ta[index][0])
                    pa.append(ta[index][1])
                    pb.append(tb[index][1])
                    seeds.append(seed)
                    seqs.append(index)
            if not y:
                continue
            res = paired_difference(np.asarray(y), np.asarray(pa), np.asarray(pb),
                                    np.asarray(seeds), sequence_ids=np.asarray(seqs),
                                    confidence=CONFIDENCE,
                                    n_resamples=n_resamples or N_RESAMPLES, seed=0)
            shared = {k: v for k, v in cells[pair.a].items() if k != pair.factor}
            out.append({"dataset": dataset, "split": split, "factor": pair.factor,
                        "a": pair.value_a, "b": pair.value_b, **shared, **res.as_dict()})
    return out


def _predictions(row: dict[str, Any]) -> dict[int, tuple[int, int]]:
    """Test sequence index → (true label, predicted label) of one row."""
    tp = row["test_predictions"]
    return {int(i): (int(t), int(p))
            for i, t, p in zip(tp["indices"], tp["labels"], tp["predictions"])}


def _comparison_label(c: dict[str, Any], side: str) -> str:
    value = c[side]
    if c["factor"] == "classifier":
        return short_name(str(value))
    if c["factor"] == "L":
        return f"L={value}"
    return str(value)


def _context(c: dict[str, Any]) -> str:
    parts = []
    for k in FACTORS:
        if k == c["factor"] or k not in c:
            continue
        parts.append(f"L={c[k]}" if k == "L" else short_name(str(c[k])))
    return " ".join(parts)


def comparison_rows(comps: Sequence[dict[str, Any]]) -> list[list[str]]:
    """Table cells: factor, A, B, where (the shared factors), B − A (points), interval,
    seeds B>A/A>B/tied, McNemar p, verdict."""
    rows = []
    for c in comps:
        verdict = c["verdict"]
        if verdict == "B better":
            verdict = f"{_comparison_label(c, 'b')} better"
        elif verdict == "A better":
            verdict = f"{_comparison_label(c, 'a')} better"
        rows.append([
            c["factor"], _comparison_label(c, "a"), _comparison_label(c, "b"), _context(c),
            f"{100 * c['difference']:+.1f}",
            f"[{100 * c['low']:+.1f}, {100 * c['high']:+.1f}]",
            f"{c['b_better_seeds']}/{c['a_better_seeds']}/{c['tied_seeds']}",
            _p_value(c["mcnemar_p"]), verdict])
    return rows


COMPARISON_HEADER = ["factor", "A", "B", "where", "B − A (points)", "95 % interval",
                     "seeds B>A / A>B / tied", "McNemar p", "verdict"]


def _p_value(p: float) -> str:
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


def comparisons_markdown(comps: Sequence[dict[str, Any]]) -> str:
    if not comps:
        return ""
    lines = ["| " + " | ".join(COMPARISON_HEADER) + " |",
             "|" + "---|" * len(COMPARISON_HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in comparison_rows(comps)]
    return "\n".join(lines)


def print_comparisons(comps: Sequence[dict[str, Any]], *,
                      factors: Sequence[str] = ("encoder", "classifier")) -> None:
    """The terminal's table of paired comparisons (by default of encoders and classifiers;
    report.md and results.json hold every factor)."""
    shown = [c for c in comps if c["factor"] in factors]
    if not shown:
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="paired comparisons (B − A; an interval spanning 0 is unresolved)",
                  title_justify="left")
    for col in COMPARISON_HEADER:
        table.add_column(col, justify="left" if col in ("factor", "A", "B", "where",
                                                        "verdict") else "right")
    for row in comparison_rows(shown):
        table.add_row(*row)
    console = Console()
    if not console.is_terminal:
        console = Console(width=160)
    console.print(table)


def peak_step(rows: Sequence[dict[str, Any]]) -> str:
    """The step that set the peak memory of most of ``rows`` (the first seed's on a tie);
    "-" for rows that do not say (written before steps were recorded)."""
    steps = [r.get("peak_step") for r in rows if r.get("peak_step")]
    if not steps:
        return "-"
    return max(dict.fromkeys(steps), key=steps.count)


def _interval(ci: Sequence[float] | None) -> str:
    if not ci:
        return "-"
    return f"{100 * ci[0]:.1f}–{100 * ci[1]:.1f}"


def _pct(mean: float, std: float) -> str:
    if math.isnan(mean):
        return "-"
    return f"{100 * mean:.1f} ± {100 * std:.1f}"


def table_rows(summaries: Sequence[dict[str, Any]]) -> list[list[str]]:
    rows = []
    for s in summaries:
        rows.append([
            s["encoder"], short_name(s["classifier"]), str(s["L"]),
            _pct(s["accuracy_mean"], s["accuracy_std"]), _interval(s.get("accuracy_ci95")),
            str(len(s["seeds"])),
            f"{s['encode_ms_per_frame_mean']:.3f}",
            f"{s['train_s_mean']:.1f}",
            f"{s['inference_ms_per_sequence_mean']:.2f}",
            f"{s['peak_rss_mb_mean']:.0f}",
            s.get("peak_step", "-"),
        ])
    return rows


TABLE_HEADER = ["encoder", "classifier", "L", "accuracy %", "95 % CI of mean", "seeds",
                "encode ms/frame",
                "train s", "infer ms/seq", "peak MB", "peak step"]


def print_table(summaries: Sequence[dict[str, Any]], *, title: str = "") -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title or None, title_justify="left")
    for col in TABLE_HEADER:
        table.add_column(col, justify="right" if col not in ("encoder", "classifier",
                                                              "peak step") else "left")
    for row in table_rows(summaries):
        table.add_row(*row)
    console = Console()
    if not console.is_terminal:  # logs and pipes: no wrapping at 80 columns
        console = Console(width=160)
    console.print(table)


def markdown_table(summaries: Sequence[dict[str, Any]]) -> str:
    lines = ["| " + " | ".join(TABLE_HEADER) + " |",
             "|" + "---|" * len(TABLE_HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(summaries)]
    return "\n".join(lines)


def per_class_markdown(summaries: Sequence[dict[str, Any]]) -> str:
    if not summaries:
        return ""
    classes = summaries[0]["classes"]
    lines = ["| encoder | classifier | L | " + " | ".join(classes) + " |",
             "|" + "---|" * (3 + len(classes))]
    for s in summaries:
        cells = [f"{100 * s['per_class_accuracy'][c]:.1f}"
                 if s["per_class_accuracy"][c] is not None
                 and not math.isnan(s["per_class_accuracy"][c]) else "-" for c in classes]
        lines.append(f"| {s['encoder']} | {short_name(s['classifier'])} | {s['L']} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def failed_cells(rows: Iterable[dict[str, Any]]) -> list[dict[str, str]]:
    """One line per failed cell: ``encoder``, ``classifier`` (short), ``L``, ``seed``,
    ``error`` (``Type: message``, first line) and ``key``."""
    out = []
    for r in failed_rows(rows):
        error = r.get("error", {})
        message = str(error.get("message", "")).strip().splitlines()
        out.append({"encoder": r["encoder"], "classifier": short_name(r["classifier"]),
                    "L": str(r["L"]), "seed": str(r["seed"]), "key": r["key"],
                    "error": f"{error.get('type', 'Error')}: {message[0] if message else ''}"})
    return out


def failed_cells_markdown(rows: Iterable[dict[str, Any]]) -> str:
    """A Markdown table of the failed cells ("" when none failed)."""
    failed = failed_cells(rows)
    if not failed:
        return ""
    lines = ["| encoder | classifier | L | seed | error | row |", "|---|---|---|---|---|---|"]
    for f in failed:
        error = f["error"].replace("|", "\\|")
        lines.append(f"| {f['encoder']} | {f['classifier']} | {f['L']} | {f['seed']} | "
                     f"{error} | `cells/{f['key']}.json` |")
    return "\n".join(lines)


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
        lines += [f"![{name}]({path.name})", "", f"*{_caption(name, summaries, reference)}*",
                  ""]
    return "\n".join(lines)


def reference_markdown(reference: Sequence[dict[str, Any]],
                       summaries: Sequence[dict[str, Any]]) -> str:
    """A table: each published point, and our cells it compares with ("-" where none)."""
    lines = ["| published | L | published % | ours (cell) | ours % | 95 % CI of mean |",
             "|---|---|---|---|---|---|"]
    for p in reference:
        published = f"{100 * p['accuracy']:.1f}" + (
            f" ± {100 * p['err']:.1f}" if p["err"] is not None else "")
        ours = [s for s in summaries if s["L"] == p["L"] and p["label"] in (
            s["encoder"], f"{s['encoder']} / {short_name(s['classifier'])}")]
        if not ours:
            lines.append(f"| {p['label']} | {p['L']} | {published} | - | - | - |")
        for s in ours:
            lines.append(
                f"| {p['label']} | {p['L']} | {published} | {s['encoder']} / "
                f"{short_name(s['classifier'])} | {_pct(s['accuracy_mean'], s['accuracy_std'])}"
                f" | {_interval(s.get('accuracy_ci95'))} |")
    return "\n".join(lines)


def _caption(name: str, summaries: Sequence[dict[str, Any]],
             reference: Sequence[dict[str, Any]]) -> str:
    curves = _curve_keys(summaries)
    several = len({k[:2] for k in curves}) > 1
    if name == "accuracy_vs_L":
        notes = {_curve_label(k, several): band_note(pts) for k, pts in curves.items()}
        bands = ("every line: " + next(iter(notes.values())) if len(set(notes.values())) == 1
                 else "; ".join(f"{label}: {note}" for label, note in notes.items()))
        text = ("Accuracy against window length L, mean over seeds; the shaded band is the "
                "95 % t-interval of the mean over seeds (± std where no interval could be "
                f"computed, none with one seed). Bands: {bands}.")
        if reference:
            text += (" Open markers on dotted lines: the study's published points "
                     "(\"study (published)\"), with their error bars where given.")
        return text
    if name == "cost_vs_accuracy":
        drawn = [s for s in summaries if not math.isnan(s["encode_ms_per_frame_mean"])]
        costs = [s["encode_ms_per_frame_mean"] for s in drawn]
        front = pareto_front(list(zip(costs, [s["accuracy_mean"] for s in drawn])))
        members = ", ".join(
            f"{drawn[i]['encoder']} / {short_name(drawn[i]['classifier'])} L={drawn[i]['L']} "
            f"({costs[i]:.3g} ms, {100 * drawn[i]['accuracy_mean']:.1f} %)" for i in front)
        return ("Accuracy against encode cost (ms per frame on one core, log scale; a cost "
                f"below {MIN_PLOTTED_COST_MS:g} ms is drawn at {MIN_PLOTTED_COST_MS:g}), "
                f"error bars: {_band_only(drawn)}. Dashed step line and "
                "rings: the Pareto front, the cells no other cell beats on both accuracy and "
                f"cost: {members}.")
    if name == "per_class_vs_L":
        return ("Per-class accuracy against window length L, one panel per class, a line "
                "per encoder × classifier; means over seeds, no bands.")
    cell = next((f"{s['encoder']} / {short_name(s['classifier'])}, L={s['L']}"
                 for s in summaries if name == "confusion_" + _slug(s["encoder"]) + "_"
                 + _slug(short_name(s["classifier"])) + f"_L{s['L']}"), name)
    return (f"Confusion matrix of {cell}: each true class's row normalised per seed, then "
            "averaged over seeds.")


#: Top-level figures :func:`write_plots` may write besides ``confusion_*.png``
#: (``tactbench.runner.planning.OUT_FILES`` lists them for the out-folder check).
PLOT_FILES = ("accuracy_vs_L.png", "cost_vs_accuracy.png", "per_class_vs_L.png")
#: The lowest encode cost drawn on the log axis (a cost of 0 ms is drawn there).
MIN_PLOTTED_COST_MS = 1e-4
_BAND_CI = "95 % CI of the mean over seeds"
_BAND_STD = "± std over seeds"


def accuracy_band(summary: dict[str, Any]) -> tuple[float, float, str] | None:
    """``(low, high, kind)`` of the band drawn around a summary's mean accuracy.

    The 95 % t-interval of the mean over seeds (``accuracy_ci95``) where there is one;
    else mean ± std where the std is a positive number over ≥ 2 seeds; else None (one
    seed: no band).
    """
    ci = summary.get("accuracy_ci95")
    if ci and all(isinstance(v, (int, float)) and math.isfinite(v) for v in ci):
        return float(ci[0]), float(ci[1]), _BAND_CI
    mean, std = summary.get("accuracy_mean"), summary.get("accuracy_std")
    if (len(summary.get("seeds", ())) > 1 and isinstance(std, (int, float))
            and math.isfinite(std) and std > 0 and math.isfinite(mean)):
        return mean - std, mean + std, _BAND_STD
    return None


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the ``(cost, accuracy)`` points no other point beats on both.

    A point is beaten when another costs no more *and* scores no less, and is better in
    one of the two (lower cost, higher accuracy). Equal points are all on the front;
    points with a NaN are never on it. Ordered by cost, then index.
    """
    finite = [i for i, (c, a) in enumerate(points)
              if not (math.isnan(float(c)) or math.isnan(float(a)))]
    front = []
    for i in finite:
        ci, ai = points[i]
        beaten = any(points[j][0] <= ci and points[j][1] >= ai
                     and (points[j][0] < ci or points[j][1] > ai) for j in finite)
        if not beaten:
            front.append(i)
    return sorted(front, key=lambda i: (points[i][0], i))


def check_reference(reference: Iterable[dict[str, Any]] | None) -> list[dict[str, Any]]:
    """Validated published points to draw beside ours: each ``{"label": str, "L": int ≥ 1,
    "accuracy": fraction in [0, 1], "err": fraction ≥ 0 or None}`` (accuracy and err as
    fractions, like every accuracy tactbench reports)."""
    out = []
    for i, point in enumerate(reference or ()):
        where = f"reference point {i + 1}"
        if not isinstance(point, dict):
            raise InputError(f"{where} must be a mapping with label, L and accuracy, "
                             f"got {type(point).__name__}")
        missing = [k for k in ("label", "L", "accuracy") if k not in point]
        if missing:
            raise InputError(f"{where} lacks {', '.join(missing)} "
                             "(each needs label, L, accuracy and optionally err)")
        unknown = sorted(set(point) - {"label", "L", "accuracy", "err"})
        if unknown:
            raise InputError(f"{where} has unknown field(s) {', '.join(map(str, unknown))} "
                             "(known: label, L, accuracy, err)")
        label, length, acc, err = (point["label"], point["L"], point["accuracy"],
                                   point.get("err"))
        if not isinstance(label, str) or not label.strip():
            raise InputError(f"{where}: label must be a non-empty text, got {label!r}")
        if isinstance(length, bool) or not isinstance(length, int) or length < 1:
            raise InputError(f"{where} ({label}): L must be a whole number ≥ 1, "
                             f"got {length!r}")
        if (isinstance(acc, bool) or not isinstance(acc, (int, float))
                or not 0 <= acc <= 1):
            hint = f" (write {acc / 100:g} for {acc:g} %)" if (
                isinstance(acc, (int, float)) and not isinstance(acc, bool)
                and 1 < acc <= 100) else ""
            raise InputError(f"{where} ({label}): accuracy must be a fraction in [0, 1], "
                             f"got {acc!r}{hint}")
        if err is not None and (isinstance(err, bool) or not isinstance(err, (int, float))
                                or not 0 <= err <= 1):
            raise InputError(f"{where} ({label}): err must be a fraction in [0, 1], "
                             f"got {err!r}")
        out.append({"label": label, "L": length, "accuracy": float(acc),
                    "err": None if err is None else float(err)})
    return out


def _curve_keys(summaries: Sequence[dict[str, Any]]) -> dict[tuple, list[dict[str, Any]]]:
    """(dataset, split, encoder, classifier) → that curve's summaries, sorted by L."""
    curves: dict[tuple, list[dict[str, Any]]] = {}
    for s in summaries:
        key = (s["dataset"], s["split"], s["encoder"], short_name(s["classifier"]))
        curves.setdefault(key, []).append(s)
    for pts in curves.values():
        pts.sort(key=lambda s: s["L"])
    return dict(sorted(curves.items()))


def _curve_label(key: tuple, several_blocks: bool) -> str:
    dataset, split, enc, clf = key
    return f"{enc} / {clf}" + (f" [{dataset}, {split}]" if several_blocks else "")


def _seeds_text(points: Sequence[dict[str, Any]]) -> str:
    counts = sorted({len(s["seeds"]) for s in points})
    n = str(counts[0]) if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
    return f"{n} seed" + ("" if counts == [1] else "s")


def band_note(points: Sequence[dict[str, Any]]) -> str:
    """What the band around a curve (or point) is: ``3 seeds, band: 95 % CI of the mean
    over seeds``, ``1 seed, no band``, ..."""
    kinds = []
    for s in points:
        band = accuracy_band(s)
        kind = band[2] if band else "no band"
        if kind not in kinds:
            kinds.append(kind)
    if kinds == ["no band"]:
        return f"{_seeds_text(points)}, no band"
    bands = [k for k in kinds if k != "no band"]
    text = f"{_seeds_text(points)}, band: " + " / ".join(bands)
    return text + (", none where one seed" if "no band" in kinds else "")


def _band_only(points: Sequence[dict[str, Any]]) -> str:
    """:func:`band_note` without the number of seeds: ``95 % CI of the mean over seeds``,
    ``no band``, ..."""
    return band_note(points).split(", ", 1)[1].removeprefix("band: ")


def l_curves_apply(summaries: Sequence[dict[str, Any]]) -> bool:
    """Whether the L figures apply: some encoder × classifier has ≥ 2 values of L."""
    return any(len({s["L"] for s in pts}) >= 2 for pts in _curve_keys(summaries).values())


def write_plots(out: Path, summaries: Sequence[dict[str, Any]], *,
                reference: Iterable[dict[str, Any]] | None = None) -> dict[str, Path]:
    """The figures of a run, as PNG (matplotlib, Agg) in ``out``; returns name → path.

    - ``accuracy_vs_L``: accuracy against L, a line per encoder × classifier with a shaded
      band (:func:`accuracy_band`), and ``reference`` (:func:`check_reference`), the
      published points, as open markers "study (published)"; only when some line has ≥ 2
      values of L.
    - ``cost_vs_accuracy``: accuracy against encode cost (log x), error bars from the
      band, the :func:`pareto_front` as a step line with its members ringed.
    - ``per_class_vs_L``: one panel per class, a line per encoder × classifier (means
      over seeds); only when some line has ≥ 2 values of L.
    - ``confusion_<encoder>_<classifier>_L<L>``: each summary's normalised confusion.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    reference = check_reference(reference)
    figures: dict[str, Path] = {}
    summaries = [s for s in summaries if not math.isnan(s["accuracy_mean"])]
    if not summaries:
        return figures
    curves = _curve_keys(summaries)
    several = len({k[:2] for k in curves}) > 1
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {key: colours[i % len(colours)] for i, key in enumerate(curves)}

    def save(fig, name: str, dpi: int = 120) -> None:
        fig.set_label(name)
        fig.tight_layout()
        figures[name] = out / f"{name}.png"
        fig.savefig(figures[name], dpi=dpi)
        plt.close(fig)

    if l_curves_apply(summaries):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for key, pts in curves.items():
            xs = [s["L"] for s in pts]
            ys = [100 * s["accuracy_mean"] for s in pts]
            ax.plot(xs, ys, marker="o", color=colour[key],
                    label=f"{_curve_label(key, several)} ({band_note(pts)})")
            bands = [accuracy_band(s) for s in pts]
            if any(bands):  # NaN where a point has no band: the shading stops there
                ax.fill_between(xs, [100 * b[0] if b else math.nan for b in bands],
                                [100 * b[1] if b else math.nan for b in bands],
                                color=colour[key], alpha=0.2, linewidth=0)
        markers = "DsPX^v*"
        encoders = {}
        for key in curves:
            encoders.setdefault(key[2], []).append(key)
        for i, label in enumerate(dict.fromkeys(p["label"] for p in reference)):
            pts = sorted((p for p in reference if p["label"] == label), key=lambda p: p["L"])
            same = encoders.get(label, [])
            ax.errorbar([p["L"] for p in pts], [100 * p["accuracy"] for p in pts],
                        yerr=[100 * (p["err"] or 0) for p in pts]
                        if any(p["err"] for p in pts) else None,
                        marker=markers[i % len(markers)], markersize=8, linestyle=":",
                        markerfacecolor="white", capsize=3,
                        color=colour[same[0]] if len(same) == 1 else "black",
                        label=f"study (published): {label}")
        ax.set_xlabel("window length L (frames)")
        ax.set_ylabel("test accuracy (%)")
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        save(fig, "accuracy_vs_L")

    drawn = [s for s in summaries if not math.isnan(s["encode_ms_per_frame_mean"])]
    if drawn:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        costs = [max(s["encode_ms_per_frame_mean"], MIN_PLOTTED_COST_MS) for s in drawn]
        accs = [100 * s["accuracy_mean"] for s in drawn]
        for s, x, y in zip(drawn, costs, accs):
            band = accuracy_band(s)
            yerr = [[y - 100 * band[0]], [100 * band[1] - y]] if band else None
            key = (s["dataset"], s["split"], s["encoder"], short_name(s["classifier"]))
            ax.errorbar([x], [y], yerr=yerr, marker="o", capsize=3, color=colour[key])
            ax.annotate(f"{s['encoder']} / {short_name(s['classifier'])} L={s['L']}",
                        (x, y), fontsize=7, xytext=(4, 4), textcoords="offset points")
        front = pareto_front([(s["encode_ms_per_frame_mean"], s["accuracy_mean"])
                              for s in drawn])
        ax.step([costs[i] for i in front], [accs[i] for i in front], where="post",
                color="crimson", linestyle="--", linewidth=1,
                label="Pareto front (not beaten on both accuracy and cost)")
        ax.scatter([costs[i] for i in front], [accs[i] for i in front], s=160,
                   facecolors="none", edgecolors="crimson", linewidths=1.5, zorder=3)
        ax.set_xscale("log")
        ax.margins(x=0.35)  # room for the labels right of the points
        ax.set_xlabel("encode cost (ms per frame, one core, log scale)")
        ax.set_ylabel("test accuracy (%)")
        ax.set_title(f"error bars: {_band_only(drawn)}", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
        save(fig, "cost_vs_accuracy")

    if l_curves_apply(summaries):
        classes = list(dict.fromkeys(c for s in summaries for c in s["classes"]))
        ncols = min(3, len(classes))
        nrows = math.ceil(len(classes) / ncols)
        fig, axes = plt.subplots(nrows, ncols, figsize=(3.2 * ncols, 2.6 * nrows + 0.6),
                                 sharex=True, sharey=True, squeeze=False)
        for ax, cls in zip(axes.flat, classes):
            for key, pts in curves.items():
                pts = [s for s in pts if _finite(s["per_class_accuracy"].get(cls))]
                if pts:
                    ax.plot([s["L"] for s in pts],
                            [100 * s["per_class_accuracy"][cls] for s in pts], marker="o",
                            markersize=4, color=colour[key], label=_curve_label(key, several))
            ax.set_title(cls, fontsize=9)
            ax.grid(alpha=0.3)
            ax.xaxis.get_major_locator().set_params(integer=True)
        for ax in list(axes.flat)[len(classes):]:
            ax.set_visible(False)
        for ax in axes[-1]:
            ax.set_xlabel("L (frames)", fontsize=8)
        for ax in axes[:, 0]:
            ax.set_ylabel("class accuracy (%)", fontsize=8)
        handles, labels = axes.flat[0].get_legend_handles_labels()
        fig.legend(handles, labels, fontsize=7, loc="lower center",
                   ncol=min(4, max(1, len(labels))))
        fig.suptitle("per-class accuracy against L (mean over seeds)", fontsize=9)
        fig.set_label("per_class_vs_L")
        fig.tight_layout(rect=(0, 0.08 + 0.02 * math.ceil(len(labels) / 4), 1, 1))
        figures["per_class_vs_L"] = out / "per_class_vs_L.png"
        fig.savefig(figures["per_class_vs_L"], dpi=110)
        plt.close(fig)

    # normalised confusion matrices averaged over seeds
    for s in summaries:
        classes = s["classes"]
        matrix = s["confusion_normalised"]
        fig, ax = plt.subplots(figsize=(1.0 + 0.8 * len(classes), 0.8 + 0.8 * len(classes)))
        ax.imshow(matrix, vmin=0, vmax=1, cmap="Blues")
        for i, line in enumerate(matrix):
            for j, v in enumerate(line):
                ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=8,
                        color="white" if v > 0.5 else "black")
        ax.set_xticks(range(len(classes)), classes, rotation=45, ha="right", fontsize=8)
        ax.set_yticks(range(len(classes)), classes, fontsize=8)
        ax.set_xlabel("predicted")
        ax.set_ylabel("true")
        ax.set_title(f"{s['encoder']} / {short_name(s['classifier'])}, L={s['L']}", fontsize=9)
        name = f"confusion_{_slug(s['encoder'])}_{_slug(short_name(s['classifier']))}_L{s['L']}"
        save(fig, name, dpi=110)
    return figures


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)


def _slug(text: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in text).strip("-")
