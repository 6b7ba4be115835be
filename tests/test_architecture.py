"""docs/architecture.md is the map of the package: every module it names exists, and
every module of the package is on the map (so the map cannot rot in either direction)."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "architecture.md"
#: Paths named in the doc: `tactbench/x.py`, `tactbench/x/` (a folder), `plugins/...`.
PATH_RE = re.compile(r"`((?:tactbench|plugins|benchmarks|tests|docs)/[\w./-]*)`")


def named_paths() -> list[str]:
    return sorted(set(PATH_RE.findall(DOC.read_text())))


def test_the_map_names_modules():
    assert len(named_paths()) >= 30


def test_every_module_the_map_names_exists():
    missing = [p for p in named_paths() if not (REPO / p).exists()]
    assert not missing, f"docs/architecture.md names paths that do not exist: {missing}"


def test_every_module_of_the_package_is_on_the_map():
    named = set(named_paths())
    folders = {p.rstrip("/") for p in named if p.endswith("/")}
    unlisted = []
    for path in sorted((REPO / "tactbench").rglob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        if path.name == "__init__.py" or path.name == "__main__.py":
            continue
        if rel not in named and path.parent.relative_to(REPO).as_posix() not in folders:
            unlisted.append(rel)
    assert not unlisted, f"modules missing from docs/architecture.md: {unlisted}"


#: stage → the stages (and shared modules) below it that it may import; data moves down.
MAY_IMPORT = {
    "data": set(),
    "encoders": {"data"},
    "classifiers": {"data"},
    "datasets": {"data", "can"},  # a recorded CAN log is one of the formats it reads
}
STAGES = {"data", "datasets", "encoders", "classifiers", "runner", "sensors", "can",
          "commands", "live"}


def imported_stages(path: Path) -> set[str]:
    import ast

    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for name in names:
            parts = name.split(".")
            if parts[0] == "tactbench" and len(parts) > 1 and parts[1] in STAGES:
                found.add(parts[1])
    return found


def test_data_moves_down_the_pipeline():
    wrong = []
    for stage, allowed in MAY_IMPORT.items():
        for path in sorted((REPO / "tactbench" / stage).rglob("*.py")):
            bad = imported_stages(path) - allowed - {stage}
            if bad:
                wrong.append(f"{path.relative_to(REPO)} imports {sorted(bad)}")
    assert not wrong, "a stage imports one above it: " + "; ".join(wrong)


def test_importing_tactbench_has_no_side_effects_on_the_import_system():
    """No finder on sys.meta_path, no hooks: ``import tactbench`` only defines names."""
    import subprocess
    import sys

    code = ("import sys; before = list(sys.meta_path), list(sys.path_hooks)\n"
            "import tactbench\n"
            "assert (list(sys.meta_path), list(sys.path_hooks)) == before\n"
            "print('clean')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.stdout.strip() == "clean", out.stderr
