"""Result rows on disk: one JSON file per cell under ``OUT/cells``, written atomically.

A row is a cell's identity (see :mod:`tactbench.runner.planning`) plus what came of it:

- ``status: "ok"``: the cell trained and was tested; the row holds accuracy,
  per-class accuracy, the confusion matrix and the costs (see ``docs/runner.md``);
- ``status: "failed"``: the cell raised; the row holds ``error`` (``type``,
  ``message``, ``traceback``: the last frames, formatted) instead of results.

Rows written before ``status`` existed are finished rows (``"ok"``). A failed row is not
finished: the next run of the same scene retries it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterable

from tactbench.paths import atomic_write_text

OK = "ok"
FAILED = "failed"


def row_status(row: dict[str, Any]) -> str:
    """``"ok"`` or ``"failed"`` (rows from before the field existed are ``"ok"``)."""
    return row.get("status", OK)


def ok_rows(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of cells that finished: the ones accuracy tables are made of."""
    return [r for r in rows if row_status(r) == OK]


def failed_rows(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of cells that raised."""
    return [r for r in rows if row_status(r) == FAILED]


class ResultStore:
    """One JSON file per cell under ``OUT/cells``, written atomically."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.cells = self.out / "cells"

    def path(self, key: str) -> Path:
        """Where the row of cell ``key`` is (or will be) kept."""
        return self.cells / f"{key}.json"

    def get(self, key: str) -> dict[str, Any] | None:
        """The row of cell ``key``, ok or failed; None when there is none."""
        try:
            return json.loads(self.path(key).read_text())
        except FileNotFoundError:
            return None
        except (json.JSONDecodeError, UnicodeDecodeError):
            return None  # cannot happen with atomic writes; recompute if it does

    def finished(self, key: str) -> bool:
        """Whether cell ``key`` has an ``ok`` row (a failed one is retried)."""
        row = self.get(key)
        return row is not None and row_status(row) == OK

    def put(self, row: dict[str, Any]) -> None:
        atomic_write_text(self.path(row["key"]), json.dumps(row, indent=2))

    def rows(self, keys: Iterable[str]) -> list[dict[str, Any]]:
        """The stored rows of ``keys``, in that order, skipping cells without one."""
        return [row for key in keys if (row := self.get(key)) is not None]
