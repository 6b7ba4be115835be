"""Tables of summaries and comparisons: for the terminal (rich) and for Markdown."""

from __future__ import annotations

import math
import re
from typing import Any, Iterable, Mapping, Sequence

from tactbench.runner.summaries import (
    FACTORS,
    failed_cells,
    short_name,
    spec_label,
    spec_labels,
)

#: Classifier spec → the name shown for it (:func:`tactbench.runner.summaries.spec_labels`).
Labels = Mapping[str, str]


_MD_SPECIAL = re.compile(r"([\\`*_\[\]<>|~])")


def md(text: Any) -> str:
    """Text a user gave (a class or user name, an error message) as literal Markdown in a
    table cell: every Markdown special character escaped with a backslash (``|`` would
    end the cell, ``*`` start emphasis), line breaks as spaces."""
    return _MD_SPECIAL.sub(r"\\\1", " ".join(str(text).split()))


def summary_labels(summaries: Iterable[dict[str, Any]]) -> dict[str, str]:
    """The labels of the classifiers of ``summaries`` (or rows, or variance entries)."""
    return spec_labels(s["classifier"] for s in summaries)


def comparison_labels(comps: Iterable[dict[str, Any]]) -> dict[str, str]:
    """The labels of the classifiers ``comps`` compare or share."""
    specs = []
    for c in comps:
        if c["factor"] == "classifier":
            specs += [c["a"], c["b"]]
        if "classifier" in c:
            specs.append(c["classifier"])
    return spec_labels(specs)


def _comparison_label(c: dict[str, Any], side: str, labels: Labels | None = None) -> str:
    value = c[side]
    if c["factor"] == "classifier":
        return spec_label(value, labels)
    if c["factor"] == "L":
        return f"L={value}"
    if c["factor"] == "contrast":  # "encoder=raw,L=6" → "raw L=6"
        parts = []
        for item in str(value).split(","):
            k, _, v = item.partition("=")
            parts.append(f"L={v}" if k == "L" else v)
        return " ".join(parts)
    return str(value)


def _context(c: dict[str, Any], labels: Labels | None = None) -> str:
    parts = []
    for k in FACTORS:
        if k == c["factor"] or k not in c:
            continue
        parts.append(f"L={c[k]}" if k == "L" else spec_label(c[k], labels) if
                     k == "classifier" else str(c[k]))
    return " ".join(parts) or "-"


COMPARISON_HEADER = ["factor", "A", "B", "where", "B − A (points)",
                     "95 % interval over runs", "runs B>A / A>B / tied",
                     "p (t / sign-flip)", "Holm p", "runs for ±2 (±margin)", "verdict"]


def verdict_text(c: dict[str, Any], labels: Labels | None = None) -> str:
    """The verdict in words: ``farneback better``, ``equivalent within ±2``, ..."""
    verdict = c["verdict"]
    if verdict == "B better":
        return f"{_comparison_label(c, 'b', labels)} better"
    if verdict == "A better":
        return f"{_comparison_label(c, 'a', labels)} better"
    if verdict == "equivalent":
        return f"equivalent within ±{c['equivalence_margin']:g}"
    return verdict


def _runs_needed(c: dict[str, Any]) -> str:
    n = c.get("runs_needed")
    return "unreachable" if n is None else str(n)


def comparison_rows(comps: Sequence[dict[str, Any]], labels: Labels | None = None
                    ) -> list[list[str]]:
    """Table cells: factor, A, B, where (the shared factors), B − A (points), the
    run-level interval, runs B>A/A>B/tied, p of the corrected t and of the sign-flip
    test, the family's Holm-adjusted p, the runs a ±2-point (or ±margin) interval needs,
    and the verdict. A classifier is named by its label in ``labels`` (by default the
    labels among the classifiers of ``comps``, :func:`comparison_labels`)."""
    labels = comparison_labels(comps) if labels is None else labels
    rows = []
    for c in comps:
        rows.append([
            c["factor"], _comparison_label(c, "a", labels), _comparison_label(c, "b", labels),
            _context(c, labels),
            f"{100 * c['difference']:+.1f}",
            f"[{100 * c['low']:+.1f}, {100 * c['high']:+.1f}]" if c["df"] else "-",
            f"{c['b_better_runs']}/{c['a_better_runs']}/{c['tied_runs']}",
            f"{_p_value(c['t_p'])} / {_p_value(c['permutation_p'])}",
            _p_value(c["p_holm"]), _runs_needed(c), verdict_text(c, labels)])
    return rows


def _p_value(p: float | None) -> str:
    if p is None:
        return "-"
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


