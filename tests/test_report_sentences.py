"""Every stored report's sentence on what its runs allow is generated from all of that
report's results (issue 48): rendered again here from the results.json of every run it
names, it is the sentence in the report, and its counts and ranges are those of the
comparisons stored there. The README's families per report come from the same files."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REPORTS = REPO / "docs" / "reports"
DECIDED = ("B better", "A better", "equivalent")


def _reports_module():
    spec = importlib.util.spec_from_file_location("reports_bench", REPO / "benchmarks" /
                                                  "reports.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _notes():
    """(report.md, the sentence, the runs it names) of every stored report with one."""
    out = []
    for md in sorted(REPORTS.glob("*.md")):
        for line in md.read_text().splitlines():
            if line.startswith("- Counted over "):
                names = re.findall(r"`([^`]+)`", line.split(":")[0])
                out.append((md.name, line[2:], names))
    return out


def test_every_report_with_comparisons_has_its_note():
    assert {name for name, _, _ in _notes()} >= {"study.md", "real-data.md",
                                                 "which-flow.md", "which-classifier.md"}


@pytest.mark.parametrize("report, sentence, names", _notes(),
                         ids=[n for n, _, _ in _notes()])
def test_the_note_is_rendered_from_every_run_it_names(report, sentence, names):
    reports = _reports_module()
    parts = [{"out": REPORTS / n, "results": json.loads((REPORTS / n / "results.json")
                                                        .read_text())} for n in names]
    assert sentence == reports._runs_note(*parts)
    comps = [c for p in parts for c in p["results"]["comparisons"]]
    open_ = [c for c in comps if c["verdict"] not in DECIDED]
    assert f"up to {max(c['runs'] for c in comps)} runs per cell" in sentence
    if not open_:
        assert "is resolved." in sentence
        return
    assert "is resolved" not in sentence
    said = int(re.search(r"Of the (\d+) comparisons", sentence).group(1))
    assert said == len(open_)
    reach = [c["runs_for_power"] for c in open_ if c["runs_for_power"] is not None]
    if reach:
        assert re.search(rf"{len(reach)} would reach 80 % power at their observed "
                         rf"difference with {min(reach)}(–{max(reach)})? runs", sentence)
        assert f"for {len(open_) - len(reach)} no number of runs" in sentence
    else:
        assert "for every one no number of runs" in sentence
    shown = [c["detectable_effect"] for c in open_ if c["detectable_effect"] is not None]
    if shown:
        low, high = f"{min(shown):.1f}", f"{max(shown):.1f}"
        assert f"differences of {low if low == high else low + '–' + high} points" in sentence


def test_the_readme_counts_the_families_alpha_is_per():
    reports = _reports_module()
    said = reports._families_per_report(REPORTS)
    text = (REPO / "README.md").read_text()
    assert "α = 0.05 per run" in text and said in text
    study = sum(any(c.get("family") == "primary" for c in json.loads(f.read_text())
                    ["comparisons"]) for f in (REPORTS / "study").glob("*/results.json"))
    assert f"study: {study}" in said
