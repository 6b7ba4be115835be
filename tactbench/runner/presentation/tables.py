"""Tables of summaries and comparisons: for the terminal (rich) and for Markdown."""

from __future__ import annotations

import math
import re
from typing import Any, Iterable, Mapping, Sequence

from tactbench.runner.analysis.answering import beyond_looks
from tactbench.runner.analysis.paired_tests import PAIRED_TEST_TEXT, chosen_tests
from tactbench.runner.analysis.comparisons import (INDEPENDENT_METHOD, P_RULE, Comparison, plain_t,
                                                   read_comparisons)
from tactbench.runner.presentation.marks import accuracy_mark, learning_legend
from tactbench.runner.analysis.statistics import (A_BETTER, B_BETTER, DECIDED, EQUIVALENT,
                                                  MIN_RUNS, NOT_LEARNED, TOO_FEW_RUNS, UNRESOLVED)
from tactbench.runner.analysis.summaries import failed_cells
from tactbench.runner.execution.questions import FACTORS, short_name, spec_label, spec_labels

#: Classifier spec → the name shown for it (``questions.spec_labels``).
Labels = Mapping[str, str]
#: Comparisons as records, or as results.json stores them (verified by ``read_comparisons``).
Comparisons = Sequence["Comparison | Mapping[str, Any]"]


_MD_SPECIAL = re.compile(r"([\\`*_\[\]<>|~])")


def md(text: Any) -> str:
    """Text a user gave (a class or user name, an error message) as literal Markdown in a
    table cell: every Markdown special character escaped with a backslash (``|`` would
    end the cell, ``*`` start emphasis), line breaks as spaces."""
    return _MD_SPECIAL.sub(r"\\\1", " ".join(str(text).split()))


def labels_for(*, rows: Iterable[dict[str, Any]] = (), summaries: Iterable[dict[str, Any]] = (),
               comps: Comparisons = ()) -> dict[str, str]:
    """The name every table and figure of a run shows for each classifier that ``rows``,
    ``summaries`` or the comparisons ``comps`` name (compared, or shared where they
    differ in another factor): :func:`~tactbench.runner.execution.questions.spec_labels`
    over them all, so one run tells its variants apart the same way everywhere."""
    comps = read_comparisons(comps) if comps else []
    return spec_labels([*(r["classifier"] for r in rows),
                        *(s["classifier"] for s in summaries),
                        *(v for c in comps if c.factor == "classifier" for v in (c.a, c.b)),
                        *(c.where["classifier"] for c in comps if "classifier" in c.where)])


def _comparison_label(c: Comparison, side: str, labels: Labels | None = None) -> str:
    value = getattr(c, side)
    if c.factor == "classifier":
        return spec_label(value, labels)
    if c.factor == "L":
        return f"L={value}"
    if c.factor == "contrast":  # "encoder=raw,L=6" → "raw L=6"
        items = [item.partition("=") for item in str(value).split(",")]
        return " ".join(f"L={v}" if k == "L" else v for k, _, v in items)
    return str(value)


def _context(c: Comparison, labels: Labels | None = None) -> str:
    parts = []
    for k in FACTORS:
        if k == c.factor or k not in c.where:
            continue
        value = c.where[k]
        parts.append(f"L={value}" if k == "L" else spec_label(value, labels) if
                     k == "classifier" else str(value))
    return " ".join(parts) or "-"


def _pair(c: Comparison, labels: Labels | None) -> list[str]:
    """The cells naming a comparison in every table of comparisons: factor, A, B, where."""
    return [c.factor, _comparison_label(c, "a", labels), _comparison_label(c, "b", labels),
            _context(c, labels)]


COMPARISON_HEADER = ["factor", "A", "B", "where", "B − A (points)",
                     "95 % interval over runs (unadjusted)", "runs B>A / A>B / tied",
                     "p (corrected t)", "Holm p (its family)", "P(A better / ≈ / B better)",
                     "runs for 80 % power (one fixed test)", "verdict"]
#: The p column's name where a table's t are all plain, or mixed (:func:`comparison_header`).
P_COLUMN = {"plain": "p (paired t)", "mixed": "p (t over runs)"}


def _t_kind(comps: Sequence[Comparison]) -> str:
    """``corrected`` (every comparison's t is corrected for overlapping runs), ``plain``
    (every one is the paired t over independent runs) or ``mixed``."""
    kinds = {plain_t(c) for c in comps}
    return "corrected" if True not in kinds else "plain" if kinds == {True} else "mixed"