def comparisons_markdown(comps: Sequence[dict[str, Any]], labels: Labels | None = None) -> str:
    if not comps:
        return ""
    lines = ["| " + " | ".join(COMPARISON_HEADER) + " |",
             "|" + "---|" * len(COMPARISON_HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in comparison_rows(comps, labels)]
    return "\n".join(lines)


def print_comparisons(comps: Sequence[dict[str, Any]], *,
                      factors: Sequence[str] = ("encoder", "classifier"),
                      labels: Labels | None = None) -> None:
    """The terminal's table of paired comparisons (by default of encoders and classifiers;
    report.md and results.json hold every factor)."""
    labels = comparison_labels(comps) if labels is None else labels
    shown = [c for c in comps if c["factor"] in factors]
    if not shown:
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="paired comparisons over runs (B − A; Holm-adjusted within the run; "
                        "an interval touching 0 is unresolved)",
                  title_justify="left")
    for col in COMPARISON_HEADER:
        table.add_column(col, justify="left" if col in ("factor", "A", "B", "where",
                                                        "verdict") else "right")
    # the interval beside every verdict is the run-level one (comparison_rows)
    for row in comparison_rows(shown, labels):
        table.add_row(*row)
    console = Console()
    if not console.is_terminal:
        console = Console(width=160)
    console.print(table)


def _interval(ci: Sequence[float] | None) -> str:
    if not ci:
        return "-"
    return f"{100 * ci[0]:.1f}–{100 * ci[1]:.1f}"


def _pct(mean: float, std: float) -> str:
    if math.isnan(mean):
        return "-"
    return f"{100 * mean:.1f} ± {100 * std:.1f}"


TABLE_HEADER = ["encoder", "classifier", "input", "L", "accuracy %", "95 % CI of mean", "seeds",
                "encode ms/frame",
                "train s", "infer ms/seq", "peak MB", "peak step"]


def table_rows(summaries: Sequence[dict[str, Any]], labels: Labels | None = None
               ) -> list[list[str]]:
    """The accuracy table's cells; a classifier by its label in ``labels`` (by default
    among the classifiers of ``summaries``, :func:`summary_labels`)."""
    labels = summary_labels(summaries) if labels is None else labels
    rows = []
    for s in summaries:
        rows.append([
            s["encoder"], spec_label(s["classifier"], labels), s.get("input", "-"), str(s["L"]),
            _pct(s["accuracy_mean"], s["accuracy_std"]), _interval(s.get("accuracy_ci95")),
            str(len(s["seeds"])),
            f"{s['encode_ms_per_frame_mean']:.3f}",
            f"{s['train_s_mean']:.1f}",
            f"{s['inference_ms_per_sequence_mean']:.2f}",
            f"{s['peak_rss_mb_mean']:.0f}",
            s.get("peak_step", "-"),
        ])
    return rows


def print_table(summaries: Sequence[dict[str, Any]], *, title: str = "",
                labels: Labels | None = None) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title or None, title_justify="left")
    for col in TABLE_HEADER:
        table.add_column(col, justify="right" if col not in ("encoder", "classifier",
                                                              "input", "peak step") else "left")
    for row in table_rows(summaries, labels):
        table.add_row(*row)
    console = Console()
    if not console.is_terminal:  # logs and pipes: no wrapping at 80 columns
        console = Console(width=160)
    console.print(table)


