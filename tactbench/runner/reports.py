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

from tactbench.paths import atomic_write_text
from tactbench.runner.store import failed_rows, ok_rows, row_status

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
    """``small-cnn-lstm:epochs=4,...`` → ``small-cnn-lstm``."""
    return spec.split(":", 1)[0]


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
    return None if res.low is None else [res.low, res.high]


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
                  meta: dict[str, Any] | None = None, plots: bool = True) -> dict[str, Path]:
    """Write results.json, results.csv, report.md and the plots into ``out``.

    ``rows``: every row of the run, ok and failed (failed cells are listed in report.md,
    kept in the JSON and CSV, and left out of summaries and plots).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summaries = summarise(rows)
    comps = comparisons(rows)
    paths = {"json": out / "results.json", "csv": out / "results.csv",
             "markdown": out / "report.md"}
    atomic_write_text(paths["json"], json.dumps(
        {"meta": meta or {}, "summary": summaries, "comparisons": comps,
         "rows": list(rows)}, indent=2))
    atomic_write_text(paths["csv"], rows_csv(rows))
    figures: dict[str, Path] = {}
    if plots and summaries:
        figures = write_plots(out, summaries)
        paths.update(figures)
    atomic_write_text(paths["markdown"], markdown_report(summaries, rows, meta or {},
                                                         figures, comps))
    return paths


def markdown_report(summaries, rows, meta, figures, comps=()) -> str:
    """report.md: run facts, the accuracy/cost table, per-class accuracy, failed cells,
    figures."""
    done = ok_rows(rows)
    failed = failed_cells_markdown(rows)
    first = done[0] if done else (rows[0] if rows else {})
    n_failed = len(rows) - len(done)
    lines = [
        "# tactbench report", "",
        f"- dataset: `{first.get('dataset', '?')}` (content hash "
        f"`{str(first.get('dataset_hash', '?'))[:16]}`)",
        f"- split: `{first.get('split', '?')}`; profile: `{first.get('profile', '?')}`; "
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
    if failed:
        lines += ["## Failed cells", "",
                  f"{n_failed} cell(s) raised; their rows (with the traceback's last frames) "
                  "are in `cells/`, and the next run of the same command retries them.", "",
                  failed, ""]
    for name, path in figures.items():
        lines += [f"![{name}]({path.name})", ""]
    return "\n".join(lines)


def write_plots(out: Path, summaries: Sequence[dict[str, Any]]) -> dict[str, Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures: dict[str, Path] = {}
    # accuracy against L, one line per encoder × classifier
    fig, ax = plt.subplots(figsize=(6, 4))
    lines: dict[tuple[str, str], list[dict]] = {}
    for s in summaries:
        lines.setdefault((s["encoder"], short_name(s["classifier"])), []).append(s)
    for (enc, clf), pts in sorted(lines.items()):
        pts.sort(key=lambda s: s["L"])
        ax.errorbar([s["L"] for s in pts], [100 * s["accuracy_mean"] for s in pts],
                    yerr=[100 * s["accuracy_std"] for s in pts], marker="o", capsize=3,
                    label=f"{enc} / {clf}")
    ax.set_xlabel("window length L (frames)")
    ax.set_ylabel("test accuracy (%)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    figures["accuracy_vs_L"] = out / "accuracy_vs_L.png"
    fig.savefig(figures["accuracy_vs_L"], dpi=120)
    plt.close(fig)

    # cost against accuracy
    fig, ax = plt.subplots(figsize=(6, 4))
    for s in summaries:
        cost = s["encode_ms_per_frame_mean"]
        ax.errorbar([max(cost, 1e-4)], [100 * s["accuracy_mean"]],
                    yerr=[100 * s["accuracy_std"]], marker="o", capsize=3)
        ax.annotate(f"{s['encoder']} / {short_name(s['classifier'])} L={s['L']}",
                    (max(cost, 1e-4), 100 * s["accuracy_mean"]), fontsize=7,
                    xytext=(4, 4), textcoords="offset points")
    ax.set_xscale("log")
    ax.margins(x=0.35)  # room for the labels right of the points
    ax.set_xlabel("encode cost (ms per frame, one core, log scale)")
    ax.set_ylabel("test accuracy (%)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    figures["cost_vs_accuracy"] = out / "cost_vs_accuracy.png"
    fig.savefig(figures["cost_vs_accuracy"], dpi=120)
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
        fig.tight_layout()
        name = f"confusion_{_slug(s['encoder'])}_{_slug(short_name(s['classifier']))}_L{s['L']}"
        figures[name] = out / f"{name}.png"
        fig.savefig(figures[name], dpi=110)
        plt.close(fig)
    return figures


def _slug(text: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in text).strip("-")
