"""The README's two set-up commands are the ones CI runs, word for word."""

from __future__ import annotations

import re
from pathlib import Path

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
