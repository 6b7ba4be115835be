"""The README's two set-up commands are the ones CI runs, word for word; its main job
paragraph and its findings are what the benchmarks write from the committed results."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def readme_commands() -> dict[str, str]:
    text = (REPO / "README.md").read_text()
    blocks = dict(re.findall(r"<!-- (install|test) -->\s*```(?:bash|sh)?\n(.*?)\n```", text,
                             flags=re.S))
    assert set(blocks) == {"install", "test"}, "README lost its install/test blocks"
    return {k: v.strip() for k, v in blocks.items()}


def test_ci_runs_the_readme_commands():
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    commands = readme_commands()
    assert commands["install"] in ci
    assert commands["test"] in ci
    assert ci.index(commands["install"]) < ci.index(commands["test"])


def test_install_pins_the_cpu_torch():
    # a bare torch requirement pulls ~3 GB of CUDA packages on a fresh machine
    assert '"torch==2.13.0"' in readme_commands()["install"]


@pytest.mark.slow("recomputes every look of the committed main job from its stored cells (half a minute)")
def test_the_readmes_main_job_paragraph_is_written_from_the_committed_run():
    """The README states the main job's answer and runs as benchmarks/runner.py writes
    them from docs/results/study-quick: a stale sentence fails here."""
    import importlib.util
    import textwrap

    spec = importlib.util.spec_from_file_location("bench_runner",
                                                  REPO / "benchmarks" / "runner.py")
    runner = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(runner)
    text = (REPO / "README.md").read_text()
    block = text.split(runner.MAIN_START, 1)[1].split(runner.MAIN_END, 1)[0].strip()
    folder = REPO / "docs" / "results" / "study-quick"
    assert block == textwrap.fill(runner.main_job_text(folder), width=90)


def bench_reports():
    """benchmarks/reports.py, loaded as a module (a script, not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_reports",
                                                  REPO / "benchmarks" / "reports.py")
    reports = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(reports)
    return reports


def test_the_readmes_findings_are_written_from_the_stored_reports():
    """The README's findings are what benchmarks/reports.py's write_findings writes from
    the results stored under docs/reports: a stale verdict, number or count fails here
    (``python benchmarks/reports.py --from-stored`` writes them again)."""
    reports = bench_reports()
    stated = reports.readme_findings(REPO / "README.md")
    assert stated == reports.findings_text(REPO / "docs" / "reports")
    assert stated.count("\n- ") >= 8  # every report's bullet is there, none left out


def test_the_findings_check_sees_a_stale_fact(tmp_path):
    """A README whose findings state another number than the stored results is told
    apart from the current one (the check above can fail)."""
    import shutil

    reports = bench_reports()
    root = tmp_path / "reports"
    shutil.copytree(REPO / "docs" / "reports" / "study" / "lengths", root / "study" / "lengths")
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n{reports.FINDINGS_START}\nold\n{reports.FINDINGS_END}\nend\n")
    reports.write_findings(root, readme)
    assert reports.readme_findings(readme) == reports.findings_text(root)
    assert readme.read_text().startswith("# x\n") and readme.read_text().endswith("end\n")
    results = root / "study" / "lengths" / "results.json"
    doc = json.loads(results.read_text())
    flow = next(s for s in doc["summary"] if s["encoder"] == "farneback")
    flow["accuracy_mean"] += 0.05  # a fact the findings state, changed
    results.write_text(json.dumps(doc))
    assert reports.readme_findings(readme) != reports.findings_text(root)
