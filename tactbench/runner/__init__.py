"""The benchmark runner: a grid of cells, cached encodings, resumable results.

A *scene* (:class:`Scene`) names a dataset, encoders, classifiers, window lengths L,
seeds, a split and a profile. :func:`plan` checks it and expands it into *cells*, one
per (encoder, classifier, L, seed); each cell trains one classifier and writes one result
row. :func:`run` does the whole thing and returns the :class:`Report` it wrote (the
report of ``tactbench run``); :func:`render_folder` makes a finished folder's report
again (``tactbench report``), or with ``write=False`` reads it as it is. In a notebook,
:func:`cells_frame` and :func:`comparisons_frame` make pandas data frames of a report
(one row per cell; one per paired comparison) and :func:`write_parquet` writes both as
Parquet (the extra ``tactbench[export]``):

.. code-block:: python

    from tactbench.runner import Scene, render_folder, run

    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1",
                  encoders=["raw", "frame-diff"], classifiers=["logreg:max_iter=50"],
                  L=[3], seeds=[0, 1, 2], pixel_mm=10, test_per_class=1, out="runs/demo")
    report = run(scene, progress=False, plots=False)  # report.md etc. in runs/demo
    for s in report.summaries:  # one per encoder × classifier × L, over the seeds
        print(s["encoder"], f"{100 * s['accuracy_mean']:.1f} % over seeds {s['seeds']}")
    print(len(report.comparisons), "paired comparison(s);", len(report.failed), "failed")
    table = report.table()  # the rows as a table: one dict per cell, results.csv's columns
    assert len(table) == 6 and {"encoder", "seed", "accuracy", "train_s"} <= set(table[0])
    again = render_folder("runs/demo", margin=2, plots=False)  # nothing trained
    assert again.rows == report.rows and again.statistics["margin"] == 2

    # later, in a notebook: load the folder (nothing written), tables, a figure
    from tactbench.runner import cells_frame, comparisons_frame

    folder = render_folder("runs/demo", write=False)
    cells = cells_frame(folder)  # pandas: one row per cell, typed columns
    pairs = comparisons_frame(folder)  # one row per comparison: B − A, interval, p, verdict
    print(pairs[["a", "b", "difference", "low", "high", "p_holm", "verdict", "runs"]])
    by_encoder = cells.groupby("encoder")["accuracy"].agg(["mean", "std"])
    ax = by_encoder.plot.bar(y="mean", yerr="std", legend=False, ylabel="accuracy")
    ax.figure.savefig("accuracy.png")

Nothing is computed twice:

- encoded datasets are cached on disk (:class:`EncodingCache`), keyed by the
  dataset's content hash, the imaging parameters and the encoder's name, options and
  version, so each encoding is computed once across runs;
- each finished cell is written at once, atomically, to ``OUT/cells/<key>.json``
  (:class:`ResultStore`); running the same scene again skips finished cells, and a
  run killed mid-cell loses only that cell. ``OUT/cells`` is the one store of a run
  folder: results.json, results.csv and report.md are rendered from it, never read back
  (:func:`render_folder` renders them again, training nothing).

A cell that raises is stored as a *failed* row (error type, message, last traceback
frames) and the rest of the grid goes on; the next run retries it.

Cells run side by side in worker processes, one per core at one torch thread each (the
default), in turn (``workers=1``), or on a ``dask.distributed`` cluster
(``executor="dask"``). A cell's identity holds everything that changes its result,
the torch threads and the CPU kernels included (pinned to AVX2 by default, see
:mod:`tactbench.kernels`): the same identity gives the same predictions, bit for bit, on
any x86-64 machine with AVX2, in any executor, whatever runs beside it
(docs/reliability.md, "Numbers across machines").

Worker processes are spawned, and a spawned worker imports the main module again. A
script that calls ``run`` at its top level without ``if __name__ == "__main__":``, or one
read from standard input (``python - < script.py``), would run again in every worker (or
cannot be read again): there the cells run one at a time in the calling process, said in
one warning line naming the fix; a notebook, ``python -c`` and a guarded script get
workers (but for cells using something defined in the notebook itself, or that does not
pickle, which a worker cannot receive: those run in the calling process too, said so). Workers that cannot start, or one that dies while cells run (killed for
memory), stop the run with a :class:`~tactbench.errors.WorkerError` naming the cause and
the fix (``workers=1``, fewer workers); the cells finished before are stored, and a run
again computes the others.

The runner is three rooms, the arrows one way (``tests/test_architecture.py``):
:mod:`tactbench.runner.execution` (scene, plan, cache, cells, executors, the store of
rows), :mod:`tactbench.runner.analysis` (summaries, statistics, comparisons, the
sequential looks; it reads execution's records) and :mod:`tactbench.runner.presentation`
(tables, figures, report files, data frames; it reads both). Beside them,
:mod:`~tactbench.runner.orchestrate` composes the three into :func:`run`,
:func:`run_until` and :func:`render_folder`, and :mod:`~tactbench.runner.forecasting`
composes execution and analysis into :func:`forecast` (``tactbench plan``).

This package is the runner's one public face: the names below (``__all__``) are what
the commands, the benchmark scripts, plugins and notebooks use, and the only runner
names they import (``tests/test_architecture.py`` fails on an import of a room's module
from outside the runner), so the rooms can be rearranged behind them. What an event
hook receives is a record of plain values, documented with the hooks
(:mod:`tactbench.hookspecs`) and below: a cell's row as stored, a look's record
(:func:`look_record`) and a run's summary (:func:`run_summary`), their comparisons each a
:func:`comparison_record`.
"""

