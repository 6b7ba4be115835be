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
