"""Docs that cannot rot: the CLI reference is current and every relative link resolves."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted([REPO / "README.md", *(REPO / "docs").rglob("*.md"),
               *(REPO / "plugins").glob("*/README.md")])
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces → '-'."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    return {slug(m) for m in re.findall(r"^#+ (.+)$", text, re.M)}


def test_the_cli_reference_is_current():
    from tactbench.clidoc import reference_path, render

    assert reference_path().read_text() == render(), \
        "docs/cli.md is stale: run `python -m tactbench.clidoc --write`"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_relative_link_resolves(doc):
    text = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)
    broken = []
    for m in LINK.finditer(text):
        link = m.group(1) or m.group(2)
        if re.match(r"[a-z][a-z0-9+.-]*:", link):  # http:, mailto:, ...
            continue
        target, _, anchor = link.partition("#")
        path = (doc.parent / target).resolve() if target else doc
        if not path.exists():
            broken.append(f"{link} (no such file)")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{link} (no heading #{anchor} in {path.name})")
    assert not broken, f"{doc.relative_to(REPO)}: broken links: {', '.join(broken)}"


def test_the_link_checker_catches_what_it_should(tmp_path):
    assert slug("The encoding cache") == "the-encoding-cache"
    assert slug("`tactbench run` — options") == "tactbench-run--options"
    assert "flow-error-against-run-time" in anchors(REPO / "docs" / "encoders.md")


def test_every_test_named_in_the_reliability_table_exists():
    """docs/reliability.md cites tests as `tests/x/test_y.py::name`, `test_y.py::name` or
    `::name` (the file named last on that line); each must be a test in that file."""
    text = (REPO / "docs" / "reliability.md").read_text()
    cited, missing = 0, []
    for line in text.splitlines():
        current = None
        for m in re.finditer(r"`((?:tests/)?[\w/]*test_\w+\.py)?(?:::(\w+))?(?:\[[^\]]*\])?`",
                             line):
            path, name = m.group(1), m.group(2)
            if path:
                found = [REPO / path] if path.startswith("tests/") else \
                    sorted((REPO / "tests").rglob(Path(path).name))
                assert len(found) == 1 and found[0].is_file(), \
                    f"{path}: no such test file, or several (give its folder)"
                current = found[0]
            if name:
                assert current is not None, f"`::{name}` names no file before it"
                cited += 1
                if not re.search(rf"^def {name}\(", current.read_text(), re.M):
                    missing.append(f"{current.relative_to(REPO)}::{name}")
    assert cited > 40 and not missing, missing
