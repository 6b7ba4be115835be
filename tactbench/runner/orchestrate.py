"""``run(scene)``: plan, encode what is missing, run the unfinished cells, report;
``run_until(scene)``: the same in batches of runs until the primary questions are
answered; ``render_folder(out)``: the report of a finished folder again, from its cells.

This module composes the runner's three rooms and does nothing else: execution
(:mod:`tactbench.runner.execution`: plan, cache, cells, the store of rows), analysis
(:mod:`tactbench.runner.analysis`: what the rows say, decided — the comparisons, the
looks of a sequential run and whether they answered it) and presentation
(:mod:`tactbench.runner.presentation`: the report, which only formats). Every function
ends the same way: every sound row of ``OUT/cells`` (the one store of a run folder) →
:func:`~tactbench.runner.analysis.report.analyse` →
:func:`~tactbench.runner.presentation.writers.render` → :func:`write_report`, so a run's
report and a re-rendered one are the same files. The loop of :func:`run_until` reads its
decisions (answered, failed, the looks to go on from) from the analysis, never from the
rendered report.
"""

from __future__ import annotations

import dataclasses
import logging
import resource
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from tactbench.contracts import SPLIT
from tactbench.data.splits import SplitData, draw_splits, split_design
from tactbench.datasets.loading import load_dataset
from tactbench.errors import InputError, MissingFileError, TactbenchError, require
from tactbench.events import hook_timeout
from tactbench.integrity import path_kind
from tactbench.machine import git_revision
from tactbench.paths import discard
from tactbench.plugins import load_registry
from tactbench.runner.analysis.answering import History, budget_stop, first_look_to_run
from tactbench.runner.analysis.family import family_names, grid_cells
from tactbench.runner.analysis.paired_tests import choose_paired_test
from tactbench.runner.analysis.records import look_record, run_summary
from tactbench.runner.analysis.report import Analysis, analyse
from tactbench.runner.execution.cache import (EncodingCache, check_room_runs,
                                              ensure_encodings)
from tactbench.runner.execution.cell import make_jobs, model_problem
from tactbench.runner.execution.record import (RunRecord, folder_record, resolve_compute,
                                               resolve_record, write_record)
from tactbench.runner.execution.estimate import packed
from tactbench.runner.execution.executors import execute
from tactbench.runner.execution.planning import (
    INDEPENDENT_RUNS,
    Plan,
    mixed_grids,
    plan_runs,
    row_key_problem,
    with_dataset,
)
from tactbench.runner.execution.results import (
    OUT_FILES,
    ResultStore,
    command_line,
    is_run_output,
    latest_scene,
    ok_rows,
)
from tactbench.runner.execution.scene import Scene
from tactbench.runner.execution.questions import check_contrasts
from tactbench.runner.execution.system import MemoryTracker
from tactbench.runner.presentation.frames import EXTRA as EXPORT_EXTRA, refresh_parquet
from tactbench.runner.presentation.writers import Report, render, write_report
from tactbench.ui import Progress

log = logging.getLogger("tactbench.runner")


def _model_is_sound(models: Path, p: Plan, cell) -> bool:
    """Whether the saved model of a finished cell is there and sound; a damaged one is
    reported in one line and removed (the cell is then computed again)."""
    path = models / f"{cell.key}.safetensors"
    if not (path.exists() or path.is_symlink()):
        return False
    problem = model_problem(path, p, cell)
    if problem is None:
        return True
    log.warning("tactbench: warning: saved model %s is damaged (%s); the cell is computed "
                "again", path, problem)
    discard(path)
    return False


def _pending(p: Plan, store: ResultStore, models: Path | None, progress) -> list:
    """The cells of ``p`` to compute: all with ``rerun``, else those without a sound
    stored row (or, saving models, without a sound model)."""
    stored = [c for c in p.cells if not p.scene.rerun
              and store.finished(c.key, p.identities[c.key])]
    if models and stored:  # a model's check needs the data set's classes
        p = with_dataset(p, progress=progress)
        stored = [c for c in stored if _model_is_sound(models, p, c)]
    done = {c.key for c in stored}
    return [c for c in p.cells if c.key not in done]


