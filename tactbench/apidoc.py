"""The API reference for plugin authors (``docs/api.md``), generated from the docstrings.

``python -m tactbench.apidoc --write`` regenerates ``docs/api.md``; the test suite fails
when the file is stale (``tests/test_docs.py``), so the reference cannot drift from the
code. It documents what a plugin touches, by public name only (so moving the code behind
a name changes nothing here): the hooks (:mod:`tactbench.hookspecs`), the component
contracts (:mod:`tactbench.contracts`), the conformance suites (:mod:`tactbench.testing`)
and the data types a dataset or sensor builds (:mod:`tactbench.data.recording`,
:mod:`tactbench.data.normalisation`, :mod:`tactbench.data.dataset`); and, beside them,
the runner's public face (:data:`FACADE`: every name of :mod:`tactbench.runner`'s
``__all__``, what a notebook, a command, a benchmark script or a plugin uses, with the
example of its docstring, which ``tests/test_doc_examples.py`` runs).

What is documented, per module: its docstring; then each public name (``__all__`` when
the module has one, else every function and class defined there whose name has no
leading underscore, and every constant with a ``#:`` comment), in the module's order:
functions and classes with their signature and docstring, a class's own public methods
and properties, and each :class:`~tactbench.contracts.Contract` as a table of its
members. Docstrings are reStructuredText-ish; :func:`markdown` turns the parts used here
(roles, inline literals, ``::`` literal blocks, ``.. code-block:: python`` examples,
definition lists) into Markdown. Written
with the standard library's :mod:`inspect` only.
"""

from __future__ import annotations

import importlib
import inspect
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, ForwardRef, Iterator

from tactbench.contracts import Contract
from tactbench.paths import atomic_write_text

#: The public modules documented, in this order, with what each is for a plugin author.
MODULES: tuple[tuple[str, str], ...] = (
    ("tactbench.hookspecs", "the hooks a plugin implements"),
    ("tactbench.contracts", "what a component must have"),
    ("tactbench.testing", "conformance suites for a plugin's tests"),
    ("tactbench.data.recording", "recordings, frames, samples"),
    ("tactbench.data.normalisation", "raw readings to pressure"),
    ("tactbench.data.dataset", "the labelled set a dataset plugin returns"),
)

#: The runner's public face, documented whole (its ``__all__``): the module and what it is
#: for (its docstring's ``.. code-block:: python`` example is run by
#: tests/test_doc_examples.py).
FACADE = ("tactbench.runner", "the runner's public API, a benchmark from Python")

#: The line before each example fence, by which tests/test_doc_examples.py finds it.
EXAMPLE_MARK = "<!-- example: a docstring's, run by tests/test_doc_examples.py -->"

HEADER = """# API reference for plugin authors

Generated from the docstrings by `python -m tactbench.apidoc --write`; the test suite
fails when this file is stale. How to write and package a plugin is in
[plugins.md](plugins.md); this page is the reference for the names it uses. The last
section is the runner's public face: a benchmark run from Python (in a notebook), its
report and its rows as a table, and every runner name the commands, the benchmark
scripts and plugins use.
"""


# ------------------------------------------------------------------ docstrings → Markdown

_ROLE = re.compile(r":(?:[a-z]+:)?[a-z]+:`~?([^`<]*?)(?:\s*<[^>]*>)?`")
_BLOCK_START = re.compile(r"^(\s*)(.*?)::\s*$")
_CODE_BLOCK = re.compile(r"^\s*\.\. code-block:: python\s*$")