from tactbench.machine import git_revision
from tactbench.paths import atomic_write_text  # noqa: F401  (reports imported it from here)
from tactbench.runner.analysis.comparisons import Comparison, comparisons, plain_t
from tactbench.runner.analysis.forecast import points
from tactbench.runner.analysis.paired_tests import (DEFAULT_PAIRED_TEST, CorrectedT,
                                                    PairedTestChoice, choose_paired_test)
from tactbench.runner.analysis.power import detectable_effect, power
from tactbench.runner.analysis.family_paths import family_forecast
from tactbench.runner.analysis.records import comparison_record, look_record, run_summary
from tactbench.runner.analysis.report import Analysis, analyse, training_cpu_seconds
from tactbench.runner.analysis.sequential import (DECIDED_CODES, OUTCOMES_FUTILE, FamilyState,
                                                  family_look, procedure, simulate_paths)
from tactbench.runner.analysis.statistics import (A_BETTER, B_BETTER, DECIDED, EQUIVALENT,
                                                  corrected_t, holm, tost_p, verdict)
from tactbench.runner.analysis.summaries import failed_cells
from tactbench.runner.execution.cache import KEEP_RECENT_S, EncodingCache, ensure_encodings
from tactbench.runner.execution.cell import (PREDICTION_LISTS, CellJob, failed_row, make_jobs,
                                             run_cell)
from tactbench.runner.execution.entries import load_encoding
from tactbench.runner.execution.identity import migrated_row
from tactbench.runner.execution.learning import cell_learning, pooled_p, row_evidence, within_noise
from tactbench.runner.execution.planning import (ROW_SCHEMA, Cell, Plan, digest, grid_identity,
                                                 plan, row_identity)
from tactbench.runner.execution.questions import short_name
from tactbench.runner.execution.results import (FAILED, IDENTITY_DEFAULTS, OK, ResultStore,
                                                failed_rows, identity_differences, ok_rows,
                                                row_scene, row_status)
from tactbench.runner.execution.scene import (DEFAULT_PRIMARY, EXECUTORS, FIRST_LOOK,
                                              INPUT_KINDS, UNTIL, UNTIL_ONLY, Scene,
                                              parse_duration, parse_lengths, parse_seeds,
                                              show_duration)
from tactbench.runner.execution.record import (RECORD_FILE, Compute, RunRecord, folder_record,
                                               read_record)
from tactbench.runner.execution.scene_files import load_scene_file
from tactbench.runner.execution.workers import Workers, run_workers
from tactbench.runner.forecasting import forecast
from tactbench.runner.orchestrate import make_report, render_folder, run, run_until
from tactbench.runner.presentation.frames import (EXTRA as EXPORT_EXTRA, cells_frame,
                                                  comparisons_frame, write_parquet)
from tactbench.runner.presentation.plots import check_reference
from tactbench.runner.presentation.tables import (answer_text, comparisons_markdown, labels_for,
                                                  looks_markdown, markdown_table,
                                                  print_comparisons, print_table, verdict_text)
from tactbench.runner.presentation.words import answer_brief, finding_text, percent
from tactbench.runner.presentation.writers import Report, flat_rows, render, write_report

__all__ = [
    # a run: its scene, its plan, running it, its report again
    "Scene", "EXECUTORS", "UNTIL", "UNTIL_ONLY", "FIRST_LOOK", "INPUT_KINDS", "DEFAULT_PRIMARY",
    "load_scene_file", "parse_lengths", "parse_seeds", "parse_duration", "show_duration",
    "plan", "Plan", "Cell", "ROW_SCHEMA", "forecast", "points",
    "EncodingCache", "KEEP_RECENT_S", "ensure_encodings", "load_encoding",
    "CellJob", "make_jobs", "run_cell", "failed_row", "PREDICTION_LISTS",
    "run", "run_until", "render_folder", "Report", "git_revision", "Workers", "run_workers",
    # the resolved record of a run, stored with it (OUT/run-record.json)
    "RunRecord", "Compute", "RECORD_FILE", "read_record", "folder_record",
    # a folder's rows analysed (decided), then rendered (said): make_report does both
    "Analysis", "analyse", "render", "make_report",
    # the rows: the store, a row's status, identity and learning
    "ResultStore", "OK", "FAILED", "row_status", "ok_rows", "failed_rows", "failed_cells",
    "digest", "row_identity", "grid_identity", "IDENTITY_DEFAULTS", "identity_differences",
    "migrated_row",
    "row_scene", "cell_learning", "row_evidence", "pooled_p", "within_noise",
    # the statistics: comparisons, their verdicts, power and the sequential looks
    "Comparison", "comparisons", "plain_t", "corrected_t", "A_BETTER", "B_BETTER",
    "EQUIVALENT", "DECIDED", "power", "detectable_effect", "FamilyState", "family_look",
    "simulate_paths", "OUTCOMES_FUTILE", "DECIDED_CODES",
    "procedure", "family_forecast", "holm", "tost_p", "verdict",
    "CorrectedT", "PairedTestChoice", "choose_paired_test", "DEFAULT_PAIRED_TEST",
    # what a report shows: names, words, tables, files, data frames
    "short_name", "labels_for", "verdict_text", "answer_text", "finding_text", "answer_brief",
    "percent", "markdown_table",
    "comparisons_markdown", "looks_markdown", "print_table", "print_comparisons",
    "write_report", "check_reference", "flat_rows", "training_cpu_seconds",
    "cells_frame", "comparisons_frame", "write_parquet", "EXPORT_EXTRA",
    # what event hooks receive: plain records of a comparison, a look, a run
    "comparison_record", "look_record", "run_summary",
]
