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
:func:`run_until` and :func:`render_folder`.
"""

from tactbench.machine import git_revision
from tactbench.paths import atomic_write_text  # noqa: F401  (reports imported it from here)
from tactbench.runner.execution.cache import EncodingCache, ensure_encodings
from tactbench.runner.execution.cell import CellJob, failed_row, make_jobs, run_cell
from tactbench.runner.execution.entries import load_encoding
from tactbench.runner.presentation.frames import cells_frame, comparisons_frame, write_parquet
from tactbench.runner.orchestrate import render_folder, run, run_until
from tactbench.runner.execution.planning import ROW_SCHEMA, Cell, Plan, plan
from tactbench.runner.execution.results import (FAILED, OK, ResultStore, failed_rows, ok_rows,
                                                row_status)
from tactbench.runner.execution.scene import EXECUTORS, Scene, load_scene_file, parse_lengths
from tactbench.runner.presentation.writers import Report

__all__ = [
    "Scene", "EXECUTORS", "load_scene_file", "parse_lengths",
    "plan", "Plan", "Cell", "ROW_SCHEMA",
    "EncodingCache", "ensure_encodings", "load_encoding",
    "CellJob", "make_jobs", "run_cell", "failed_row",
    "ResultStore", "OK", "FAILED", "row_status", "ok_rows", "failed_rows",
    "run", "run_until", "render_folder", "Report", "git_revision",
    "cells_frame", "comparisons_frame", "write_parquet",
]
