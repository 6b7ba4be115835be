"""A run folder's report: an :class:`~tactbench.runner.analysis.report.Analysis` written
as results.json, results.csv, report.md and the figures.

:func:`render` makes a :class:`Report` of an analysis (what the rows say, decided in
:mod:`tactbench.runner.analysis.report`); :func:`write_report` writes it. Nothing here
decides or computes a number, and nothing reads a file back: the same rows always give
the same files, but for the one line saying when and by which command they were
rendered (:data:`RENDERED`). What a run writes at the top of its folder (the out-folder
check asks it) is said with the rows,
:func:`tactbench.runner.execution.results.is_run_output`.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable, Sequence

from tactbench.data.windows import UNNAMED_TEST_WINDOW
from tactbench.machine import describe_machines
from tactbench.paths import atomic_write_text
from tactbench.runner.analysis.comparisons import Comparison
from tactbench.runner.analysis.report import Analysis
from tactbench.runner.presentation.plots import caption, check_reference, write_plots
from tactbench.runner.execution.identity import IDENTITY_DEFAULTS
from tactbench.runner.execution.results import (
    INDEPENDENT_RUNS,
    REPORT_HEADER,
    command_line,
    ok_rows,
    row_status,
)
from tactbench.runner.presentation.tables import (
    comparisons_section,
    labels_for,
    primary_section,
    failed_cells_markdown,
    markdown_table,
    per_class_markdown,
    per_user_accuracy_markdown,
    reference_markdown,
    variance_markdown,
)

#: The line of report.md (and the key of results.json) that says when and by which
#: command the report was rendered: the only part two renders of the same rows differ in.
RENDERED = "- rendered: "


@dataclass
class Report:
    """A folder's :class:`~tactbench.runner.analysis.report.Analysis` as results.json,
    results.csv and report.md show it (:func:`render`).

    ``analysis``: what the rows say, decided (its ``rows``, ``summaries``,
    ``comparisons``, ``variance``, ``statistics``, ``runs``, ``looks`` and ``history``
    are read here too, as attributes of the report); ``rendered``: when and by which
    command this report was made; ``reference``: published points set beside ours;
    ``paths``: the files written (empty until :func:`write_report`). :func:`run` also
    sets ``computed``, ``skipped`` and ``seconds``.
    """

    analysis: Analysis
    rendered: dict[str, str]
    reference: list[dict[str, Any]] = field(default_factory=list)
    paths: dict[str, Path] = field(default_factory=dict)
    computed: int = 0  # cells run now (ok or failed); set by run()
    cpu_seconds: float | None = None  # set by run_until: this process and its workers
    skipped: int = 0  # cells already finished before this run
    seconds: float = 0.0

    @property
    def budget_stop(self) -> str | None:
        """Why ``--budget`` ended the run (the analysis's decision), or None."""
        return self.analysis.budget_stop

    @property
    def rows(self) -> list[dict[str, Any]]:
        """Every row, ok and failed, in the scene's order."""
        return self.analysis.rows

    @property
    def summaries(self) -> list[dict[str, Any]]:
        """One per dataset, split, encoder, classifier and L, over seeds."""
        return self.analysis.summaries

    @property
    def comparisons(self) -> list[Comparison]:
        """The paired comparisons over runs, each with its verdict."""
        return self.analysis.comparisons

    @property
    def variance(self) -> list[dict[str, Any]]:
        """Where each cell's accuracy variance comes from."""
        return self.analysis.variance

    @property
    def statistics(self) -> dict[str, Any]:
        """The statistics options the comparisons were made with."""
        return self.analysis.statistics

    @property
    def runs(self) -> list[dict[str, Any]]:
        """The command lines and git revisions that computed the rows."""
        return self.analysis.runs

    @property
    def looks(self) -> dict[str, Any] | None:
        """A run ``--until answered``: every look, replayed (None for a fixed design)."""
        return self.analysis.looks

    @property
    def ok(self) -> list[dict[str, Any]]:
        """Rows of the cells that finished."""
        return self.analysis.ok

    @property
    def failed(self) -> list[dict[str, Any]]:
        """Rows of the cells that raised (retried by the next run of the same scene)."""
        return self.analysis.failed

    def table(self) -> list[dict[str, Any]]:
        """The rows as a flat table, one dict per cell with the columns of results.csv
        (:func:`tactbench.runner.presentation.frames.cells_frame` makes a typed data frame
        of it)."""
        return flat_rows(self.rows)

    def document(self) -> dict[str, Any]:
        """results.json's content: ``runs``, ``rendered``, ``summary``, ``comparisons``
        (with the contrasts and margin they were made with in ``statistics``),
        ``variance``, ``rows`` and, when given, ``reference``."""
        doc = {"runs": self.runs, "rendered": self.rendered, "summary": self.summaries,
               "comparisons": [c.to_dict() for c in self.comparisons],
               "statistics": self.statistics,
               "variance": self.variance, "rows": self.rows}
        if self.reference:
            doc["reference"] = self.reference
        if self.looks is not None:
            doc["looks"] = self.looks
        return doc


#: The columns on whether a cell's model learned (:mod:`tactbench.runner.execution.learning`),
#: beside its accuracy in results.csv; rows made before have none.
LEARNING_COLUMNS = ("train_accuracy", "chance_accuracy", "learning")


#: An identity field left out of a row at its default (:data:`~tactbench.runner.execution.
#: identity.IDENTITY_DEFAULTS`) → the value its column shows, so that every identity field is
#: a column of every row (two cells differing in one never look like one cell twice).
IDENTITY_COLUMN_DEFAULTS = {**IDENTITY_DEFAULTS, INDEPENDENT_RUNS: False}


def csv_columns(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The columns of results.csv (and of :meth:`Report.table`) for ``rows``: the cell
    (every field of its identity, :data:`~tactbench.runner.execution.planning.
    IDENTITY_FIELDS` and ``COMPUTE_FIELDS``, ``imaging`` as compact JSON), its status and
    accuracy (and, where a row records them, :data:`LEARNING_COLUMNS`), ``acc_<class>``
    for every class of any row, the costs."""
    classes = list(dict.fromkeys(c for r in rows for c in r.get("classes", ())))
    learning = [c for c in LEARNING_COLUMNS if any(c in r for r in rows)]
    return ["dataset", "dataset_hash", "split", "split_seed", "test_window",
            "test_per_class", "imaging", "encoder", "encoder_version", "precision",
            "classifier", "profile", "L", "seed", "init_seed", "input", "run_dataset",
            INDEPENDENT_RUNS, "status", "accuracy", *learning,
            *[f"acc_{c}" for c in classes],
            "encode_ms_per_frame", "train_s", "inference_ms_per_sequence", "peak_rss_mb",
            "peak_step", "n_train_windows", "n_test", "device", "threads", "cpu_kernels",
            "finished", "key", "schema", "error"]


def flat_rows(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One flat dict per row, of the :func:`csv_columns` (None where a row has no
    value); a failed cell's has ``status`` ``failed``, its error in ``error`` and no
    accuracy or costs."""
    columns = csv_columns(rows)
    flat = []
    for r in rows:
        line = {**IDENTITY_COLUMN_DEFAULTS, **r, "status": row_status(r)}
        if isinstance(r.get("imaging"), dict):
            line["imaging"] = json.dumps(r["imaging"], sort_keys=True, separators=(",", ":"))
        for c, accuracy in (r.get("per_class_accuracy") or {}).items():
            line[f"acc_{c}"] = accuracy
        if "error" in r:
            line["error"] = f"{r['error'].get('type')}: {r['error'].get('message')}"
        flat.append({k: line.get(k) for k in columns})
    return flat


def rows_csv(rows: Sequence[dict[str, Any]]) -> str:
    """Flat CSV: one line per cell (:func:`flat_rows`)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=csv_columns(rows))
    writer.writeheader()
    writer.writerows(flat_rows(rows))
    return buf.getvalue()


def render(analysis: Analysis, *, reference: Iterable[dict[str, Any]] | None = None,
           rendered: str | None = None) -> Report:
    """The :class:`Report` of ``analysis``: nothing is decided here, only said.

    ``reference``: published points to set beside ours (:func:`check_reference`; a
    mistake is refused here, before any file); ``rendered``: how the report came to be,
    said in report.md beside the command line and the time."""
    return Report(analysis=analysis, reference=check_reference(reference),
                  rendered={"by": command_line(), "how": rendered or "from the rows of cells/",
                            "at": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")})


def write_report(out: str | Path, report: Report, *, plots: bool = True) -> dict[str, Path]:
    """Write ``report`` into ``out`` as results.json, results.csv, report.md and (with
    ``plots``) the figures; returns the paths written (also kept in ``report.paths``)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "results.json", "csv": out / "results.csv",
             "markdown": out / "report.md"}
    atomic_write_text(paths["json"], json.dumps(report.document(), indent=2))
    atomic_write_text(paths["csv"], rows_csv(report.rows))
    figures: dict[str, Path] = {}
    if plots and report.summaries:
        figures = write_plots(out, report.summaries, reference=report.reference,
                              labels=labels_for(rows=report.rows, summaries=report.summaries))
        paths.update(figures)
    atomic_write_text(paths["markdown"], markdown_report(report, figures))
    report.paths = paths
    return paths


def _runs_text(runs: Sequence[dict[str, Any]]) -> str:
    """``computed by `COMMAND` (git `REV`)``; several runs with their counts of cells."""
    if len(runs) == 1:
        return f"computed by `{runs[0]['command']}` (git `{runs[0]['git']}`)"
    return "computed by " + "; ".join(f"`{r['command']}` (git `{r['git']}`, {r['cells']} "
                                      f"cells)" for r in runs)


def _statistics_text(statistics: dict[str, Any]) -> str:
    margin = statistics.get("margin")
    contrasts = ", ".join(f"`{c}`" for c in statistics.get("contrasts") or ()) or "none"
    primary = ", ".join(f"`{c}`" for c in statistics.get("primary") or ())
    test = statistics.get("paired_test")
    return (f"- statistics: margin {'none' if margin is None else f'{margin:g} points'}; "
            f"contrasts {contrasts}" + (f"; primary {primary}" if primary else "")
            + (f"; paired test `{test}` (--paired-test)" if test else ""))


def _facts(report: Report) -> list[str]:
    """The lines of report.md that say what the rows are: dataset, split, cells and the
    runs that computed them, versions, machines, statistics options, how it was rendered."""
    rows = report.rows
    done = ok_rows(rows)
    first = done[0] if done else (rows[0] if rows else {})
    n_failed = len(rows) - len(done)
    rendered = report.rendered
    return [
        f"- dataset: `{first.get('dataset', '?')}` " + (
            "(a data set of its own for every run, independent replications: each row's "
            "`run_dataset` and content hash name it)" if first.get(INDEPENDENT_RUNS) else
            f"(content hash `{str(first.get('dataset_hash', '?'))[:16]}`)"),
        f"- split: `{first.get('split', '?')}`; test window: "
        f"`{first.get('test_window', UNNAMED_TEST_WINDOW)}` (the L frames each test sequence is "
        f"classified on); profile: `{first.get('profile', '?')}`; "
        f"device: `{first.get('device', '?')}`",
        f"- cells: {len(rows)}" + (f" ({n_failed} failed, listed below)" if n_failed else "")
        + f"; {_runs_text(report.runs)}",
        "- versions: " + ", ".join(f"{k} {v}" for k, v in first.get("versions", {}).items()),
        f"- machine: {describe_machines(rows)} (see docs/reliability.md, 'Numbers "
        f"across machines')",
        _statistics_text(report.statistics),
        f"{RENDERED}{rendered['how']} by `{rendered['by']}` at {rendered['at']}",
    ]


def test_set_sizes(rows: Iterable[dict[str, Any]]) -> str:
    """The test-set sizes of ``rows``' seeds: ``150``, or ``19–157`` where seeds differ
    ("" without any)."""
    sizes = sorted({int(r["n_test"]) for r in rows if isinstance(r.get("n_test"), int)})
    if not sizes:
        return ""
    return str(sizes[0]) if len(sizes) == 1 else f"{sizes[0]}–{sizes[-1]}"


def markdown_report(report: Report, figures: dict[str, Path]) -> str:
    """report.md: run facts, the accuracy/cost table, per-class accuracy, paired
    comparisons over runs (with per-class and per-user gains), the variance
    decomposition, published reference points, failed cells, figures with captions."""
    summaries, rows, comps = report.summaries, report.rows, report.comparisons
    reference, variance = report.reference, report.variance
    labels = labels_for(rows=rows, summaries=summaries)
    done = ok_rows(rows)
    failed = failed_cells_markdown(rows)
    first = done[0] if done else (rows[0] if rows else {})
    n_failed = len(rows) - len(done)
    lines = [
        REPORT_HEADER, "", *_facts(report), "",
        *primary_section(comps, report.looks, labels),
        "Accuracy is mean ± standard deviation over seeds, with a 95 % t-interval of the "
        f"mean over seeds (test set: {test_set_sizes(done) or first.get('n_test', '?')} "
        "sequences per seed). Encode cost is per frame on one "
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
                  "How each cell's accuracy spreads over the people tested; every user's "
                  "value is drawn in per_user_accuracy.png and kept in results.json "
                  "(`summary[].per_user_accuracy`).", "", by_user, ""]
    if variance:
        lines += ["## Where each cell's accuracy variance comes from", "",
                  "Runs vary the split and the initialisation separately; each cell's "
                  "accuracy variance split into split, initialisation and test sampling "
                  "(p(1 − p)/n_test), as standard deviations in points (`variance` in "
                  "results.json; a pair's difference is decomposed under the comparisons, "
                  "`comparisons[].variance_components`).", "",
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

