"""Give stored cells the computation they were trained with in their identity (issue 36).

    python benchmarks/pin_identities.py FOLDER [FOLDER ...]   (run folders or docs/)

A cell's identity now holds its torch thread count, its CPU kernels and its device kind
(see :func:`tactbench.runner.execution.identity.compute_identity`), each left out at its
default (1 thread, kernels pinned to AVX2, the CPU). Rows trained before that recorded
these facts (``threads``, ``machine``, ``device``) but their keys did not: a row trained
with 2 threads, with the unpinned kernels of its machine, or on a GPU, would otherwise be
taken for a pinned 1-thread CPU cell. This gives each such row the identity it was
trained with, under its new key, re-sealed; the results are untouched. The rule is the
package's (:func:`tactbench.runner.execution.identity.migrated_row`, tested there); this
script only walks the folders. A row whose identity does not hash to its key is refused
(nothing is moved). Run ``tactbench report`` on each folder afterwards.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tactbench.paths import discard
from tactbench.runner import ResultStore, migrated_row


def rekey(folder: Path) -> tuple[int, int]:
    """Re-key the rows of one run folder (:func:`tactbench.runner.migrated_row`, the
    package's migration); (rows moved, rows kept)."""
    store = ResultStore(folder)
    rows = store.stored_rows()
    try:  # every row checked before any is moved
        moving = [(row["key"], new) for row in rows if (new := migrated_row(row)) is not None]
    except ValueError as exc:
        sys.exit(f"{folder}: {exc}; nothing moved")
    for old, row in moving:
        store.put(row)
        discard(store.path(old))
    return len(moving), len(rows) - len(moving)


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
