"""The suite's own rules (docs/testing.md): a slow test says why, the default command
leaves slow tests out and CI runs them, and what the docs and the README say the suite
costs is what benchmarks/test_suite.py measured."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
RECORD = REPO / "docs" / "benchmarks" / "test-suite.json"

pytest_plugins = ["pytester"]


def bench():
    spec = importlib.util.spec_from_file_location("bench_test_suite",
                                                  REPO / "benchmarks" / "test_suite.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("mark, refused", [
    ('@pytest.mark.slow("trains a full-size cell")', False),
    ("@pytest.mark.slow", True),
    ('@pytest.mark.slow("")', True),
    ("@pytest.mark.slow(reason=3)", True),
])
def test_a_slow_mark_without_a_one_line_reason_stops_the_suite(pytester, mark, refused):
    pytester.makeconftest((REPO / "tests" / "conftest.py").read_text())
    pytester.makeini("[pytest]\nmarkers =\n    slow(reason): why\n")
    pytester.makepyfile(f"import pytest\n\n{mark}\ndef test_x():\n    pass\n")
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-p", "no:xdist")
    if refused:
        assert result.ret == pytest.ExitCode.USAGE_ERROR
        assert "needs a one-line reason" in result.stderr.str()
    else:
        assert result.ret == 0 and result.parseoutcomes() == {"passed": 1}


def test_the_default_command_leaves_slow_tests_out_and_ci_runs_them():
    (addopts,) = re.findall(r"^addopts = (.*)$", (REPO / "pyproject.toml").read_text(), re.M)
    assert "-m 'not slow'" in addopts and "-n auto" in addopts
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert ".venv/bin/python -m pytest -m slow" in ci
    assert ci.index(".venv/bin/python -m pytest") < ci.index(".venv/bin/python -m pytest -m slow")


def test_the_docs_and_readme_state_the_measured_cost():
    record = json.loads(RECORD.read_text())
    text = (REPO / "docs" / "testing.md").read_text()
    block = text.split("<!-- suite:start -->\n", 1)[1].split("\n<!-- suite:end -->", 1)[0]
    assert block == bench().docs_text(record)
    readme = (REPO / "README.md").read_text()
    said = re.search(r"runs the fast suite \(([0-9.]+) minutes on (\d+) cores, measured "
                     r"(\d{4}-\d\d-\d\d)", readme)
    assert said, "the README no longer states what its test command costs"
    assert float(said.group(1)) == round(record["fast"]["wall_s"] / 60, 1)
    assert int(said.group(2)) == record["machine"]["cores"]
    assert said.group(3) == record["date"][:10]


def test_the_record_parses_pytests_lines():
    module = bench()
    m = module.DURATION.match("12.50s call     tests/runner/test_cell.py::test_x[a b]")
    assert m and m.group(3) == "tests/runner/test_cell.py::test_x[a"
    assert module.room_of("tests/runner/test_cell.py::test_x") == "tests/runner"
    assert module.room_of("tests/test_cli.py::test_y") == "tests/*.py"
    closing = module.CLOSING.match("==== 3 failed, 2025 passed, 29 skipped in 1733.71s ====")
    assert closing and closing.group(1).startswith("3 failed") and closing.group(2) == "1733.71"
    quiet = module.CLOSING.match("2303 passed, 7 skipped, 2 warnings in 145.21s (0:02:25)")
    assert quiet and quiet.group(1) == "2303 passed, 7 skipped, 2 warnings"
    assert not module.CLOSING.match("tests/test_x.py::test_y passed in 3.00s of setup")
