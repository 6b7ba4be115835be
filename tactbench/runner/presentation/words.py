"""A comparison in the words of a finding: the sentences the benchmark reports
(docs/reports/) and the README's "What it finds" are written in, from results.json's
comparisons, so that no script words a verdict, a difference or a test of its own.

:func:`finding_text` is one comparison in a sentence (the difference, its interval, how
many runs favoured B, the test and Holm p, the verdict), :func:`answer_brief` a primary
question's answer in a clause (the verdict its looks reached, the difference over runs,
why it stopped where it is unresolved), :func:`percent` an accuracy fraction as the
reports print it. A and B are named as the sentence calls them (``names``), the verdict
by :func:`~tactbench.runner.presentation.tables.verdict_text`.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from tactbench.runner.analysis.comparisons import Comparison, plain_t, read_comparisons
from tactbench.runner.analysis.statistics import DECIDED
from tactbench.runner.presentation.tables import verdict_text

#: The group-sequential prefix of a look's note, left out of an answer's reason.
_SEQUENTIAL = "group-sequential: "


def percent(x: float | None) -> str:
    """An accuracy fraction in percent, one decimal (``0.807`` → ``80.7``); ``-`` for
    none or NaN."""
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f}"


def finding_text(c: Comparison | Mapping[str, Any] | None, a: str, b: str) -> str:
    """One sentence for a paired comparison (a record, or results.json's entry), A and B
    named ``a`` and ``b``: B − A in points, the 95 % interval over runs, the runs B won,
    the test's p and the Holm p of its family, the verdict in bold, the note."""
    if c is None:
        return f"{b} − {a}: not compared."
    [c] = read_comparisons([c])
    if c.ceiling:
        return (f"{b} − {a}: both right on every paired recording of every run "
                f"({c.runs} runs): a ceiling, not a precise zero.")
    text = f"{b} − {a}: {100 * c.difference:+.1f} points"
    if c.df:
        text += (f", 95 % interval over runs [{100 * c.low:+.1f}, "
                 f"{100 * c.high:+.1f}] (unadjusted)")
    text += f", {c.b_better_runs} of {c.runs} runs higher"
    if c.t_p is not None:
        test = "paired t, independent runs" if plain_t(c) else "corrected t"
        text += (f", p = {c.t_p:.2g} ({test}), Holm p = {c.p_holm:.2g} "
                 f"({c.family or 'exploratory'}, {c.family_size})")
    text += f" → **{verdict_text(c, names=(a, b))}**"
    if c.note:
        text += f" ({c.note})"
    return text + "."


def answer_brief(c: Comparison | Mapping[str, Any], a: str, b: str) -> str:
    """A primary question's answer in a clause, A and B named ``a`` and ``b``: the
    verdict its looks reached in bold, B − A over runs with its interval, and why it
    stopped where it is unresolved; a ceiling named as one."""
    [c] = read_comparisons([c])
    if c.ceiling:
        return (f"**a ceiling**: {a} and {b} right on every paired recording of every run "
                f"({c.runs} runs)")
    text = (f"**{verdict_text(c, names=(a, b))}**, {b} − {a} "
            f"{100 * c.difference:+.1f} points")
    if c.df:
        text += f" [{100 * c.low:+.1f}, {100 * c.high:+.1f}]"
    text += f" over {c.runs} runs"
    if c.verdict not in DECIDED and c.note:
        text += f" ({c.note.removeprefix(_SEQUENTIAL)})"
    return text
