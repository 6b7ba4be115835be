"""``tactbench reproduce FOLDER``: train a run folder's stored cells again on this machine
and say, test prediction by test prediction, whether they come out the same.

The check a researcher makes before citing a colleague's table (docs/reliability.md,
"Numbers across machines"). A row's identity holds everything that changes its result,
the thread count and the CPU kernels included, and the row stores the scene that planned
it; planned again from that scene, a cell trained with the default pinned kernels has
the same key on any x86-64 machine with AVX2, and must give the same predictions. Each
chosen cell ends as one of:

- ``identical``: the same key and every test prediction the same (a row of an older
  format, without the folds and groups of its predictions, is judged by those it has);
- ``differs``: the same key, other predictions (how many, and the accuracy before and
  now): this machine does not keep the promise for this cell;
- ``other identity``: planned here, the cell has another identity, so another key, and
  the fields that differ are named (a row trained with a machine's native kernels,
  ``cpu_kernels: native AMD EPYC (avx2)``, is that kind of processor's alone; it is
  trained anyway, and its predictions compared);
- ``failed``: the cell failed here (its error is shown).

By default one cell of each encoder × classifier × L, the lowest seed's; ``--cell KEY``
names cells, ``--all`` takes every one. The cells are trained in a separate folder
(``--out``, else a temporary one, removed after), never in FOLDER, and share the
encoding cache with every other run. Exit status 0 when every chosen cell is identical,
1 otherwise.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import tempfile
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import click

from tactbench.cli import get_registry
from tactbench.datasets.loading import is_path_spec
from tactbench.errors import InputError
from tactbench.paths import check_output_folder
from tactbench.plugins import load_registry
from tactbench.runner import (IDENTITY_DEFAULTS, OK, PREDICTION_LISTS, UNTIL_ONLY, ResultStore,
                              Scene, digest, folder_record, identity_differences, ok_rows,
                              row_identity, row_scene, run)

#: The stored scene's fields a reproduction sets itself: one plain run of the chosen
#: cells, in its own folder, with no question asked of them.
#: ``rerun``: a cell already in ``--out`` (a reproduction of before) is trained again too.
PLAIN_RUN = {"until": None, "primary": None, "contrasts": None, "margin": None,
             "budget": None, "rerun": True, "save_models": False, "executor": "local",
             "scheduler": None}
#: The run folders a reproduction makes in ``--out``: ``part-<digest of its scene>``, so
#: that a later reproduction into the same ``--out`` (other ``--cell`` choices) trains
#: each grid in its own folder (``part1``, ``part2``, ...: the names of before).
PART_PREFIX = "part"
PART = re.compile(PART_PREFIX + r"(?:[1-9][0-9]*|-[0-9a-f]{12})")
IDENTICAL, DIFFERS, OTHER_IDENTITY, CELL_FAILED = ("identical", "differs", "other identity",
                                                   "failed")


def stored_rows(folder: str) -> list[dict[str, Any]]:
    """The sound ``ok`` rows of ``folder``'s cells, or one :class:`InputError` line."""
    store = ResultStore(folder)
    if not store.cells.is_dir():
        raise InputError(f"{folder} has no cells/ folder: not the --out of a "
                         f"`tactbench run`")
    rows = ok_rows(store.stored_rows())
    if not rows:
        raise InputError(f"{folder}/cells holds no finished cell to reproduce")
    return rows