def run(scene: Scene, *, registry=None, progress: bool = True,
        cache: EncodingCache | None = None, plots: bool = True,
        on_row: Callable[[dict[str, Any]], None] | None = None) -> Report:
    """Run ``scene``: plan, encode what is missing, run unfinished cells, then write the
    folder's report (results.json, results.csv, report.md and, with ``plots``, the
    figures) from every row of ``OUT/cells`` and return it, with ``computed``,
    ``skipped`` and ``seconds`` set.

    ``registry`` (default: every installed plugin) is used for planning and by every
    cell, in every executor. A cell that raises is stored as a failed row and the others
    go on; ``on_row(row)`` is called with each row as it is stored, and so is every
    plugin's ``cell_finished`` hook; when the report is written, every plugin's
    ``run_finished`` hook is called with the run's summary
    (:func:`~tactbench.runner.analysis.records.run_summary`; :mod:`tactbench.hookspecs`).
    """
    registry = registry or load_registry()
    report, record = _batch(scene, registry=registry, progress=progress, cache=cache,
                            plots=plots, on_row=on_row)
    _finished(registry, report, record, scene.out)
    return report


def _finished(registry, report: Report, record: RunRecord, out: str | Path) -> None:
    """A run ended (a plain one, or every look of :func:`run_until`): each plugin's
    ``run_finished`` hook gets its summary, and the hooks are waited for."""
    analysis = report.analysis
    registry.notify("run_finished", out=Path(out), summary=run_summary(
        analysis.rows, analysis.comparisons, computed=report.computed,
        skipped=report.skipped, seconds=report.seconds, looks=analysis.looks,
        budget_stop=analysis.budget_stop, record=record.to_json()))
    registry.settle()  # the hooks' calls, each within its bound


def _batch(scene: Scene, *, registry, progress: bool, plots: bool,
           on_row: Callable[[dict[str, Any]], None] | None,
           cache: EncodingCache | None = None, resume: History | None = None,
           record: RunRecord | None = None, seeds: Sequence[int] | None = None,
           ) -> tuple[Report, RunRecord]:
    """:func:`run` but its ``run_finished`` event, and its record: one look's batch of
    :func:`run_until` (``seeds``: the look's; ``resume``: the ``history`` of the run's
    previous look, whose looks the analysis does not compute again; ``record``: the
    run's, made by its first batch and read by every later one, never made again)."""
    start = time.perf_counter()
    hook_timeout()  # a bad TACTBENCH_HOOK_TIMEOUT: one line before any work
    cache = cache or EncodingCache()  # an unusable cache folder: before any work
    memory = MemoryTracker()  # which of this process's steps sets its peak memory
    whole, scene = scene, (dataclasses.replace(scene, seeds=list(seeds))
                           if seeds is not None else scene)
    compute = record.compute if record is not None else resolve_compute(whole)
    # the lease: no prune or clear removes an entry this run uses while it lives
    with cache.lease(), Progress(enabled=progress) as bars:
        task = bars.add(f"check grid, load dataset {scene.dataset}", total=1)
        made = bars.callback(f"make dataset {scene.dataset}")
        plans = plan_runs(scene, registry, progress=made, compute=compute)
        paired = choose_paired_test(record.paired_test if record is not None
                                    else whole.paired_test, plans[0].registry)
        paired.check(planned_design(plans[0]), sequential=scene.until is not None)
        bars.update(task, 1)
        memory.step("plan (load the dataset)")
        store = ResultStore(scene.out)
        store.clean()
        identities = {k: v for p in plans for k, v in p.identities.items()}
        claim = store.claim(identities, identities)  # one grid per folder
        models = Path(scene.out) / "models" if scene.save_models else None
        todos = [(p, _pending(p, store, models, made)) for p in plans]
        check_room_runs(cache, todos)  # every run's data set, before any entry is written
        pending, jobs = [], []
        for p, todo in todos:  # one plan, or one per run where each run draws its data set
            if todo or p.dataset is not None:
                p = with_dataset(p, progress=made)
                jobs += make_jobs(p, todo, ensure_encodings(p, cache, todo, bars), models)
            pending += todo
        memory.step("encode")
        if record is None:  # made once, before the first cell, and stored with the run
            record = resolve_record(
                whole, plan=plans[0], rows=store.stored_rows(quiet=True),
                parent_peak_mb=memory.peak_mb, paired_test=paired.name, compute=compute,
                families=family_names(grid_cells(plans[0].cells), whole.design.primary))
            write_record(scene.out, record)
        run_meta = {"command": command_line(), "git": git_revision(),
                    "scene": asdict(scene),  # its relative paths are from cwd
                    "cwd": str(Path.cwd())}

        def finish(row: dict[str, Any]) -> None:
            row["run"] = run_meta
            row = store.put(row)  # as stored: a row too large to keep is a failed one
            # each plugin gets its own copy, on its own thread: no hook holds back the
            # next row or changes what another sees (tactbench.events)
            plans[0].registry.notify("cell_finished", row=row, out=Path(scene.out))
            if on_row is not None:
                on_row(row)

        if jobs:  # on the workers the record decided (cores, GPUs, memory: workers.py)
            execute(scene, jobs, finish, bars, memory, record.workers)
    claim.unlink(missing_ok=True)
    analysis = analyse(store.stored_rows(), contrasts=scene.contrasts or (),
                       margin=scene.margin,
                       users=known_users(p.dataset.users) if p.run_dataset is None else None,
                       primary=record.primary, sequential=record.design,
                       resume=resume, paired_test=paired)
    report = render(analysis, rendered="at the end of the run, from the rows of cells/")
    write_report(scene.out, report, plots=plots)
    report.paths.update(refresh_parquet(report, scene.out))  # never left stale
    report.computed, report.skipped = len(pending), len(identities) - len(pending)
    report.seconds = time.perf_counter() - start
    plans[0].registry.settle()  # the cell hooks' calls, each within its bound
    return report, record


