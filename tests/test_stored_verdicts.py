"""Every verdict the stored reports state is the one their stored rows give.

A run folder's rows are its cells (docs/reports/*/*/cells/*.json, committed, each verified
by its key and checksum as it is read), every row with its per-sequence predictions, so
each comparison is recomputed here from the cells, in the order
:func:`tactbench.runner.execution.results.scene_order` gives them (with the contrasts and margin
the report's results.json says it was made with), and must equal the one results.json
states; every table of comparisons in the reports' Markdown must be a row of the
recomputed tables. A report that states another verdict, interval or p fails, and so
does a results.json whose rows are not its folder's cells.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

REPORTS = Path(__file__).resolve().parents[1] / "docs" / "reports"
STORED = sorted(REPORTS.glob("*/*/results.json"))
FIELDS = ("verdict", "difference", "low", "high", "t_p", "permutation_p", "p", "p_holm",
          "runs", "runs_needed", "discordant_recordings", "equivalence_p_holm")


def _recompute(path: Path) -> tuple[dict, list]:
    from tactbench.runner.execution.results import ResultStore, latest_scene
    from tactbench.runner.execution.scene import design_of
    from tactbench.runner.orchestrate import make_report

    doc = json.loads(path.read_text())
    rows = ResultStore(path.parent).stored_rows()
    assert rows == doc["rows"], f"{path}: its rows are not those of {path.parent}/cells"
    stats = doc["statistics"]
    # the primary family and (for a run --until answered) the looks its verdicts rest on
    primary = stats.get("primary", [])
    report = make_report(rows, contrasts=stats["contrasts"], margin=stats["margin"],
                         primary=primary, sequential=design_of(latest_scene(rows)))
    return doc, report.comparisons


@pytest.fixture(scope="module")
def recomputed() -> dict[Path, tuple[dict, list]]:
    return {path: _recompute(path) for path in STORED}


def test_there_are_stored_reports_to_check():
    assert len(STORED) >= 5


@pytest.mark.parametrize("path", STORED, ids=lambda p: f"{p.parent.parent.name}/{p.parent.name}")
def test_each_stored_comparison_is_what_its_rows_give(path, recomputed):
    doc, comps = recomputed[path]
    stored = doc["comparisons"]
    assert len(stored) == len(comps)
    for old, record in zip(stored, comps):
        new = record.to_dict()
        where = (f"{old['factor']} {old['a']} → {old['b']} "
                 f"({old.get('L')}, {old.get('classifier')})")
        for field in FIELDS:
            if isinstance(new[field], float):
                assert old[field] == pytest.approx(new[field], rel=1e-9, abs=1e-12), \
                    f"{path}: {where}: {field}"
            else:
                assert old[field] == new[field], f"{path}: {where}: {field}"


def _comparison_lines(text: str, width: int) -> list[str]:
    from tactbench.runner.execution.questions import FACTORS

    kinds = {*FACTORS, "contrast"}
    lines = text.splitlines()
    headers = {lines[i - 1] for i, line in enumerate(lines) if i and line.startswith("|---")}
    return [line for line in lines
            if line.startswith("| ") and line.count(" | ") == width - 1
            and line[2:].split(" | ", 1)[0] in kinds and line not in headers]


def test_every_table_of_comparisons_in_the_reports_is_recomputed(recomputed):
    from tactbench.runner.presentation.tables import COMPARISON_HEADER, comparison_rows

    width = len(COMPARISON_HEADER)
    checked = 0
    for md in sorted(REPORTS.glob("*.md")) + sorted(REPORTS.glob("*/*/report.md")):
        parts = ([md.parent / "results.json"] if md.name == "report.md"
                 else sorted((REPORTS / md.stem).glob("*/results.json")))
        expected = {"| " + " | ".join(r) + " |"
                    for p in parts if p in recomputed for r in comparison_rows(recomputed[p][1])}
        text = md.read_text()
        assert "McNemar p |" not in text, f"{md}: a table of the old, pooled statistics"
        for line in _comparison_lines(text, width):
            assert line in expected, f"{md}: states a comparison its rows do not give:\n{line}"
            checked += 1
    assert checked > 50