def comparison_header(comps: Comparisons) -> list[str]:
    """:data:`COMPARISON_HEADER` of ``comps``, its p column named by their test or t kind."""
    comps = read_comparisons(comps)
    column = f"p ({chosen_tests(comps)})" if chosen_tests(comps) else P_COLUMN.get(_t_kind(comps))
    return [column or col if col == "p (corrected t)" else col for col in COMPARISON_HEADER]


def verdict_text(c: Comparison | Mapping[str, Any], labels: Labels | None = None,
                 names: tuple[str, str] | None = None) -> str:
    """The verdict in words: ``farneback better``, ``equivalent within ±2``, ...; ``names``:
    A and B as a sentence calls them (``("raw", "flow")``), else their labels."""
    [c] = read_comparisons([c])
    a, b = names or (_comparison_label(c, "a", labels), _comparison_label(c, "b", labels))
    if c.verdict in (B_BETTER, A_BETTER):
        return f"{b if c.verdict == B_BETTER else a} better"
    if c.verdict == EQUIVALENT:
        return f"equivalent within ±{c.equivalence_margin:g}"
    return c.verdict


def comparison_rows(comps: Comparisons, labels: Labels | None = None) -> list[list[str]]:
    """Table cells, :data:`COMPARISON_HEADER`'s columns (the p: the comparison's
    ``method``'s t). A classifier is named by its label in ``labels`` (by default the
    labels among the classifiers of ``comps``, :func:`labels_for`)."""
    comps = read_comparisons(comps)
    labels = labels_for(comps=comps) if labels is None else labels
    return [[*_pair(c, labels), "ceiling" if c.ceiling else f"{100 * c.difference:+.1f}",
             "both 100 %" if c.ceiling else
             f"[{100 * c.low:+.1f}, {100 * c.high:+.1f}]" if c.p is not None else "-",
             f"{c.b_better_runs}/{c.a_better_runs}/{c.tied_runs}",
             _p_value(c.p), _p_value(c.p_holm), _bayes(c), _power_runs(c),
             verdict_text(c, labels)]
            for c in comps]


def _bayes(c: Comparison) -> str:
    """The Bayesian correlated t's three probabilities, within ±margin points."""
    if c.bayes_b_better is None:
        return "-"
    return (f"{c.bayes_a_better:.2f} / {c.bayes_equivalent:.2f} / {c.bayes_b_better:.2f} "
            f"(±{c.bayes_margin:g})")


def _power_runs(c: Comparison) -> str:
    """Runs for 80 % power at the observed difference, or why there is no number."""
    if c.ceiling or c.verdict in (*DECIDED, NOT_LEARNED):
        return "-"
    if c.runs < MIN_RUNS or c.difference == 0:  # too few runs to judge the spread
        return "-"
    if c.runs_for_power is not None:
        return str(c.runs_for_power)
    return "beyond these data"


def _p_value(p: float | None) -> str:
    return "-" if p is None else "< 0.001" if p < 0.001 else f"{p:.3f}"


