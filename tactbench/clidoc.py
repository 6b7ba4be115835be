"""The CLI reference (``docs/cli.md``), generated from the click application itself.

``python -m tactbench.clidoc --write`` regenerates ``docs/cli.md``; the test suite fails
when the file is stale (``tests/test_docs.py``), so the reference cannot drift from the
commands. Only built-in commands are listed (a plugin's commands depend on what is
installed); the help text is rendered at a fixed width so the file does not depend on
the terminal.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from tactbench.cli import TactbenchGroup, cli
from tactbench.plugins import make_plugin_manager

WIDTH = 96
HEADER = """# Command-line reference

Generated from the click application by `python -m tactbench.clidoc --write`; the test
suite fails when this file is stale. Every command also answers `-h`/`--help`.

Exit status, for every command:

| status | meaning |
|---|---|
| 0 | everything asked for was done |
| 1 | a run's cells failed (the run finished the others and lists them), or a bug in tactbench or a plugin (its traceback is printed, with a line saying it is a bug) |
| 2 | a mistake in what was given (an option, a file, a folder, a value): one `Error: ...` line, before any work where it can be known before |
| 130 | interrupted (Ctrl-C): one line; finished work (cache entries, cell rows) is kept, and running the command again goes on from there; worker processes stop without tracebacks |

`--json` output is standard JSON: a number that is not finite is printed as `null`. A
terminal whose encoding lacks a character (a forced ASCII locale) shows it as an escape
(`\xd7` for ×) instead of failing.
"""


def _walk(command: click.Command, path: list[str], parent: click.Context | None,
          obj: dict | None = None):
    ctx = click.Context(command, info_name=path[-1], parent=parent, terminal_width=WIDTH,
                        max_content_width=WIDTH, obj=obj, **command.context_settings)
    yield path, command, ctx
    if isinstance(command, click.Group):
        for name in sorted(command.list_commands(ctx)):
            sub = command.get_command(ctx, name)
            if sub is not None and not sub.hidden:
                yield from _walk(sub, [*path, name], ctx)


def _builtin_cli() -> click.Group:
    """A copy of the ``tactbench`` group without its epilog (the header above says the
    exit statuses)."""
    return TactbenchGroup(name="tactbench", callback=cli.callback, params=cli.params,
                          help=cli.help, context_settings=cli.context_settings)


def render() -> str:
    """The whole reference as Markdown."""
    # built-in commands only: the file must not vary with what is installed
    builtins = {"pm": make_plugin_manager(entry_points=False, strict=True)}
    parts = [HEADER]
    toc, sections = [], []
    for path, command, ctx in _walk(_builtin_cli(), ["tactbench"], None, builtins):
        title = " ".join(path)
        anchor = "-".join(path)
        if len(path) > 1:
            toc.append(f"{'  ' * (len(path) - 2)}- [`{title}`](#{anchor})")
        summary = command.get_short_help_str(limit=WIDTH)
        sections.append(f"## {title}\n\n{summary}\n\n```text\n"
                        f"{command.get_help(ctx).rstrip()}\n```\n")
    parts.append("\n".join(toc) + "\n")
    parts.extend(sections)
    return "\n".join(parts)


def reference_path() -> Path:
    return Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    text = render()
    if argv == ["--write"]:
        reference_path().write_text(text, encoding="utf-8")
        print(f"wrote {reference_path()}", file=sys.stderr)
        return 0
    if argv:
        print("usage: python -m tactbench.clidoc [--write]", file=sys.stderr)
        return 2
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
