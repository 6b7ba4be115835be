"""The primary family of a run: which comparisons ``--primary`` expands to over a grid's
cells, and what each is called — one place for the run
(:func:`tactbench.runner.analysis.comparisons.comparisons`), its looks
(:mod:`tactbench.runner.analysis.answering`) and the plan
(:mod:`tactbench.runner.forecasting`, through :mod:`tactbench.runner.analysis.forecast`),
so that they agree on the family by construction (issue 48: the plan forecast only a
question's first comparison, at α where the run used α/3)."""

from __future__ import annotations

from typing import Any, Iterable, Mapping, Sequence

from tactbench.runner.execution.questions import (FACTORS, contrast_pairs, parse_contrast,
                                                  spec_label, spec_labels)


def primary_family(cells: Sequence[Mapping[str, Any]], primary: Sequence[str]
                   ) -> list[tuple]:
    """The primary family ``primary`` (contrasts) expands to over ``cells`` (each a
    mapping of :data:`FACTORS`, in the run's order): (index of A, index of B, factor,
    value of A, value of B, family "primary") of each comparison, in the run's order.
    The one place the family is decided: the run (:func:`comparisons`) and the plan
    (:func:`tactbench.runner.forecasting.forecast`, through
    :func:`tactbench.runner.analysis.forecast._family`) both call it, so a question
    over three classifiers is three primaries in both, each at the family's level."""
    labels = spec_labels(c["classifier"] for c in cells)
    todo: list[tuple] = []
    for text in primary:
        a_side, b_side = parse_contrast(text)
        for i, j in contrast_pairs(text, list(cells)):
            differ = [f for f in FACTORS if cells[i][f] != cells[j][f]]
            if len(differ) == 1:  # shown as that factor's comparison, A and B as asked
                f = differ[0]
                todo.append((i, j, f, cells[i][f], cells[j][f], "primary"))
            else:
                todo.append((i, j, "contrast", side_label(cells[i], a_side, labels),
                             side_label(cells[j], b_side, labels), "primary"))
    return todo


def pair_where(cells: Sequence[Mapping[str, Any]], i: int, factor: str, value_a: Any
               ) -> dict[str, Any]:
    """The factors both cells of a pair share (a comparison's ``where``)."""
    named = set(parse_contrast_factors(factor, value_a))
    return {k: v for k, v in cells[i].items() if k != factor and k not in named}


def pair_name(a: Any, b: Any, where: Mapping[str, Any]) -> str:
    """A comparison's name in the looks and the plan: ``raw → farneback (L=5,
    small-cnn-lstm)``."""
    shared = ", ".join(f"{k}={v}" if k == "L" else str(v) for k, v in where.items())
    return f"{a} → {b}" + (f" ({shared})" if shared else "")


def side_label(cell: dict[str, Any], side: dict[str, str],
                labels: Mapping[str, str] | None = None) -> str:
    """``encoder=raw,L=6`` with the cell's own values (a classifier by its label in
    ``labels``, :func:`spec_labels`)."""
    return ",".join(f"{f}={spec_label(cell[f], labels) if f == 'classifier' else cell[f]}"
                    for f in side)


def parse_contrast_factors(factor: str, label: Any) -> list[str]:
    """The factors a comparison's ``a`` value sets: a contrast's (``encoder=raw,L=6``),
    or the one factor of a one-factor pair."""
    if factor != "contrast":
        return [factor]
    return [item.partition("=")[0] for item in str(label).split(",")]


def family_names(cells: Sequence[Mapping[str, Any]], primary: Sequence[str]
                 ) -> dict[str, list[str]]:
    """Each primary question of ``primary`` → the names (:func:`pair_name`) of the
    comparisons it expands to over ``cells`` (:func:`primary_family`): what a run's
    record says of its family before any cell is trained."""
    return {text: [pair_name(a, b, pair_where(cells, i, factor, a))
                   for i, _, factor, a, b, _ in primary_family(cells, [text])]
            for text in primary}


def grid_cells(cells: Iterable[Any]) -> list[dict[str, Any]]:
    """The distinct cells of a plan (objects with ``encoder``, ``classifier``, ``L``) as
    the mappings of :data:`FACTORS` the family is decided over, in the plan's order."""
    return [dict(zip(FACTORS, key)) for key in
            dict.fromkeys((c.encoder, c.classifier, c.L) for c in cells)]