def render_folder(out: str | Path, *, contrasts: Sequence[str] | None = None,
                  margin: float | None = None, plots: bool = True,
                  registry=None, primary: Sequence[str] | None = None,
                  write: bool = True, parquet: bool = False,
                  paired_test: str | None = None) -> Report:
    """The report of the run folder ``out`` again, from the rows of ``OUT/cells`` alone,
    written over its results.json, results.csv, report.md and figures; nothing is
    trained, and results.json is not read.

    ``contrasts``, ``margin``, ``primary`` and ``paired_test`` (statistics options,
    which change no cell) default to those of the run's record, stored with the folder
    (:func:`~tactbench.runner.execution.record.folder_record`; a folder from before
    records: the scene of its latest row), so that a report rendered again with no
    options is the run's own, but for the line saying when and by what. The
    per-user results need the user of each recording: the dataset is loaded (through
    ``registry``) and used when its content hash is the rows'; otherwise they are left
    out and report.md says why. With ``write=False`` nothing is written: the report of
    a folder read as it is (a notebook's, an export's; the folder may be read-only).
    With ``parquet`` cells.parquet and comparisons.parquet are written too; without it,
    those already there are written again (or removed where pandas or pyarrow is
    missing), never left stale (:func:`~tactbench.runner.presentation.frames.refresh_parquet`).
    """
    out = Path(out)
    if not out.is_dir():  # a file, a FIFO, a dangling link: said as what it is
        kind = path_kind(out)
        if kind is None:
            raise MissingFileError(f"run folder {out} does not exist")
        raise InputError(f"run folder {out} is {kind}, not a folder (give the --out of "
                         f"a `tactbench run`)")
    store = ResultStore(out)
    if not store.keys():
        raise InputError(f"run folder {out} holds no cell rows ({store.cells}/*.json): "
                         f"nothing to report; `tactbench run --out {out}` makes them")
    rows = _keyed_rows(store)
    if not rows:
        raise InputError(f"every cell row in {store.cells} is damaged (warnings above): "
                         f"nothing to report; `tactbench run --out {out}` computes them again")
    mixed = mixed_grids(rows)
    if mixed is not None:  # a run refuses such a folder (claim); its report would merge
        raise InputError(f"run folder {out} holds cells of two grids ({mixed}): a report "
                         f"would merge them as one; give each grid its own folder "
                         f"(nothing was written)")
    # files beside a run's own (a benchmark's notes) stay; of a run's names, only
    # a report.md tactbench did not write is not ours to replace
    foreign = [p.name for p in (out / name for name in OUT_FILES)
               if write and p.exists() and not is_run_output(p)]
    if foreign:
        raise InputError(f"run folder {out} holds a {foreign[0]} tactbench did not write; "
                         f"move it away first (nothing was written)")
    if write and parquet:  # a missing library: one line before any file is written
        require("pandas", EXPORT_EXTRA)
        require("pyarrow", EXPORT_EXTRA)
    record = folder_record(out, rows)  # the run's record, stored with it (or its rows')
    scene = record.scene
    contrasts = list(scene.get("contrasts") or ()) if contrasts is None else list(contrasts)
    margin = scene.get("margin") if margin is None else margin
    paired = choose_paired_test(paired_test or record.paired_test, registry)
    design = record.design
    primary = list(design.primary) if primary is None else list(primary)
    check_contrasts([*contrasts, *primary], [{f: r[f] for f in ("encoder", "classifier", "L")}
                                             for r in rows])
    users, missing = dataset_users(rows, registry, scene=scene)
    how = "re-rendered from the stored rows of cells/ (nothing trained)"
    report = render(analyse(rows, contrasts=contrasts, margin=margin, users=users,
                            primary=primary, sequential=design, paired_test=paired),
                    rendered=how + (f"; per-user results left out: {missing}"
                                    if missing else ""))
    if write:
        write_report(out, report, plots=plots)
        report.paths.update(refresh_parquet(report, out, write=parquet))
    return report