def _inline(text: str) -> str:
    """Roles (``:class:`~a.B``` → `B`) and ``double`` literals → single backticks."""
    def role(m: re.Match[str]) -> str:
        target = m.group(1)
        whole = m.group(0)
        shown = target.rsplit(".", 1)[-1] if "`~" in whole else target
        return f"`{shown}`"

    text = _ROLE.sub(role, text)
    text = re.sub(r"``(.+?)``", r"`\1`", text)
    # dunder names outside code would read as bold in Markdown (inside code they are code)
    parts = re.split(r"(`[^`\n]*`)", text)
    return "".join(part if i % 2 else re.sub(r"(?<![`\w])(__\w+__(?:\(\))?)", r"`\1`", part)
                   for i, part in enumerate(parts))


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def markdown(doc: str | None) -> str:
    """A docstring as Markdown: roles and ``literals`` as code, a paragraph ending in
    ``::`` followed by its indented block as a fenced block, ``term`` lines followed by
    an indented definition as a list. Everything else is kept as written."""
    if not doc:
        return ""
    lines = inspect.cleandoc(doc).splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        m = _BLOCK_START.match(line)
        if _CODE_BLOCK.match(line):  # an example: Python, marked for the doc tests
            body, i = _block(lines, i)
            out += ["", EXAMPLE_MARK, "```python", *body.splitlines(), "```", ""]
            continue
        if m and not line.lstrip().startswith(".."):
            # "text::" + an indented block: the block is literal
            lead = m.group(2)
            if lead:
                out.append(_inline(m.group(1) + lead + ":"))
            body, i = _block(lines, i)
            out += ["", "```text", *body.splitlines(), "```", ""]
            continue
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() and re.fullmatch(r"\s*(-{3,}|={3,})\s*", nxt):
            # a numpydoc section title ("Parameters" over dashes): bold, not a heading
            out.append(f"**{line.strip()}**")
            i += 2
            continue
        if (line.strip() and _indent(line) == 0 and not re.match(r"([-*+]|\d+\.) ", line)
                and nxt.strip() and _indent(nxt) >= 4):
            # a definition list entry: "term" then its indented text
            j = i + 1
            text: list[str] = []
            while j < len(lines) and lines[j].strip() and _indent(lines[j]) >= 4:
                text.append(lines[j].strip())
                j += 1
            out.append(_inline(f"- {line.strip()}: {' '.join(text)}"))
            i = j
            continue
        out.append(_inline(line))
        i += 1
    return re.sub(r"\n{3,}", "\n\n", "\n".join(out)).strip()


def _block(lines: list[str], i: int) -> tuple[str, int]:
    """The indented block under ``lines[i]``, dedented, and the index after it."""
    j = i + 1
    block: list[str] = []
    while j < len(lines) and (not lines[j].strip() or _indent(lines[j]) > _indent(lines[i])):
        block.append(lines[j])
        j += 1
    while block and not block[-1].strip():
        block.pop()
    return (inspect.cleandoc("\n".join(block)) if block else ""), j


# ------------------------------------------------------------------------- signatures


class _Shown:
    """An annotation shown as written (``from __future__ import annotations`` keeps
    them as text; ``inspect`` would quote them)."""

    def __init__(self, text: str) -> None:
        self.text = text

    def __repr__(self) -> str:
        return self.text


def _annotation(value: Any) -> Any:
    if value is inspect.Parameter.empty:
        return value
    if isinstance(value, ForwardRef):
        value = value.__forward_arg__
    text = value if isinstance(value, str) else inspect.formatannotation(value)
    if len(text) > 1 and text[0] == text[-1] and text[0] in "'\"":  # "np.ndarray" quoted
        text = text[1:-1]
    return _Shown(text)


def signature(obj: Any, name: str, *, bound: bool = False) -> str:
    """``name(params) -> return``, annotations as written, no memory addresses;
    ``bound``: a method as called on its object or class (no ``self``/``cls``)."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return name
    params = [p.replace(annotation=_annotation(p.annotation))
              for p in sig.parameters.values()][1 if bound else 0:]
    if inspect.isclass(obj):
        sig = sig.replace(parameters=params, return_annotation=inspect.Signature.empty)
    else:
        sig = sig.replace(parameters=params,
                          return_annotation=_annotation(sig.return_annotation))
    return _no_addresses(f"{name}{sig}")


def _no_addresses(text: str) -> str:
    return re.sub(r"<([\w.]+) object at 0x[0-9a-fA-F]+>", r"<\1>", text)


# ------------------------------------------------------------------------ what is public


def _comments(module: ModuleType) -> dict[str, str]:
    """``#:`` comments of the module's top-level assignments: name → text."""
    try:
        source = inspect.getsource(module)
    except (OSError, TypeError):
        return {}
    found: dict[str, str] = {}
    pending: list[str] = []
    for line in source.splitlines():
        if line.startswith("#:"):
            pending.append(line[2:].strip())
            continue
        m = re.match(r"([A-Za-z_]\w*)\s*(?::[^=]*)?=", line)
        if m and pending:
            found[m.group(1)] = " ".join(pending)
        pending = []
    return found