def comparisons_markdown(comps: Comparisons, labels: Labels | None = None) -> str:
    if not comps:
        return ""
    lines = ["| " + " | ".join(comparison_header(comps)) + " |",
             "|" + "---|" * len(COMPARISON_HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in comparison_rows(comps, labels)]
    return "\n".join(lines)


def print_comparisons(comps: Comparisons, *, factors: Sequence[str] = ("encoder", "classifier"),
                      labels: Labels | None = None) -> None:
    """The terminal's tables of paired comparisons: the primary questions first (all of
    them), then the exploratory ones (by default of encoders and classifiers; report.md
    and results.json hold every factor)."""
    comps = read_comparisons(comps)
    labels = labels_for(comps=comps) if labels is None else labels
    primary = [c for c in comps if c.family == "primary"]
    rest = [c for c in comps if c.family != "primary" and c.factor in factors]
    from rich.console import Console

    console = Console()
    if not console.is_terminal:
        console = Console(width=160)
    for title, shown in (("primary questions (confirmatory; Holm within them)", primary),
                         ("exploratory comparisons (Holm within them)", rest)):
        if shown:
            console.print(_rich_table(f"{title}: B − A over runs; an interval touching 0 "
                                      "is unresolved", shown, labels))


def _rich_table(title: str, comps: Sequence[Comparison], labels: Labels):
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    for col in comparison_header(comps):
        table.add_column(col, justify="left" if col in ("factor", "A", "B", "where",
                                                        "verdict") else "right")
    for row in comparison_rows(comps, labels):
        table.add_row(*row)
    return table


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
    among the classifiers of ``summaries``, :func:`labels_for`)."""
    labels = labels_for(summaries=summaries) if labels is None else labels
    rows = []
    for s in summaries:
        rows.append([
            s["encoder"], spec_label(s["classifier"], labels), s.get("input", "-"), str(s["L"]),
            _pct(s["accuracy_mean"], s["accuracy_std"]) + accuracy_mark(s),
            _interval(s.get("accuracy_ci95")),
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
    for line in _legend(summaries, labels):
        console.print(line, markup=False, highlight=False)


def _legend(summaries: Sequence[dict[str, Any]], labels: Labels | None) -> list[str]:
    """The lines under the accuracy table on cells that did not learn (none without)."""
    labels = labels_for(summaries=summaries) if labels is None else labels
    return learning_legend(summaries, lambda s: f"{s['encoder']} / "
                           f"{spec_label(s['classifier'], labels)} L={s['L']}")


def markdown_table(summaries: Sequence[dict[str, Any]], labels: Labels | None = None) -> str:
    lines = ["| " + " | ".join(TABLE_HEADER) + " |",
             "|" + "---|" * len(TABLE_HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(summaries, labels)]
    return "\n".join(lines + [f"\n{md(line)}" for line in _legend(summaries, labels)])


def per_class_markdown(summaries: Sequence[dict[str, Any]], labels: Labels | None = None
                       ) -> str:
    if not summaries:
        return ""
    labels = labels_for(summaries=summaries) if labels is None else labels
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
    labels = labels_for(summaries=summaries) if labels is None else labels
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


def per_class_gains_markdown(comps: Comparisons, labels: Labels | None = None) -> str:
    """Per-class gains B − A (points) with their run-level intervals, one line per
    comparison ("" when none has them)."""
    comps = read_comparisons(comps)
    labels = labels_for(comps=comps) if labels is None else labels
    comps = [c for c in comps if c.per_class]
    if not comps:
        return ""
    classes = list(dict.fromkeys(k for c in comps for k in c.per_class))
    lines = ["| factor | A | B | where | " + " | ".join(map(md, classes)) + " |",
             "|" + "---|" * (4 + len(classes))]
    for c in comps:
        gains = [c.per_class.get(k) for k in classes]
        cells = ["-" if g is None else f"{100 * g.difference:+.1f}" + (
            "" if g.low is None else f" [{100 * g.low:+.1f}, {100 * g.high:+.1f}]")
            for g in gains]
        lines.append("| " + " | ".join(_pair(c, labels) + cells) + " |")
    return "\n".join(lines)


def per_user_gains_markdown(comps: Comparisons, labels: Labels | None = None) -> str:
    """Per-user gains of every pair: users tested, helped, hurt, median and quartiles
    (points) ("" when no comparison has them: not a users split, or no user ids)."""
    comps = read_comparisons(comps)
    labels = labels_for(comps=comps) if labels is None else labels
    comps = [c for c in comps if c.per_user]
    if not comps:
        return ""
    lines = ["| factor | A | B | where | users | helped | hurt | median gain | "
             "quartiles |", "|---|---|---|---|---|---|---|---|---|"]
    for c in comps:
        u = c.per_user
        lines.append("| " + " | ".join(_pair(c, labels)) + f" | {u.users} | "
                     f"{u.helped} | {u.hurt} | {100 * u.median:+.1f} | "
                     f"{100 * u.q25:+.1f} … {100 * u.q75:+.1f} |")
    return "\n".join(lines)


def _component(v: Mapping[str, Any], name: str) -> str:
    """``3.0 (15 %)``: a component's SD (points) and share; ``clipped`` where noise made
    its estimate negative."""
    share = v[f"{name}_share"]
    return (f"{v[f'{name}_sd']:.1f} ({'-' if share is None else f'{100 * share:.0f} %'}"
            + (", clipped at 0" if name in v["clipped"] else "") + ")")


def variance_components_markdown(comps: Comparisons, labels: Labels | None = None) -> str:
    """The variance of each pair's per-run difference split into split, initialisation
    and test sampling (SD in points, share of the per-run variance), for the primary
    comparisons that carry it, or every comparison where none is primary ("" when no
    comparison carries it: the runs vary no init seed)."""
    comps = read_comparisons(comps)
    labels = labels_for(comps=comps) if labels is None else labels
    comps = [c for c in comps if c.variance_components]
    comps = [c for c in comps if c.family == "primary"] or comps
    if not comps:
        return ""
    lines = ["| factor | A | B | where | split × init seeds | split | initialisation | "
             "test sampling | per-run SD, estimated (observed) |", "|---" * 9 + "|"]
    for c in comps:
        v = c.variance_components
        lines.append("| " + " | ".join(_pair(c, labels)) + f" | {v['split_seeds']} × "
                     f"{v['init_seeds']} | {_component(v, 'split')} | {_component(v, 'init')}"
                     f" | {_component(v, 'test')}, {v['test_sampling']} | "
                     f"{math.sqrt(v['total_var']):.1f} ({math.sqrt(v['observed_var']):.1f}) |")
    return "\n".join(lines)


#: What report.md says above the table of variance components.
VARIANCE_TEXT = (
    "The runs vary the split (--seed) and the initialisation (--init-seed) apart, so the "
    "variance of a run's difference B − A splits into the split's, the initialisation's "
    "and the test sampling's (each run's test set is a sample: (π − δ²)/n, clustered by "
    "test group, the users of a users split, where a group holds several recordings). "
    "Standard deviations in points with their share of the per-run variance; "
    "method-of-moments estimates, rough with few split seeds (docs/statistics.md, "
    "\"Where the difference's variance comes from\").")


#: The test the interval and p of a table's comparisons come from, by :func:`_t_kind`.
T_TEXT = {
    "corrected": "the corrected resampled t over runs (Nadeau–Bengio; for K folds "
                 "Bouckaert–Frank), which counts the training variability, not only the "
                 "test set's,",
    "plain": "the plain paired t over runs (no overlap to correct for: each run drew its "
             "own data set, or every run trained anew on one fixed split, a figure about "
             "that split; `method` in results.json), which counts the runs' variability,",
    "mixed": "the t over runs: corrected resampled (Nadeau–Bengio; for K folds "
             "Bouckaert–Frank) where runs re-split one data set, the plain paired t where "
             "each run drew its own or all share one fixed split (each comparison's "
             "`method` in results.json); either counts the runs' variability,",
}
#: What report.md says above its table of comparisons, with the test (:data:`T_TEXT`)
#: and the rule of p (:data:`~tactbench.runner.analysis.comparisons.P_RULE`, "the corrected t's"
#: said "that t's" where not every t is corrected).
COMPARISONS_TEMPLATE = (
    "Every two cells that differ in one factor (and every contrast asked for), compared "
    "on the same test sequences run by run: B − A is the mean over runs (a run: one split "
    "seed, its split and initialisation) of the difference of accuracy. The interval is "
    "{test} at 95 % for that "
    "comparison alone (unadjusted); {rule}. Primary comparisons (named with "
    "--primary) are the confirmatory family; the rest are exploratory. Fewer than 3 runs "
    "give no verdict; an interval touching 0 is unresolved. P(A better / ≈ / B better) "
    "is the Bayesian correlated t (Corani & Benavoli 2015) within ±margin points; "
    "\"runs for 80 % power (one fixed test)\" is the runs one test at the end needs to find "
    "the observed difference with 80 % power at the family's Bonferroni level (a run --until "
    "answered looks from 5 runs on, and has less power at that number: `tactbench plan` "
    "forecasts it), \"beyond these data\" where no number of runs of these recordings would; "
    "\"ceiling\" is two models right on every recording. McNemar's test per seed "
    "(results.json, `mcnemar_per_seed`) speaks of "
    "those trained models only. See docs/statistics.md.")
#: The text above the comparisons where every t is corrected (every stored report's).
COMPARISONS_TEXT = COMPARISONS_TEMPLATE.format(test=T_TEXT["corrected"], rule=P_RULE)


#: What report.md adds where runs drew their own data sets (people=per-run).
INDEPENDENT_TEXT = (
    " Where every run drew its own data set (`synthetic-forearm:people=per-run`: new "
    "simulated people each run), runs are independent replications: no effect is beyond "
    "what more runs resolve, and the results speak of the simulator's population of "
    "people, not of one recorded data set.")


def comparisons_text(comps: Comparisons) -> str:
    """The text above report.md's tables of ``comps``: :data:`COMPARISONS_TEXT` where every
    t is corrected, else naming the plain paired t too (and :data:`INDEPENDENT_TEXT` where
    runs drew their own data sets; a fixed split's plain t is not that)."""
    if chosen_tests(read_comparisons(comps)):  # --paired-test: named, and in each `method`
        return COMPARISONS_TEMPLATE.format(test=PAIRED_TEST_TEXT.format(chosen_tests(
            read_comparisons(comps))), rule=P_RULE.replace("corrected t's", "paired test's"))
    kind = _t_kind(read_comparisons(comps))
    if kind == "corrected":
        return COMPARISONS_TEXT
    rule = P_RULE.replace("the corrected t's", "that t's")
    independent = any(c.method.startswith(INDEPENDENT_METHOD) for c in read_comparisons(comps))
    return (COMPARISONS_TEMPLATE.format(test=T_TEXT[kind], rule=rule)
            + (INDEPENDENT_TEXT if independent else ""))


def comparisons_section(comps: Comparisons, labels: Labels | None = None) -> list[str]:
    """report.md's lines on the paired comparisons (none without comparisons): the
    table of verdicts, the notes, and the table of each further result (per-class and
    per-user gains) — where a new test's table goes."""
    comps = read_comparisons(comps)
    if not comps:
        return []
    lines = ["## Paired comparisons over runs", "", comparisons_text(comps), ""]
    primary = [c for c in comps if c.family == "primary"]
    if primary:
        lines += ["### Primary questions (confirmatory)", "",
                  comparisons_markdown(primary, labels), "",
                  "### Exploratory comparisons", ""]
    lines += [comparisons_markdown([c for c in comps if c.family != "primary"], labels), ""]
    notes = [c.note for c in comps if c.note]
    for note in dict.fromkeys(notes):
        lines.append(f"- {notes.count(note)} comparison(s): {note}.")
    if notes:
        lines.append("")
    gains = per_class_gains_markdown(comps, labels)
    if gains:
        lines += ["### Per-class gains (B − A, points, 95 % interval over runs)", "",
                  gains, ""]
    components = variance_components_markdown(comps, labels)
    if components:
        lines += ["### Where the difference's variance comes from", "", VARIANCE_TEXT, "",
                  components, ""]
    people = per_user_gains_markdown(comps, labels)
    if people:
        lines += ["### Per-user gains (B − A on each test user's recordings)", "",
                  "A user is helped when B's accuracy on their recordings, averaged "
                  "over the runs that test them, is above A's.", "", people, ""]
    return lines


def per_user_accuracy_markdown(summaries: Sequence[dict[str, Any]],
                               labels: Labels | None = None) -> str:
    """How each cell's accuracy spreads over the test users (%, each user's the mean over
    the runs testing them): users, median, quartiles, lowest and highest — every user's
    value is drawn in ``per_user_accuracy.png`` and kept in results.json."""
    import numpy as np

    labels = labels_for(summaries=summaries) if labels is None else labels
    summaries = [s for s in summaries if s.get("per_user_accuracy")]
    if not summaries:
        return ""
    lines = ["| encoder | classifier | L | users | median | quartiles | lowest | highest |",
             "|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        acc = 100 * np.array(list(s["per_user_accuracy"].values()), dtype=float)
        q25, q50, q75 = np.percentile(acc, [25, 50, 75])
        lines.append(f"| {s['encoder']} | {spec_label(s['classifier'], labels)} | {s['L']} | "
                     f"{len(acc)} | {q50:.0f} | {q25:.0f} … {q75:.0f} | {acc.min():.0f} | "
                     f"{acc.max():.0f} |")
    return "\n".join(lines)


def variance_markdown(parts: Sequence[dict[str, Any]], labels: Labels | None = None) -> str:
    """The variance decomposition of each cell's accuracy (standard deviations, points);
    a pair's difference is :func:`variance_components_markdown`."""
    if not parts:
        return ""
    labels = labels_for(summaries=parts) if labels is None else labels
    lines = ["| encoder | classifier | L | split seeds × init seeds | split sd | "
             "initialisation sd | test-sampling sd |", "|---|---|---|---|---|---|---|"]
    for v in parts:
        lines.append(f"| {v['encoder']} | {spec_label(v['classifier'], labels)} | {v['L']} | "
                     f"{v['split_seeds']} × {v['init_seeds']} | {v['split_sd']:.1f}"
                     + (" (clipped at 0)" if "split" in v["clipped"] else "")
                     + f" | {v['init_sd']:.1f} | {v['test_sd']:.1f} |")
    return "\n".join(lines)


def answer_text(c: Comparison, labels: Labels | None = None) -> str:
    """One primary question's answer in a sentence: the verdict, the difference and its
    interval, the Holm p of its family, the Bayesian probabilities; where it is
    unresolved, what would answer it (runs for 80 % power, or "beyond these data")."""
    [c] = read_comparisons([c])
    where = _context(c, labels)
    head = (f"**{_comparison_label(c, 'b', labels)} against {_comparison_label(c, 'a', labels)}**"
            + (f" ({where})" if where != "-" else ""))
    if c.ceiling:
        return f"{head}: a ceiling — both right on every recording of every run."
    detail = (f"B − A {100 * c.difference:+.1f} points"
              + (f" [{100 * c.low:+.1f}, {100 * c.high:+.1f}] (95 %, unadjusted)"
                 if c.p is not None else "")
              + f", Holm p {_p_value(c.p_holm)} over {c.runs} runs")
    if c.bayes_b_better is not None:
        detail += (f"; P(B better by > {c.bayes_margin:g}) = {c.bayes_b_better:.2f}, "
                   f"P(within ±{c.bayes_margin:g}) = {c.bayes_equivalent:.2f}")
    answer = verdict_text(c, labels) + (f" — {c.note}" if c.verdict == NOT_LEARNED else "")
    if c.verdict in (UNRESOLVED, TOO_FEW_RUNS):
        more = _power_runs(c)
        if more == "beyond these data":
            answer += " — at this difference no number of runs of these data gives 80 % power"
        elif more.isdigit() and int(more) <= c.runs and \
                (c.note or "").startswith("group-sequential"):
            answer += (f" — {more} runs would give 80 % power in a single test at its "
                       f"family's level; it has {c.runs}, but an early look's boundary "
                       "(α spent over the looks) is stricter: the next look would likely "
                       "answer it")
        elif more != "-":
            answer += f" — about {more} runs would answer it at 80 % power"
    return f"{head}: {answer}; {detail}."


def looks_markdown(looks: Mapping[str, Any]) -> str:
    """The looks of a run ``--until answered``: runs, each primary's difference, |t|
    against its boundary and decision, and why the run stopped."""
    budget = f", no batch begun past {looks['budget']}" if looks.get("budget") else ""
    cpu = looks.get("train_cpu_seconds")
    spent = (f" Training took {cpu / 60:.1f} CPU-minutes over these cells (every thread "
             f"of each fit; encoding not counted)." if cpu else "")
    lines = [f"Runs were added in batches until every primary question was decided "
             f"(at most {looks['max_runs']} runs{budget}; α spent over the looks, "
             f"O'Brien–Fleming type, Holm carried over them): {md(looks['stopped'])}."
             + spent + beyond_looks(looks), "",
             "| look | runs | comparison | B − A (points) | \\|t\\| | boundary | decision |",
             "|---|---|---|---|---|---|---|"]
    for k, look in enumerate(looks["looks"], 1):
        for name, lk in look["comparisons"].items():
            bound = "∞" if lk["boundary"] is None else f"{lk['boundary']:.2f}"
            t = "∞" if lk["t"] is None else f"{abs(lk['t']):.2f}"
            why = f" ({md(lk['why'])})" if lk.get("why") else ""
            lines.append(f"| {k} | {look['runs']} | {md(name)} | "
                         f"{100 * lk['difference']:+.1f} | {t} | {bound} | "
                         f"{lk['decision']}{why} |")
    return "\n".join(lines)


def primary_section(comps: Comparisons, looks: Mapping[str, Any] | None,
                    labels: Labels | None = None) -> list[str]:
    """report.md's first section: each primary question's answer (none without)."""
    primary = [c for c in read_comparisons(comps) if c.family == "primary"]
    if not primary:
        return []
    lines = ["## Primary questions", "",
             "The comparisons named before the run (--primary), a family of their own; "
             "everything below them is exploratory.", ""]
    lines += [f"- {answer_text(c, labels)}" for c in primary]
    if looks and looks.get("looks"):
        lines += ["", looks_markdown(looks)]
    return [*lines, ""]
