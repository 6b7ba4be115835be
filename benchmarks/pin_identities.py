"""Give stored cells the computation they were trained with in their identity (issue 36).

    python benchmarks/pin_identities.py FOLDER [FOLDER ...]   (run folders or docs/)

A cell's identity now holds its torch thread count and its CPU kernels (see
:func:`tactbench.runner.execution.planning.compute_identity`), each left out at its default (1
thread, kernels pinned to AVX2). Rows trained before that recorded both facts (``threads``,
``machine``) but their keys did not: a row trained with 2 threads, or with the unpinned
kernels of its machine, would otherwise be taken for a pinned 1-thread cell. This gives
each such row the identity it was trained with — ``threads`` as it records, and
``cpu_kernels`` as its ``machine`` says (``native <cpu> (<isa>)`` for unpinned kernels,
``not recorded`` for rows older than the machine record) — under its new key, re-sealed;
the results are untouched. A row whose identity does not hash to its key is refused
(nothing is moved). Run ``tactbench report`` on each folder afterwards.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tactbench.kernels import DEFAULT_KERNELS, KERNEL_LEVELS, KERNEL_VARIABLES, KERNELS_ENV
from tactbench.paths import discard
from tactbench.runner import ResultStore, digest, row_identity


def old_identity(row: dict) -> dict:
    """The identity a row was keyed by before threads and kernels entered it
    (:func:`~tactbench.runner.execution.planning.row_identity` without them)."""
    return row_identity(row, compute=False)


def recorded_kernels(row: dict) -> str:
    """The CPU kernels a row's ``machine`` record says it computed with."""
    facts = row.get("machine")
    if not isinstance(facts, dict):
        return "not recorded"
    pinned = facts.get("pinned") or {}
    level = str(pinned.get(KERNELS_ENV, "")).lower()
    if level in KERNEL_LEVELS and all(
            pinned.get(name, "") == value
            for name, value in zip(KERNEL_VARIABLES, KERNEL_LEVELS[level][:-1])):
        return level
    isa = str(facts.get("cpu_kernels") or "unknown").lower()
    return f"native {facts.get('cpu') or 'unknown CPU'} ({isa})"


def new_identity(row: dict) -> dict:
    """``old_identity`` with the row's threads and kernels where not the defaults."""
    threads, kernels = int(row.get("threads") or 1), recorded_kernels(row)
    return {**old_identity(row), **({} if threads == 1 else {"threads": threads}),
            **({} if kernels == DEFAULT_KERNELS else {"cpu_kernels": kernels})}


def rekey(folder: Path) -> tuple[int, int]:
    """Re-key the rows of one run folder; (rows moved, rows kept)."""
    store = ResultStore(folder)
    rows = store.stored_rows()
    for row in rows:  # every row checked before any is moved
        if digest(old_identity(row)) != row["key"]:
            sys.exit(f"{folder}: row {row['key']} is not keyed by its identity; nothing moved")
    moved = 0
    for row in rows:
        identity = new_identity(row)
        key = digest(identity)
        if key == row["key"]:
            continue
        old = store.path(row["key"])
        store.put({**row, **identity, "key": key})
        discard(old)
        moved += 1
    return moved, len(rows) - moved


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path)
    args = parser.parse_args()
    for top in args.folders:
        for cells in sorted({p.parent for p in top.glob("**/cells/*.json")}):
            moved, kept = rekey(cells.parent)
            print(json.dumps({"folder": str(cells.parent), "moved": moved, "kept": kept}))


if __name__ == "__main__":
    main()
