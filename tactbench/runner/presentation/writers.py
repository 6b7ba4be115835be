"""A run folder's report: computed from its rows, written as results.json, results.csv,
report.md and the figures.

:func:`make_report` computes a :class:`Report` from rows alone (what the cells of a folder
hold: :meth:`tactbench.runner.execution.results.ResultStore.stored_rows`); :func:`write_report`
writes it. Nothing here reads a file back: the same rows always give the same files, but
for the one line saying when and by which command they were rendered (:data:`RENDERED`).
What a run writes at the top of its folder (the out-folder check asks it) is said with
the rows, :func:`tactbench.runner.execution.results.is_run_output`.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import shlex
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable, Sequence

from tactbench.data.windows import UNNAMED_TEST_WINDOW
from tactbench.machine import describe_machines
from tactbench.paths import atomic_write_text
from tactbench.runner.analysis.answering import History, comparison_name, replay
from tactbench.runner.analysis.comparisons import Comparison, comparisons
from tactbench.runner.analysis.paired_tests import (DEFAULT_CHOICE, DEFAULT_PAIRED_TEST,
                                                    PairedTestChoice)
from tactbench.runner.presentation.plots import caption, check_reference, write_plots
from tactbench.runner.execution.identity import IDENTITY_DEFAULTS
from tactbench.runner.execution.results import (
    INDEPENDENT_RUNS,
    REPORT_HEADER,
    command_line,
    failed_rows,
    ok_rows,
    row_status,
)
from tactbench.runner.execution.scene import Design
from tactbench.runner.analysis.sequential import FUTILE
from tactbench.runner.analysis.statistics import DECIDED, NOT_LEARNED, UNRESOLVED
from tactbench.runner.analysis.summaries import summarise, variance_decomposition
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
    """What a run folder's rows say, as results.json, results.csv and report.md show it.

    ``rows``: every row, ok and failed, in the scene's order; ``summaries`` (one per
    dataset, split, encoder, classifier and L, over seeds), ``comparisons`` (paired over
    runs), ``variance`` and ``statistics`` (the options they were made with) are computed
    from them (:func:`make_report`); ``runs``: the command lines and git revisions that
    computed the rows; ``rendered``: when and by which command this report was made;
    ``paths``: the files written (empty until :func:`write_report`). :func:`run` also
    sets ``computed``, ``skipped`` and ``seconds``.
    """

    rows: list[dict[str, Any]]
    summaries: list[dict[str, Any]]
    comparisons: list[Comparison]
    variance: list[dict[str, Any]]
    statistics: dict[str, Any]
    runs: list[dict[str, Any]]
    rendered: dict[str, str]
    reference: list[dict[str, Any]] = field(default_factory=list)
    looks: dict[str, Any] | None = None  # a run --until answered: every look, replayed
    # the looks as computed (answering.History), for the next look of the same run to go
    # on from (make_report's ``resume``); not part of any file
    history: Any = field(default=None, repr=False, compare=False)
    paths: dict[str, Path] = field(default_factory=dict)
    computed: int = 0  # cells run now (ok or failed); set by run()
    cpu_seconds: float | None = None  # set by run_until: this process and its workers
    budget_stop: str | None = None  # set by run_until when --budget ended it
    skipped: int = 0  # cells already finished before this run
    seconds: float = 0.0

    @property
    def ok(self) -> list[dict[str, Any]]:
        """Rows of the cells that finished."""
        return ok_rows(self.rows)

    @property
    def failed(self) -> list[dict[str, Any]]:
        """Rows of the cells that raised (retried by the next run of the same scene)."""
        return failed_rows(self.rows)

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


def make_report(rows: Sequence[dict[str, Any]], *,
                reference: Iterable[dict[str, Any]] | None = None,
                contrasts: Sequence[str] = (), margin: float | None = None,
                users: Sequence[str] | None = None, rendered: str | None = None,
                primary: Sequence[str] = (), sequential: Design | None = None,
                resume: History | None = None,
                paired_test: PairedTestChoice = DEFAULT_CHOICE) -> Report:
    """The :class:`Report` of ``rows`` (every row of a folder, ok and failed, in the
    scene's order: failed cells are listed and left out of summaries and plots).

    ``reference``: published points to set beside ours (:func:`check_reference`; a
    mistake is refused here, before any file); ``contrasts``, ``margin`` (points) and
    ``primary`` (the contrasts of the confirmatory family): see
    :func:`tactbench.runner.analysis.comparisons.comparisons`; ``users``: the user of each
    dataset sample (by index), for per-user results; ``rendered``: how the report came
    to be, said in report.md beside the command line and the time; ``sequential``: the
    :class:`~tactbench.runner.execution.scene.Design` of a run ``--until answered``, whose
    looks are replayed from the rows (:func:`tactbench.runner.analysis.answering.replay`;
    ``resume``: an earlier report's ``history`` of the same run, whose looks are not
    computed again); ``paired_test``: the test every comparison's p and interval come
    from (:mod:`tactbench.runner.analysis.paired_tests`), recorded in ``statistics``
    where it is not the default.
    """
    rows = list(rows)
    reference = check_reference(reference)
    looks = history = None
    if sequential is not None and sequential.looks and primary:
        paired_test.check(None, sequential=True)  # the looks: one line, before any file
        history = replay(rows, seed_order=sequential.seed_order, looks=sequential.looks,
                         primary=primary, margin=margin, resume=resume)
        looks = history.as_dict()
        looks["budget"] = sequential.budget
        looks["train_cpu_seconds"] = training_cpu_seconds(rows)
        looks["runs_stored"] = len({int(r["seed"]) for r in ok_rows(rows)})
    comps = comparisons(rows, contrasts=contrasts, margin=margin, users=users, primary=primary,
                        paired_test=paired_test)
    if looks is not None:
        comps = [sequential_verdict(c, looks) if c.family == "primary" else c for c in comps]
    return Report(looks=looks, history=history,
        rows=rows, summaries=summarise(rows, users=users), comparisons=comps,
        variance=variance_decomposition(rows),
        statistics={"unit": "run (one split seed)", "contrasts": list(contrasts),
                    "margin": margin, "per_user": users is not None,
                    **({"primary": list(primary)} if primary else {}),
                    **({"paired_test": paired_test.name}
                       if paired_test.name != DEFAULT_PAIRED_TEST else {})},
        runs=computed_by(rows), reference=reference,
        rendered={"by": command_line(), "how": rendered or "from the rows of cells/",
                  "at": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")})


def sequential_verdict(c: Comparison, looks: dict[str, Any]) -> Comparison:
    """A primary comparison of a run ``--until answered`` with the verdict its looks
    reached: better, worse or equivalent where a look's boundary decided it, else
    unresolved with the looks' reason in the note. The fixed-design verdict at the last
    run count would ignore the looks before it (and overstate the evidence); the
    interval and p beside it stay the unadjusted ones, labelled so."""
    name = comparison_name(c)
    seen = [(lk["runs"], lk["comparisons"][name]) for lk in looks.get("looks", ())
            if name in lk["comparisons"]]
    if not seen or c.verdict == NOT_LEARNED:  # a run of its cells did not learn: no verdict
        return c
    runs, last = seen[-1]
    decided = (looks.get("decisions") or {}).get(name)
    if decided in DECIDED:
        return dataclasses.replace(c, verdict=decided, note=(
            f"group-sequential: decided at the look after {runs} runs, α spent over "
            f"{len(seen)} look(s)"))
    why = (f"futile after {runs} runs" + (f" ({last['why']})" if last.get("why") else "")
           if last["decision"] == FUTILE
           else f"no verdict in {len(seen)} look(s) up to {runs} runs ({last['why']})"
           if last.get("why")  # a boundary crossed below the minimum of evidence
           else f"no boundary crossed in {len(seen)} look(s) up to {runs} runs")
    return dataclasses.replace(c, verdict=UNRESOLVED, note=f"group-sequential: {why}")


def training_cpu_seconds(rows: Iterable[dict[str, Any]]) -> float | None:
    """The training CPU-seconds (every thread of the fitting process) summed over the
    ok rows that record it; None when none does (rows from before it was recorded)."""
    values = []
    for row in ok_rows(list(rows)):
        fits = row.get("fit")
        for fit in fits if isinstance(fits, list) else [fits]:
            value = fit.get("train_cpu_seconds") if isinstance(fit, dict) else None
            if isinstance(value, (int, float)) and value >= 0:
                values.append(float(value))
    return sum(values) if values else None


def computed_by(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The runs that computed ``rows``: ``{"command", "git", "cells"}`` for each distinct
    command line and git revision a row records (``run``), the earliest first. A command
    is shown as :func:`~tactbench.runner.execution.results.command_line` writes it (rows from
    before it kept the program's path: ``/src/tactbench/__main__.py run`` is
    ``tactbench run``)."""
    runs: dict[tuple, dict[str, Any]] = {}
    for row in sorted(rows, key=lambda r: (str(r.get("finished", "")), str(r.get("key")))):
        run = row.get("run") if isinstance(row.get("run"), dict) else {}
        command = run.get("command")
        try:
            command = command_line(shlex.split(command)) if isinstance(command, str) \
                else command
        except ValueError:  # unbalanced quotes: shown as recorded
            pass
        entry = runs.setdefault((str(command), str(run.get("git"))), {
            "command": command, "git": run.get("git"), "cells": 0})
        entry["cells"] += 1
    return list(runs.values())


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


def write_reports(out: str | Path, rows: Sequence[dict[str, Any]], *, plots: bool = True,
                  **options: Any) -> dict[str, Path]:
    """:func:`make_report` of ``rows`` (with its ``options``), written into ``out`` by
    :func:`write_report`; returns the paths written."""
    return write_report(out, make_report(rows, **options), plots=plots)


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

