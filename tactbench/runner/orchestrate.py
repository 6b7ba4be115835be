"""``run(scene)``: plan, encode what is missing, run the unfinished cells, collect rows.

This module only orchestrates; each step lives in its own module (scene, plan, cache,
cell, executors, store, system).
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

from tactbench.runner.cache import EncodingCache, ensure_encodings
from tactbench.runner.cell import make_jobs
from tactbench.runner.executors import execute
from tactbench.runner.planning import Plan, plan
from tactbench.runner.scene import Scene
from tactbench.runner.store import ResultStore, failed_rows, ok_rows
from tactbench.runner.system import MemoryTracker, git_revision
from tactbench.ui import Progress


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


def run(scene: Scene, *, registry=None, progress: bool = True,
        cache: EncodingCache | None = None,
        on_row: Callable[[dict[str, Any]], None] | None = None) -> RunResult:
    """Run ``scene``: plan, encode what is missing, run unfinished cells, collect rows.

    ``registry`` (default: every installed plugin) is used for planning and by every
    cell, in every executor. A cell that raises is stored as a failed row and the others
    go on; ``on_row(row)`` is called with each row as it is stored.
    """
    start = time.perf_counter()
    memory = MemoryTracker()  # which of this process's steps sets its peak memory
    with Progress(enabled=progress) as bars:
        task = bars.add(f"check grid, load dataset {scene.dataset}", total=1)
        p = plan(scene, registry, progress=bars.callback(f"make dataset {scene.dataset}"))
        bars.update(task, 1)
        memory.step("plan (load the dataset)")
        store = ResultStore(scene.out)
        models = Path(scene.out) / "models" if scene.save_models else None
        pending = [c for c in p.cells if scene.rerun or not store.finished(c.key)
                   or (models and not (models / f"{c.key}.safetensors").exists())]
        folders = ensure_encodings(p, cache or EncodingCache(), pending, bars)
        memory.step("encode")
        jobs = make_jobs(p, pending, folders, models)
        run_meta = {"command": " ".join(sys.argv), "git": git_revision(),
                    "scene": asdict(scene)}

        def finish(row: dict[str, Any]) -> None:
            row["run"] = run_meta
            store.put(row)
            if on_row is not None:
                on_row(row)

        if jobs:
            execute(scene, jobs, finish, bars, memory)
    rows = store.rows(c.key for c in p.cells)
    return RunResult(p, rows, computed=len(pending), skipped=len(p.cells) - len(pending),
                     seconds=time.perf_counter() - start)
