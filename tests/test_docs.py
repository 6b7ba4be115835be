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


def test_the_api_reference_is_current():
    from tactbench.apidoc import reference_path, render

    assert reference_path().read_text() == render(), \
        "docs/api.md is stale: run `python -m tactbench.apidoc --write`"


def test_the_api_reference_covers_what_a_plugin_uses():
    """Every hook, every contract member, every tactbench.testing name and the data types
    a plugin builds have their entry (found independently of the generator)."""
    import pluggy

    import tactbench.testing
    from tactbench import contracts, hookspecs
    from tactbench.contracts import CONTRACTS, FRAME

    text = (REPO / "docs" / "api.md").read_text()
    headings = set(re.findall(r"^### `([^`]+)`$", text, re.M))
    pm = pluggy.PluginManager("tactbench")
    pm.add_hookspecs(hookspecs)
    hooks = {name for name in dir(pm.hook) if not name.startswith("_")}
    assert len(hooks) >= 5 and hooks <= headings
    assert set(tactbench.testing.__all__) <= headings
    assert {"Recording", "Frame", "Sample", "Dataset", "Normalisation"} <= headings
    for contract in (*CONTRACTS.values(), FRAME):
        names = {name for name, value in vars(contracts).items() if value is contract}
        assert names & headings, contract.kind
        for member in contract.members:
            assert f"| `{member.name}` |" in text, (contract.kind, member.name)
    for doc in ("plugins.md", "../README.md"):
        assert "api.md" in (REPO / "docs" / doc).read_text()


def test_docstrings_become_markdown():
    from tactbench.apidoc import markdown, signature

    doc = '''Read :class:`~tactbench.data.recording.Recording` from ``path``.

    :func:`tactbench.contracts.check` is called; a sensor's __enter__ returns it::

        with sensor:
            pass

    ``name``
        the name, over
        two lines.

    Parameters
    ----------
    - a list stays a list
      with its continuation.
    '''
    assert markdown(doc).splitlines() == [
        "Read `Recording` from `path`.", "",
        "`tactbench.contracts.check` is called; a sensor's `__enter__` returns it:", "",
        "```text", "with sensor:", "    pass", "```", "",
        "- `name`: the name, over two lines.", "",
        "**Parameters**", "- a list stays a list", "  with its continuation."]

    def f(x: "np.ndarray", *, sentinel=object(), n: int = 3) -> "list[int]":
        """Nothing."""

    assert signature(f, "f") == "f(x: np.ndarray, *, sentinel=<object>, n: int = 3) -> " \
                                "list[int]"