def make_report(rows: Sequence[dict[str, Any]], *,
                reference: Sequence[dict[str, Any]] | None = None,
                rendered: str | None = None, **options: Any) -> Report:
    """The :class:`~tactbench.runner.presentation.writers.Report` of ``rows``: their
    :func:`~tactbench.runner.analysis.report.analyse` (with its ``options``: contrasts,
    margin, users, primary, sequential, resume, paired_test) rendered
    (:func:`~tactbench.runner.presentation.writers.render`, with ``reference`` and
    ``rendered``); nothing is written."""
    return render(analyse(rows, **options), reference=reference, rendered=rendered)


def write_reports(out: str | Path, rows: Sequence[dict[str, Any]], *, plots: bool = True,
                  **options: Any) -> dict[str, Path]:
    """:func:`make_report` of ``rows`` (with its ``options``), written into ``out`` by
    :func:`write_report`; returns the paths written."""
    return write_report(out, make_report(rows, **options), plots=plots)


def planned_design(p: Plan) -> str:
    """The design of the runs ``p`` plans, as their rows will record it (what a paired
    test is checked against before any training): ``independent`` where every run draws
    its own data set, else the split's declared design, or for an undeclared one the
    reading of its first draw (:func:`~tactbench.data.splits.split_design`)."""
    if p.run_dataset is not None:
        return "independent"
    declared = SPLIT.get(p.split, "design")
    if declared is not None or p.dataset is None:
        return declared or "resampled"
    data = SplitData.of(p.dataset, test_per_class=p.scene.test_per_class)
    return split_design(p.split, draw_splits(p.split, data, p.scene.seeds[0], "split"))


def _keyed_rows(store: ResultStore) -> list[dict[str, Any]]:
    """The sound rows of ``store`` whose identity hashes to their key; a row copied
    under another name (its checksum re-sealed) is named in one warning line and left
    out, as a damaged row is, so that no cell counts twice."""
    rows = []
    for row in store.stored_rows():
        problem = row_key_problem(row)
        if problem is None:
            rows.append(row)
        else:
            log.warning("tactbench: warning: cell row %s %s; the report leaves it out",
                        store.path(str(row.get("key"))), problem)
    return rows


def dataset_users(rows: Sequence[dict[str, Any]], registry=None, *,
                  scene: Mapping[str, Any] | None = None,
                  ) -> tuple[list[str] | None, str | None]:
    """``(the user of every sample of the rows' dataset, None)``, loading the dataset
    the run's ``scene`` names (its record's; None: the scene of the rows' latest row);
    ``(None, why)`` when it cannot be loaded here or is not the one the rows were
    computed on (another content hash)."""
    spec = (latest_scene(rows) if scene is None else scene).get("dataset")
    done = ok_rows(rows) or list(rows)
    digest = done[0].get("dataset_hash") if done else None
    if not isinstance(spec, str) or not digest:
        return None, "the rows do not name their dataset"
    if any(r.get(INDEPENDENT_RUNS) for r in done):
        return None, "each run drew its own people, so no user is in more than one run"
    try:
        data = load_dataset(spec, registry=registry)
    except TactbenchError as exc:
        log.warning("tactbench: warning: dataset %s cannot be loaded here (%s); the report "
                    "leaves out per-user results", spec, exc)
        return None, f"dataset `{spec}` cannot be loaded here"
    if data.content_hash() != digest:
        log.warning("tactbench: warning: dataset %s is not the one the rows were computed "
                    "on (content hash %s, the rows' %s); the report leaves out per-user "
                    "results", spec, data.content_hash()[:16], digest[:16])
        return None, f"dataset `{spec}` here is not the rows' (another content hash)"
    users = known_users(data.users)
    return (users, None) if users is not None else (None, "the dataset has no user ids")


