"""``run(scene)``: plan, encode what is missing, run the unfinished cells, collect rows.

This module only orchestrates; each step lives in its own module (scene, plan, cache,
cell, executors, store, system).
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

from tactbench.machine import git_revision
from tactbench.paths import discard
from tactbench.runner.cache import EncodingCache, ensure_encodings
from tactbench.runner.cell import make_jobs, model_problem
from tactbench.runner.executors import execute
from tactbench.runner.planning import Plan, plan
from tactbench.runner.scene import Scene
from tactbench.runner.results import REPORT_JSON, ResultStore, failed_rows, ok_rows
from tactbench.runner.system import MemoryTracker
from tactbench.ui import Progress

log = logging.getLogger("tactbench.runner")


@dataclass
class RunResult:
    """What a run left: every stored row of the plan's cells, ok and failed."""

    plan: Plan
    rows: list[dict[str, Any]]  # in the plan's cell order
    computed: int  # cells run now (ok or failed)
    skipped: int  # cells already finished before this run
    seconds: float

    @property
    def ok(self) -> list[dict[str, Any]]:
        """Rows of the cells that finished."""
        return ok_rows(self.rows)

    @property
    def failed(self) -> list[dict[str, Any]]:
        """Rows of the cells that raised (retried by the next run of the same scene)."""
        return failed_rows(self.rows)


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


def run(scene: Scene, *, registry=None, progress: bool = True,
        cache: EncodingCache | None = None,
        on_row: Callable[[dict[str, Any]], None] | None = None) -> RunResult:
    """Run ``scene``: plan, encode what is missing, run unfinished cells, collect rows.

    ``registry`` (default: every installed plugin) is used for planning and by every
    cell, in every executor. A cell that raises is stored as a failed row and the others
    go on; ``on_row(row)`` is called with each row as it is stored.
    """
    start = time.perf_counter()
    cache = cache or EncodingCache()  # an unusable cache folder: before any work
    memory = MemoryTracker()  # which of this process's steps sets its peak memory
    with Progress(enabled=progress) as bars:
        task = bars.add(f"check grid, load dataset {scene.dataset}", total=1)
        p = plan(scene, registry, progress=bars.callback(f"make dataset {scene.dataset}"))
        bars.update(task, 1)
        memory.step("plan (load the dataset)")
        store = ResultStore(scene.out)
        store.clean()
        claim = store.claim((c.key for c in p.cells), p.identities)  # one grid per folder
        if not scene.rerun:  # rows results.json keeps and cells/ lacks (git ignores it)
            restored = store.restore(p.identities)
            if restored:
                log.warning("tactbench: %d cell row(s) put back into %s from %s "
                            "(verified); not computed again", len(restored), store.cells,
                            store.out / REPORT_JSON)
        models = Path(scene.out) / "models" if scene.save_models else None
        pending = [c for c in p.cells if scene.rerun
                   or not store.finished(c.key, p.identities[c.key])
                   or (models and not _model_is_sound(models, p, c))]
        folders = ensure_encodings(p, cache, pending, bars)
        memory.step("encode")
        jobs = make_jobs(p, pending, folders, models)
        run_meta = {"command": " ".join(sys.argv), "git": git_revision(),
                    "scene": asdict(scene)}

        def finish(row: dict[str, Any]) -> None:
            row["run"] = run_meta
            row = store.put(row)  # as stored: a row too large to keep is a failed one
            if on_row is not None:
                on_row(row)

        if jobs:
            execute(scene, jobs, finish, bars, memory)
    rows = store.rows(c.key for c in p.cells)
    claim.unlink(missing_ok=True)
    return RunResult(p, rows, computed=len(pending), skipped=len(p.cells) - len(pending),
                     seconds=time.perf_counter() - start)
