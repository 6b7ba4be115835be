"""A comparison in the words of a finding (runner/presentation/words.py): the sentences
docs/reports/ and the README are written in, from a stored comparison."""

from __future__ import annotations

import json
import math
from pathlib import Path

from tactbench.runner import answer_brief, finding_text, percent, verdict_text

STORED = Path(__file__).resolve().parents[3] / "docs" / "reports" / "study" / "paper"


def _stored() -> dict:
    """The study's flagship comparison as results.json keeps it (farneback against raw)."""
    return json.loads((STORED / "results.json").read_text())["comparisons"][0]


def test_a_finding_names_the_sides_as_the_sentence_calls_them():
    c = _stored()
    assert verdict_text(c) == "farneback better"
    assert verdict_text(c, names=("raw", "flow")) == "flow better"
    assert finding_text(c, "raw", "flow") == (
        "flow − raw: +7.5 points, 95 % interval over runs [+4.5, +10.4] (unadjusted), "
        "5 of 5 runs higher, p = 0.0021 (corrected t), Holm p = 0.0021 (primary, 1) → "
        "**flow better** (group-sequential: decided at the look after 5 runs, α spent "
        "over 1 look(s)).")
    assert finding_text(None, "raw", "flow") == "flow − raw: not compared."


def test_an_answer_says_why_an_open_question_stopped_and_a_ceiling_is_one():
    c = _stored()
    assert answer_brief(c, "raw", "flow") == ("**flow better**, flow − raw +7.5 points "
                                              "[+4.5, +10.4] over 5 runs")
    c.update(verdict="futile", note="group-sequential: stopped at 10 runs")
    assert answer_brief(c, "raw", "flow").endswith("over 5 runs (stopped at 10 runs)")
    assert finding_text({**c, "ceiling": True}, "raw", "flow").endswith(
        "(5 runs): a ceiling, not a precise zero.")
    assert answer_brief({**c, "ceiling": True}, "raw", "flow").startswith("**a ceiling**")


def test_percent_is_one_decimal_and_a_dash_for_none():
    assert percent(0.807) == "80.7" and percent(None) == "-" and percent(math.nan) == "-"