def markdown_table(summaries: Sequence[dict[str, Any]], labels: Labels | None = None) -> str:
    lines = ["| " + " | ".join(TABLE_HEADER) + " |",
             "|" + "---|" * len(TABLE_HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(summaries, labels)]
    return "\n".join(lines)


def per_class_markdown(summaries: Sequence[dict[str, Any]], labels: Labels | None = None
                       ) -> str:
    if not summaries:
        return ""
    labels = summary_labels(summaries) if labels is None else labels
    classes = summaries[0]["classes"]
    lines = ["| encoder | classifier | L | " + " | ".join(map(md, classes)) + " |",
             "|" + "---|" * (3 + len(classes))]
    for s in summaries:
        cells = [f"{100 * s['per_class_accuracy'][c]:.1f}"
                 if s["per_class_accuracy"][c] is not None
                 and not math.isnan(s["per_class_accuracy"][c]) else "-" for c in classes]
        lines.append(f"| {s['encoder']} | {spec_label(s['classifier'], labels)} | {s['L']} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def failed_cells_markdown(rows: Iterable[dict[str, Any]]) -> str:
    """A Markdown table of the failed cells ("" when none failed)."""
    failed = failed_cells(rows)
    if not failed:
        return ""
    lines = ["| encoder | classifier | L | seed | error | row |", "|---|---|---|---|---|---|"]
    for f in failed:
        error = md(f["error"])
        lines.append(f"| {f['encoder']} | {f['classifier']} | {f['L']} | {f['seed']} | "
                     f"{error} | `cells/{f['key']}.json` |")
    return "\n".join(lines)


def reference_markdown(reference: Sequence[dict[str, Any]],
                       summaries: Sequence[dict[str, Any]], labels: Labels | None = None
                       ) -> str:
    """A table: each published point, and our cells it compares with ("-" where none):
    those of its label's encoder, or ``encoder / classifier`` (by short name or label)."""
    labels = summary_labels(summaries) if labels is None else labels
    lines = ["| published | L | published % | ours (cell) | ours % | 95 % CI of mean |",
             "|---|---|---|---|---|---|"]
    for p in reference:
        published = f"{100 * p['accuracy']:.1f}" + (
            f" ± {100 * p['err']:.1f}" if p["err"] is not None else "")
        ours = [s for s in summaries if s["L"] == p["L"] and p["label"] in (
            s["encoder"], f"{s['encoder']} / {short_name(s['classifier'])}",
            f"{s['encoder']} / {spec_label(s['classifier'], labels)}")]
        if not ours:
            lines.append(f"| {p['label']} | {p['L']} | {published} | - | - | - |")
        for s in ours:
            lines.append(
                f"| {p['label']} | {p['L']} | {published} | {s['encoder']} / "
                f"{spec_label(s['classifier'], labels)} | "
                f"{_pct(s['accuracy_mean'], s['accuracy_std'])}"
                f" | {_interval(s.get('accuracy_ci95'))} |")
    return "\n".join(lines)


def per_class_gains_markdown(comps: Sequence[dict[str, Any]], labels: Labels | None = None
                             ) -> str:
    """Per-class gains B − A (points) with their run-level intervals, one line per
    comparison ("" when none has them)."""
    labels = comparison_labels(comps) if labels is None else labels
    comps = [c for c in comps if c.get("per_class")]
    if not comps:
        return ""
    classes = list(dict.fromkeys(k for c in comps for k in c["per_class"]))
    lines = ["| factor | A | B | where | " + " | ".join(map(md, classes)) + " |",
             "|" + "---|" * (4 + len(classes))]
    for c in comps:
        cells = []
        for k in classes:
            g = c["per_class"].get(k)
            if g is None:
                cells.append("-")
            elif g["low"] is None:
                cells.append(f"{100 * g['difference']:+.1f}")
            else:
                cells.append(f"{100 * g['difference']:+.1f} [{100 * g['low']:+.1f}, "
                             f"{100 * g['high']:+.1f}]")
        lines.append(f"| {c['factor']} | {_comparison_label(c, 'a', labels)} | "
                     f"{_comparison_label(c, 'b', labels)} | {_context(c, labels)} | "
                     + " | ".join(cells)
                     + " |")
    return "\n".join(lines)


def per_user_gains_markdown(comps: Sequence[dict[str, Any]], labels: Labels | None = None
                            ) -> str:
    """Per-user gains of every pair: users tested, helped, hurt, median and quartiles
    (points) ("" when no comparison has them: not a users split, or no user ids)."""
    labels = comparison_labels(comps) if labels is None else labels
    comps = [c for c in comps if c.get("per_user")]
    if not comps:
        return ""
    lines = ["| factor | A | B | where | users | helped | hurt | median gain | "
             "quartiles |", "|---|---|---|---|---|---|---|---|---|"]
    for c in comps:
        u = c["per_user"]
        lines.append(f"| {c['factor']} | {_comparison_label(c, 'a', labels)} | "
                     f"{_comparison_label(c, 'b', labels)} | {_context(c, labels)} | "
                     f"{u['users']} | "
                     f"{u['helped']} | {u['hurt']} | {100 * u['median']:+.1f} | "
                     f"{100 * u['q25']:+.1f} … {100 * u['q75']:+.1f} |")
    return "\n".join(lines)


def per_user_accuracy_markdown(summaries: Sequence[dict[str, Any]],
                               labels: Labels | None = None) -> str:
    """Per-user accuracy of every cell (%, mean over the runs testing the user)."""
    labels = summary_labels(summaries) if labels is None else labels
    summaries = [s for s in summaries if s.get("per_user_accuracy")]
    if not summaries:
        return ""
    users = sorted({u for s in summaries for u in s["per_user_accuracy"]})
    lines = ["| encoder | classifier | L | " + " | ".join(map(md, users)) + " |",
             "|" + "---|" * (3 + len(users))]
    for s in summaries:
        acc = s["per_user_accuracy"]
        lines.append(f"| {s['encoder']} | {spec_label(s['classifier'], labels)} | {s['L']} | "
                     + " | ".join(f"{100 * acc[u]:.0f}" if u in acc else "-" for u in users)
                     + " |")
    return "\n".join(lines)


def variance_markdown(parts: Sequence[dict[str, Any]], labels: Labels | None = None) -> str:
    """The variance decomposition of each cell's accuracy (standard deviations, points)."""
    if not parts:
        return ""
    labels = summary_labels(parts) if labels is None else labels
    lines = ["| encoder | classifier | L | split seeds × init seeds | split sd | "
             "initialisation sd | test-sampling sd |", "|---|---|---|---|---|---|---|"]
    for v in parts:
        lines.append(f"| {v['encoder']} | {spec_label(v['classifier'], labels)} | {v['L']} | "
                     f"{v['split_seeds']} × {v['init_seeds']} | {v['split_sd']:.1f}"
                     + (" (clipped at 0)" if "split" in v["clipped"] else "")
                     + f" | {v['init_sd']:.1f} | {v['test_sd']:.1f} |")
    return "\n".join(lines)