def choose(rows: Sequence[dict[str, Any]], keys: Sequence[str],
           everything: bool) -> list[dict[str, Any]]:
    """The rows to train again: those of ``keys`` (a key or a unique prefix of one), every
    row with ``everything``, else the lowest seed's of each encoder × classifier × L."""
    if keys:
        chosen = []
        for key in keys:
            hits = [r for r in rows if str(r["key"]).startswith(key)]
            if len(hits) != 1:
                what = "no" if not hits else f"{len(hits)}"
                raise InputError(f"--cell {key}: {what} finished cell(s) of the folder "
                                 f"match (its keys: {', '.join(r['key'] for r in rows[:6])}"
                                 f"{', …' if len(rows) > 6 else ''})")
            chosen.append(hits[0])
        return list({r["key"]: r for r in chosen}.values())
    if everything:
        return list(rows)
    first: dict[tuple, dict[str, Any]] = {}
    for row in sorted(rows, key=lambda r: (r["seed"], r.get("init_seed") or 0)):
        first.setdefault((row["encoder"], row["classifier"], row["L"]), row)
    lowest = {r["key"] for r in first.values()}
    return [r for r in rows if r["key"] in lowest]


def scenes_for(rows: Sequence[dict[str, Any]], out: Path,
               workers: int | None) -> list[tuple[Scene, list[dict[str, Any]]]]:
    """Scenes that plan the cells of ``rows`` again, each with the rows it covers: rows of
    one stored scene and seed go in one scene where they are its whole grid (encoders ×
    classifiers × L), else one scene a row."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        stored = row_scene(row)
        if stored is None:
            raise InputError(f"cell {row['key']}: its row keeps no scene (written before "
                             f"rows stored one): it cannot be planned again")
        group = (json.dumps(stored, sort_keys=True), row["seed"], row.get("init_seed"))
        groups.setdefault(group, []).append(row)
    scenes = []
    for group in groups.values():
        grid = {(r["encoder"], r["classifier"], r["L"]) for r in group}
        axes = [sorted({c[i] for c in grid}, key=str) for i in range(3)]
        whole = len(grid) == len(axes[0]) * len(axes[1]) * len(axes[2])
        for part in ([group] if whole else [[r] for r in group]):
            scene = _scene(part, out / PART_PREFIX, workers)
            named = {k: v for k, v in asdict(scene).items() if k not in ("out", "workers")}
            folder = out / f"{PART_PREFIX}-{digest(named, 12)}"
            scenes.append((dataclasses.replace(scene, out=str(folder)), part))
    return scenes


def _scene(rows: Sequence[dict[str, Any]], out: Path, workers: int | None) -> Scene:
    stored = rows[0]["run"]["scene"]
    known = {f.name for f in fields(Scene)}
    # a plain run: the fields that mean something only with --until are left out
    values = {k: v for k, v in stored.items() if k in known and k not in UNTIL_ONLY}
    init = rows[0].get("init_seed")
    # the threads the row trained with (a scene of before kept None: "this machine's")
    values.update(PLAIN_RUN, out=str(out), workers=workers,
                  dataset=dataset_here(rows[0]),
                  threads=rows[0].get("threads") or 1,
                  encoders=_distinct(r["encoder"] for r in rows),
                  classifiers=_distinct(r["classifier"] for r in rows),
                  L=_distinct(r["L"] for r in rows), seeds=[rows[0]["seed"]],
                  init_seeds=None if init is None else [init])
    return Scene.of(values)


def dataset_here(row: dict[str, Any]) -> str:
    """The data set of ``row``'s stored scene as this process can read it: a registered
    data set's spec as it is; a relative path resolved against the folder its run was
    started in (``run.cwd``), else against this working folder; else one line saying
    exactly why it cannot be found."""
    spec = str(row["run"]["scene"].get("dataset", ""))
    if not is_path_spec(spec):
        return spec
    path = Path(spec).expanduser()
    started = (row.get("run") or {}).get("cwd")
    if path.is_absolute():
        if path.exists():
            return spec
        raise InputError(f"cell {row['key']}: its data set {spec} is not on this machine "
                         f"(no such file or folder); copy it there, or reproduce where it is")
    for base in ([Path(started)] if isinstance(started, str) else []) + [Path.cwd()]:
        if (base / path).exists():
            return str((base / path).resolve())
    where = (f"the folder its run was started in, {started}" if isinstance(started, str)
             else "the folder its run was started in, which the row does not record "
                  "(written before rows kept it)")
    raise InputError(f"cell {row['key']}: its data set {spec} is a path relative to "
                     f"{where}, and is found neither there nor from here ({Path.cwd()}); "
                     f"run reproduce from that folder")


def _distinct(values: Iterable[Any]) -> list[Any]:
    return list(dict.fromkeys(values))


def compare(old: dict[str, Any], new: dict[str, Any] | None,
            defaults: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """What training ``old``'s cell again gave: its outcome and the numbers behind it
    (``defaults``: what the folder's run record leaves out of an identity at its
    default, for :func:`identity_difference`)."""
    out: dict[str, Any] = {"key": old["key"], "encoder": old["encoder"],
                           "classifier": old["classifier"], "L": old["L"],
                           "seed": old["seed"], "accuracy_before": old["accuracy"]}
    if new is None:  # a bug: every planned cell leaves a row
        raise RuntimeError(f"cell {old['key']} was planned again but left no row")
    out["key_now"] = new["key"]
    if new.get("status") != OK:
        error = new.get("error") or {}
        return {**out, "outcome": CELL_FAILED,
                "error": f"{error.get('type', 'error')}: {error.get('message', '')}"}
    before, now = old["test_predictions"], new["test_predictions"]
    same = 0  # recordings tested in another order (another split) share no prediction
    if before["indices"] == now["indices"]:
        same = sum(a == b for a, b in zip(before["predictions"], now["predictions"]))
    out.update(accuracy_now=new["accuracy"], predictions=len(before["predictions"]),
               predictions_same=same)
    if new["key"] != old["key"]:
        return {**out, "outcome": OTHER_IDENTITY,
                "identity_differs": identity_difference(old, new, defaults)}
    return {**out, "outcome": IDENTICAL if same_predictions(before, now) else DIFFERS}


def same_predictions(before: dict[str, Any], now: dict[str, Any]) -> bool:
    """Whether two rows' ``test_predictions`` are the same, test recording by test
    recording, whatever format each row was stored in: the lists both hold
    (:data:`~tactbench.runner.execution.cell.PREDICTION_LISTS`; rows of before lack
    folds and groups) are compared, and indices, labels and predictions must be there."""
    needed = ("indices", "labels", "predictions")
    if any(k not in before or k not in now for k in needed):
        return False
    return all(list(before[k]) == list(now[k]) for k in PREDICTION_LISTS
               if k in before and k in now)


def identity_difference(old: dict[str, Any], new: dict[str, Any],
                        defaults: Mapping[str, Any] | None = None) -> list[str]:
    """``field: THERE there, HERE here`` for each identity field the two rows differ in
    (:func:`~tactbench.runner.execution.results.identity_differences`; a value at its
    default, 1 thread or the pinned AVX2 kernels, says so: ``defaults``, the folder's
    run record's, else those of this version)."""
    defaults = IDENTITY_DEFAULTS if defaults is None else defaults

    def shown(field: str, value: Any) -> str:
        default = field in defaults and value == defaults[field]
        return f"{value} (the default)" if default and value is not None else f"{value}"

    return [f"{field}: {shown(field, there)} there, {shown(field, here)} here"
            for field, there, here in identity_differences(old, row_identity(new))]


def reproduce(folder: str, *, keys: Sequence[str] = (), everything: bool = False,
              out: str | None = None, workers: int | None = None,
              progress: bool = True, registry=None) -> list[dict[str, Any]]:
    """Train the chosen cells of ``folder`` again (in ``out``, else a temporary folder
    removed after) and return one :func:`compare` result per cell."""
    if out:  # new, empty or an earlier reproduction's; never in FOLDER or the cache
        check_output_folder(out, inputs=[folder], ours=_is_part)
    stored = stored_rows(folder)
    rows = choose(stored, keys, everything)
    there = folder_record(folder, stored)  # what the folder's run resolved, stored with it
    # a check of stored cells, not results: no plugin's event hook (an MLflow export)
    # hears of them, nor of the temporary folder they are trained in
    registry = (registry or load_registry()).without_events()
    root = Path(out) if out else Path(tempfile.mkdtemp(prefix="tactbench-reproduce-"))
    try:
        results = []
        for scene, part in scenes_for(rows, root, workers):
            run(scene, registry=registry, progress=progress, plots=False)
            store = ResultStore(scene.out)
            made = store.stored_rows()
            here = folder_record(scene.out, made)  # what this machine resolved for them
            for row in part:
                new = store.get(row["key"]) or _same_cell(row, made)
                results.append({**compare(row, new, there.identity_defaults),
                                "compute_there": asdict(there.compute),
                                "compute_here": asdict(here.compute)})
        return results
    finally:
        if not out:
            shutil.rmtree(root, ignore_errors=True)


def _is_part(entry: Path) -> bool:
    """Whether ``entry`` of ``--out`` is a run folder a reproduction made (``partN``)."""
    return entry.is_dir() and PART.fullmatch(entry.name) is not None


def _same_cell(row: dict[str, Any], made: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """The row trained here for ``row``'s cell under another key: the same encoder,
    classifier, L and seed."""
    for new in made:
        if all(new.get(k) == row.get(k) for k in ("encoder", "classifier", "L", "seed",
                                                   "init_seed")):
            return new
    return None


def _line(r: dict[str, Any]) -> str:
    cell = f"{r['key']} {r['encoder']} / {r['classifier'].split(':')[0]} L={r['L']} " \
           f"seed {r['seed']}"
    if r["outcome"] == CELL_FAILED:
        return f"{cell}: failed here: {r['error']}"
    preds = f"{r['predictions_same']} of {r['predictions']} test predictions the same"
    acc = f"accuracy {100 * r['accuracy_before']:.2f} % there, {100 * r['accuracy_now']:.2f} % here"
    if r["outcome"] == IDENTICAL:
        return f"{cell}: identical ({preds}; {acc})"
    if r["outcome"] == DIFFERS:
        return f"{cell}: differs ({preds}; {acc})"
    return f"{cell}: other identity here ({'; '.join(r['identity_differs'])}): {preds}; {acc}"


@click.command("reproduce")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--cell", "keys", multiple=True, metavar="KEY",
              help="A cell to train again (its key, or a unique start of it); repeatable. "
                   "[default: the lowest seed's cell of each encoder × classifier × L]")
@click.option("--all", "everything", is_flag=True, help="Train every finished cell again.")
@click.option("--out", type=click.Path(file_okay=False), default=None,
              help="Where the cells are trained again: a new or empty folder, or an "
                   "earlier reproduction's. [default: a temporary folder, removed after]")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Cells at once. [default: cores, GPUs and memory allow]")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def reproduce_cmd(folder: str, keys: tuple[str, ...], everything: bool, out: str | None,
                  workers: int | None, as_json: bool) -> None:
    """Train a run folder's stored cells again here and compare every test prediction.

    FOLDER is the --out of a `tactbench run` (a colleague's, a committed report's). Each
    chosen cell is planned again from the scene its row stored and trained in another
    folder; the cell is identical (same key, every test prediction the same), differs
    (same key, other predictions), has another identity here (the fields that differ are
    named: threads, CPU kernels, ...) or failed. Exit status 0 when every cell is
    identical, 1 otherwise.
    """
    if keys and everything:
        raise InputError("--cell and --all: give one or the other")
    results = reproduce(folder, keys=keys, everything=everything, out=out,
                        workers=workers, progress=not as_json, registry=get_registry())
    if as_json:
        click.echo(json.dumps({"folder": folder, "cells": results}, indent=2))
    else:
        for r in results:
            click.echo(_line(r))
        same = sum(r["outcome"] == IDENTICAL for r in results)
        click.echo(f"{same} of {len(results)} cell(s) of {folder} identical on this machine")
    if any(r["outcome"] != IDENTICAL for r in results):
        click.get_current_context().exit(1)
