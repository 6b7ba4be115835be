"""How the tables mark a cell whose model did not learn: :data:`MARK` after its accuracy
(:func:`accuracy_mark`) and the lines under the table that explain it
(:func:`learning_legend`).

Whether a cell learned is decided in execution (:mod:`tactbench.runner.execution.learning`:
the rule, and each summary's ``learning`` field); only how that is shown lives here.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

from tactbench.runner.execution.learning import (LEARNING_FIELD, NOISE_ALPHA, TRAIN_KAPPA_MIN,
                                                 runs_text)

#: The mark of a flagged cell's accuracy in the tables.
MARK = "†"


def accuracy_mark(summary: Mapping[str, Any]) -> str:
    """:data:`MARK` after a summary's accuracy where the cell did not learn."""
    return f" {MARK}" if summary.get(LEARNING_FIELD) else ""


def learning_legend(summaries: Sequence[Mapping[str, Any]],
                    label: Callable[[Any], str]) -> list[str]:
    """The lines under a table of ``summaries`` explaining :data:`MARK` (none without
    one); ``label(summary)`` names a cell."""
    marked = [s for s in summaries if s.get(LEARNING_FIELD)]
    if not marked:
        return []
    lines = [f"{MARK} The model did not learn or did not transfer, judged over its runs "
             f"together: its training accuracy is near guessing (κ below "
             f"{TRAIN_KAPPA_MIN:g}), or its test recordings of all runs pooled cannot be told "
             f"from guessing (1/k or the majority class; one-sided exact test at "
             f"{NOISE_ALPHA:g}); no comparison with the cell gets a verdict "
             f"(docs/statistics.md)."]
    for s in marked:
        runs = "; ".join(f"{status} over {runs_text(seeds)}"
                         for status, seeds in s[LEARNING_FIELD].items())
        lines.append(f"{MARK} {label(s)}: {runs}.")
    return lines