def known_users(users: Sequence[str]) -> list[str] | None:
    """The user of every sample, or None where the dataset names no user (recordings
    without user ids: a per-user table would show one user, "")."""
    return list(users) if any(users) else None


def next_batch_seconds(rows: Sequence[dict[str, Any]], seeds: int, workers: int) -> float:
    """Seconds the next ``seeds`` runs' cells take, from the stored ``rows`` (each cell's
    training and prediction time), packed onto ``workers``: a resumed run's look, whose
    cells were all stored, took no time and says nothing of the next."""
    per_seed = len({(r["encoder"], r["classifier"], r["L"]) for r in rows})
    times = sorted(float(r.get("train_s") or 0.0) + float(r.get("inference_ms_per_sequence")
                                                          or 0.0) * int(r.get("n_test") or 0)
                   / 1e3 for r in rows)
    if not times:
        return 0.0
    return packed([times[len(times) // 2]] * (per_seed * seeds), workers)


def run_until(scene, *, registry=None, progress: bool = True, plots: bool = True,
              on_look=None, on_row=None):
    """Run ``scene`` (with ``until="answered"``) look by look: the first
    :data:`FIRST_LOOK` seeds of the scene's seed order (:attr:`Scene.design`), then
    ``look_every`` more each time, each batch an ordinary :func:`run` (resumable: cells
    already stored are reused, any executor), until every primary comparison is decided,
    ``max_runs`` is reached, or the next batch would start past ``budget``. Returns the
    last :class:`~tactbench.runner.presentation.writers.Report` (its ``looks``: every look, replayed
    from the rows); ``on_look(report)`` is called after each look, and so is every
    plugin's ``look_finished`` hook, with the look's record
    (:func:`~tactbench.runner.analysis.records.look_record`); ``on_row``: see :func:`run`.
    Ctrl-C between cells keeps every finished cell. The report's ``computed``,
    ``skipped`` and ``seconds`` are this call's, over all its looks; every plugin's
    ``run_finished`` hook is called once, after the last look (as by :func:`run`)."""
    registry = registry or load_registry()
    design = scene.design  # the design the run's record holds (design_of, once)
    stored = {int(r["seed"]) for r in ResultStore(scene.out).stored_rows()}
    start = time.perf_counter()
    report, record, computed = None, None, 0
    for k in range(first_look_to_run(stored, design.seed_order, design.looks),
                   len(design.looks)):
        t0 = time.perf_counter()
        report, record = _batch(
            scene, seeds=design.seed_order[:design.looks[k]], record=record,
            registry=registry, progress=progress, plots=plots, on_row=on_row,
            resume=report.analysis.history if report is not None else None)
        design = record.design  # from here on, every look reads the run's record
        looks = design.looks
        analysis: Analysis = report.analysis  # the decisions: analysis's, not the report's
        computed += report.computed
        if k + 1 < len(looks) and not (analysis.failed or analysis.answered):
            # a look of stored cells took ~0 s: what the next one costs, from the rows
            batch = max(time.perf_counter() - t0,
                        next_batch_seconds(analysis.ok, looks[k + 1] - looks[k],
                                           record.workers.count))
            report.analysis = analysis = dataclasses.replace(
                analysis, budget_stop=budget_stop(record.design,
                                                  time.perf_counter() - start, batch))
        if on_look is not None:
            on_look(report)
        registry.notify("look_finished", out=Path(scene.out), look=look_record(
            analysis.rows, analysis.comparisons, analysis.looks, record=record.to_json()))
        registry.settle()
        if analysis.failed or analysis.answered or analysis.budget_stop:
            break
    # what this command did over all its looks, not its last look's batch alone: a
    # look's run counts the cells of the looks before it as already done
    report.skipped -= computed - report.computed
    report.computed, report.seconds = computed, time.perf_counter() - start
    usage = [resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                 resource.RUSAGE_CHILDREN)]
    report.cpu_seconds = sum(u.ru_utime + u.ru_stime for u in usage)
    _finished(registry, report, record, scene.out)
    return report
