"""The plain records a run hands on: a comparison as values (:func:`comparison_record`),
a look of ``run --until answered`` (:func:`look_record`) and a whole run
(:func:`run_summary`).

These are what a plugin's event hooks receive (:mod:`tactbench.hookspecs`) and what an
export logs: dicts of JSON values only (text, numbers, booleans, None, lists and dicts of
them), made from the rows as stored and the analysis of them, never from a report's
objects. Their keys are a public promise: a key may be added, none removed or renamed.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

from tactbench.runner.analysis.comparisons import Comparison
from tactbench.runner.execution.questions import FACTORS, parse_contrast, spec_label
from tactbench.runner.execution.results import failed_rows, ok_rows

#: The fields of a comparison's record (:func:`comparison_record`), in order, with their
#: kinds (``cells_a`` and ``cells_b``: lists of cell keys): the columns of
#: :func:`~tactbench.runner.presentation.frames.comparisons_frame` too.
COMPARISON_KINDS = {
    "family": "text", "dataset": "text", "split": "text", "factor": "text", "a": "text",
    "b": "text", "encoder": "text", "classifier": "text", "L": "int",
    "difference": "float", "low": "float", "high": "float", "confidence": "float",
    "p": "float", "p_holm": "float", "verdict": "text", "runs": "int",
    "accuracy_a": "float", "accuracy_b": "float", "equivalence_margin": "float",
    "equivalence_p": "float", "equivalence_p_holm": "float", "family_size": "int",
    "method": "text", "note": "text", "cells_a": "keys", "cells_b": "keys"}


def comparison_record(c: Comparison, rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The fields of :data:`COMPARISON_KINDS` of ``c`` as plain values (``cells_a`` and
    ``cells_b`` found among ``rows``): a row of
    :func:`~tactbench.runner.presentation.frames.comparisons_frame`, and what a look's and
    a run's record hold for each comparison (what the MLflow plugin logs)."""
    record = {name: getattr(c, name, None) for name in COMPARISON_KINDS}
    record.update({f: c.where.get(f) for f in FACTORS})
    record["cells_a"], record["cells_b"] = compared_cells(c, rows)
    return record


def compared_cells(c: Comparison, rows: Sequence[dict[str, Any]]
                   ) -> tuple[list[str], list[str]]:
    """The keys of the ok cells (one per run) on side A and on side B of ``c``."""
    if c.factor == "contrast":
        sides = parse_contrast(f"{c.a}..{c.b}")
    else:
        sides = ({c.factor: c.a}, {c.factor: c.b})

    def keys(side: dict[str, Any]) -> list[str]:
        spec = {**c.where, **side}
        return sorted(str(r["key"]) for r in ok_rows(rows)
                      if r.get("split") == c.split and all(_same(f, r.get(f), v)
                                                           for f, v in spec.items()))

    return keys(sides[0]), keys(sides[1])


def _same(factor: str, value: Any, wanted: Any) -> bool:
    """Whether a row's ``factor`` is ``wanted`` (a classifier also by its short label)."""
    return str(value) == str(wanted) or (factor == "classifier"
                                         and spec_label(str(value)) == str(wanted))


def look_record(rows: Sequence[dict[str, Any]], comparisons: Sequence[Comparison],
                looks: Mapping[str, Any] | None, *,
                record: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """A look of ``run --until answered``, as ``look_finished`` receives it:

    ``look``
        the look's number (1 for the first), ``runs`` the runs it was made over;
    ``answered``
        whether every primary question is decided, ``stopped`` why the run stops or
        goes on (a sentence), ``decisions`` each closed primary question's decision;
    ``rows``
        every row of the folder as stored (results.json's ``rows[]``);
    ``comparisons``
        every comparison after the look (:func:`comparison_record` each);
    ``record``
        the run's resolved record
        (:meth:`~tactbench.runner.execution.record.RunRecord.to_json`: design, families,
        compute, workers, paired test), or None.
    """
    looks = dict(looks or {})
    made = looks.get("looks") or []
    return {"look": len(made), "runs": made[-1]["runs"] if made else 0,
            "answered": bool(looks.get("answered")), "stopped": looks.get("stopped"),
            "decisions": dict(looks.get("decisions") or {}),
            "rows": [dict(r) for r in rows],
            "comparisons": [comparison_record(c, rows) for c in comparisons],
            "record": None if record is None else dict(record)}


def run_summary(rows: Sequence[dict[str, Any]], comparisons: Sequence[Comparison], *,
                computed: int, skipped: int, seconds: float,
                looks: Mapping[str, Any] | None = None,
                budget_stop: str | None = None,
                record: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """A run that ended (plain, or every look of ``--until answered``), as
    ``run_finished`` receives it:

    ``rows``
        every row of the folder as stored, ok and failed (results.json's ``rows[]``);
    ``comparisons``
        every paired comparison (:func:`comparison_record` each);
    ``ok``, ``failed``
        the keys of the cells that finished and of those that raised;
    ``computed``, ``skipped``, ``seconds``
        cells this run computed, cells already stored, its wall seconds;
    ``until``
        for ``--until answered`` its last look (:func:`look_record` without ``rows``
        and ``comparisons``) and ``budget_stop``, why ``--budget`` ended it (or None);
        None for a plain run;
    ``record``
        the run's resolved record (as :func:`look_record`'s), or None.
    """
    summary = {"rows": [dict(r) for r in rows],
               "comparisons": [comparison_record(c, rows) for c in comparisons],
               "ok": [str(r["key"]) for r in ok_rows(rows)],
               "failed": [str(r["key"]) for r in failed_rows(rows)],
               "computed": int(computed), "skipped": int(skipped), "seconds": float(seconds),
               "until": None, "record": None if record is None else dict(record)}
    if looks is not None:
        last = look_record((), (), looks)
        summary["until"] = {**{k: v for k, v in last.items()
                               if k not in ("rows", "comparisons", "record")},
                            "budget_stop": budget_stop}
    return summary