def public_names(module: ModuleType) -> list[tuple[str, Any, str]]:
    """``(name, object, comment)`` of what ``module`` offers, in its order (see the
    module docstring)."""
    exported = module.__dict__.get("__all__")
    comments = _comments(module)
    if exported is not None:
        names = list(exported)
        homes = {inspect.getmodule(module.__dict__[n]) for n in names}
        for home in sorted((h for h in homes if h is not None and h is not module),
                           key=lambda h: h.__name__):
            comments = {**_comments(home), **comments}
    else:
        names = [n for n in module.__dict__ if not n.startswith("_")]
    out = []
    for name in names:
        obj = module.__dict__[name]
        if inspect.ismodule(obj):
            continue
        defined_here = (inspect.isfunction(obj) or inspect.isclass(obj)) and \
            obj.__module__ == module.__name__
        if exported is not None or defined_here or isinstance(obj, Contract) \
                or name in comments:
            out.append((name, obj, comments.get(name, "")))
    return out


def _members(cls: type) -> Iterator[tuple[str, Any]]:
    """A class's own public methods and properties, in definition order."""
    for name, value in cls.__dict__.items():
        if name.startswith("_"):
            continue
        if isinstance(value, (staticmethod, classmethod)):
            value = value.__func__
        if inspect.isfunction(value) or isinstance(value, property):
            yield name, value


# --------------------------------------------------------------------------- rendering


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading (as tests/test_docs.py checks links)."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _cell(text: str) -> str:
    return _inline(" ".join(text.split())).replace("|", "\\|")


def _contract_table(contract: Any) -> str:
    rows = ["| member | kind | required, or its default | what |",
            "| --- | --- | --- | --- |"]
    for m in contract.members:
        kind = "method" if m.method else "attribute"
        default = "required" if m.required else f"`{_no_addresses(repr(m.default))}`"
        rows.append(f"| `{m.name}` | {kind} | {default} | {_cell(m.doc)} |")
    return "\n".join(rows)


def _value(obj: Any) -> str:
    if isinstance(obj, dict):
        return "a dict: " + ", ".join(f"`{k}`" for k in obj)
    text = _no_addresses(repr(obj))
    return f"`{text}`" if len(text) <= 120 else f"a {type(obj).__name__}"


def _item(module: str, name: str, obj: Any, comment: str) -> list[str]:
    parts = [f"### `{name}`", ""]
    if isinstance(obj, Contract):
        if comment:
            parts += [_inline(comment), ""]
        parts += [_contract_table(obj), ""]
        return parts
    if not (inspect.isfunction(obj) or inspect.isclass(obj) or callable(obj)):
        parts += [f"`{module}.{name}` is {_value(obj)}.", ""]
        if comment:
            parts += [_inline(comment), ""]
        return parts
    protocol = inspect.isclass(obj) and obj.__dict__.get("_is_protocol") is True
    shown = f"class {name}(Protocol)" if protocol else signature(obj, name)
    parts += ["```python", shown, "```", ""]
    doc = markdown(inspect.getdoc(obj) if not inspect.isclass(obj) else obj.__doc__)
    if doc:
        parts += [doc, ""]
    if inspect.isclass(obj):
        for member, value in _members(obj):
            if isinstance(value, property):
                head = f"`{name}.{member}` (property)"
                text = markdown(value.__doc__)
            else:
                head = f"`{signature(value, f'{name}.{member}', bound=True)}`"
                text = markdown(value.__doc__)
            parts += [f"- {head}" + (f": {_indent_more(text)}" if text else ""), ""]
    return parts


def _indent_more(text: str) -> str:
    """Continuation lines of a list item, indented under it."""
    lines = text.splitlines()
    return "\n".join([lines[0], *("  " + line if line.strip() else "" for line in lines[1:])])


def render() -> str:
    """The whole reference as Markdown."""
    toc, sections = [], []
    for name, purpose in [*MODULES, FACADE]:
        module = importlib.import_module(name)
        title = f"`{name}`: {purpose}"
        toc.append(f"- [{title}](#{_slug(title)})")
        parts = [f"## {title}", "", markdown(module.__doc__), ""]
        for item, obj, comment in public_names(module):
            parts += _item(name, item, obj, comment)
        sections.append("\n".join(parts).rstrip() + "\n")
    text = "\n".join([HEADER, "\n".join(toc) + "\n", *sections])
    return re.sub(r"\n{3,}", "\n\n", text)


def reference_path() -> Path:
    return Path(__file__).resolve().parents[1] / "docs" / "api.md"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv not in ([], ["--write"]):
        print("usage: python -m tactbench.apidoc [--write]", file=sys.stderr)
        return 2
    text = render()
    if argv == ["--write"]:
        atomic_write_text(reference_path(), text)
        print(f"wrote {reference_path()}", file=sys.stderr)
        return 0
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
