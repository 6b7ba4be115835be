"""Every code example in README.md and docs/*.md runs (or parses) as written.

- each ```python block (and each example docs/api.md takes from a docstring) runs in a
  fresh interpreter in an empty temporary folder (the session's private
  TACTBENCH_CACHE); a block that truly cannot run here (a SLURM cluster,
  CAN hardware) is marked on the line before it with ``<!-- example: not run (reason) -->``
  and is then only compiled;
- each ``tactbench ...`` command line of the other blocks is resolved against the click
  application: its subcommands must exist and every option it names must be one the
  command has, and a concrete line (no ``[...]``, ``a|b``, ``...`` or ``<...>``) must
  parse, so a renamed command or option fails here.

docs/cli.md is generated from the click application and checked by tests/test_docs.py.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import click
import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted([REPO / "README.md",
               *(p for p in (REPO / "docs").glob("*.md")
                 if p.name not in ("cli.md", "api.md"))])  # generated references
FENCE = re.compile(r"^```([\w-]*)\n(.*?)^```", re.M | re.S)
NOT_RUN = re.compile(r"<!-- example: not run \((.*)\) -->\s*$")
COMMAND = re.compile(r"^(?:\$ )?(?:\.venv/bin/)?tactbench(?:\s|$)")
SYNOPSIS = re.compile(r"\[|\]|\.\.\.|<[^>]*>|(?<=\w)\|(?=\w)")
OPTIONAL = re.compile(r"\[|\]|\.\.\.|<[^>]*>")  # dropped before a synopsis is split


@dataclass(frozen=True)
class Block:
    doc: str
    line: int
    lang: str
    code: str
    not_run: str | None  # the reason given, None when the block runs

    @property
    def id(self) -> str:
        return f"{self.doc}:{self.line}"


def blocks(paths=DOCS, root: Path = REPO) -> list[Block]:
    found = []
    for path in paths:
        text = path.read_text()
        for m in FENCE.finditer(text):
            before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
            marker = NOT_RUN.search(before)
            found.append(Block(path.relative_to(root).as_posix(),
                               text.count("\n", 0, m.start()) + 1, m.group(1), m.group(2),
                               marker.group(1).strip() if marker else None))
    return found


HEREDOC = re.compile(r"^python3? - <<'?(\w+)'?\n(.*?)\n\1$", re.M | re.S)


def python_examples(found: list[Block]) -> list[Block]:
    """The ```python blocks, and the Python of ``python - <<'PY'`` in shell blocks."""
    out = []
    for b in found:
        if b.lang == "python":
            out.append(b)
        elif b.lang in ("", "bash", "sh", "console"):
            for m in HEREDOC.finditer(b.code):
                out.append(Block(b.doc, b.line + b.code.count("\n", 0, m.start(2)) + 1,
                                 "python", m.group(2) + "\n", b.not_run))
    return out


def api_examples() -> list[Block]:
    """The examples docs/api.md takes from docstrings (``.. code-block:: python``), each
    marked on the line before its fence (:data:`tactbench.apidoc.EXAMPLE_MARK`); the
    other Python blocks of the generated reference are signatures, not examples."""
    from tactbench.apidoc import EXAMPLE_MARK

    api = REPO / "docs" / "api.md"
    lines = api.read_text().splitlines()
    return [b for b in blocks([api]) if b.lang == "python" and lines[b.line - 2] == EXAMPLE_MARK]


PYTHON = python_examples(blocks()) + api_examples()


def command_lines(block: Block) -> list[str]:
    """The ``tactbench`` command lines of a shell or text block, continuations joined."""
    lines, out = block.code.splitlines(), []
    i = 0
    while i < len(lines):
        parts = [p.strip() for p in lines[i].split(" && ")]
        command = next((p for p in parts if COMMAND.match(p)), None)
        i += 1
        if command is None:
            continue
        command = re.sub(r"^\$ |^\.venv/bin/", "", command)
        # a continuation: a trailing backslash, or a synopsis's next line of [options]
        while i < len(lines) and (command.endswith("\\") or
                                  re.match(r"\s+\[", lines[i])):
            command = command.rstrip("\\").rstrip() + " " + lines[i].strip()
            i += 1
        command = re.split(r"\s+#\s", command)[0]             # a trailing comment
        if block.doc == "README.md":                          # README: "usage   summary"
            command = re.split(r"\s{3,}(?![\[-])", command)[0]
        out.append(command.strip())
    return out


COMMANDS = [(b, c) for b in blocks() if b.lang in ("", "bash", "sh", "console", "text")
            for c in command_lines(b)]


def _options(command: click.Command) -> set[str]:
    names = {"--help", "-h"}
    for param in command.params:
        if isinstance(param, click.Option):
            names.update(param.opts)
            names.update(param.secondary_opts)
    return names


def check_command(line: str) -> None:
    """Fail (AssertionError or click.UsageError) unless ``line`` fits the click app."""
    from tactbench.cli import cli

    concrete = not SYNOPSIS.search(line)
    tokens = shlex.split(OPTIONAL.sub(" ", line) if not concrete else line)
    assert tokens[0] == "tactbench", line
    # the group's own settings (-h): click caches a command's help option from the first
    # context it sees, so a bare Context here would change what --help shows later
    ctx = click.Context(cli, info_name="tactbench", **cli.context_settings)
    command: click.Command = cli
    args = tokens[1:]
    path = ["tactbench"]
    while isinstance(command, click.Group) and args and not args[0].startswith("-"):
        # "ls|clear": every alternative must exist; the first one is followed
        names = re.split(r"\|", re.sub(r"[\[\]]", "", args[0]))
        subs = [command.get_command(ctx, n) for n in names]
        assert all(subs), f"{line!r}: no command {' '.join(path)} {args[0]}"
        ctx = click.Context(subs[0], info_name=names[0], parent=ctx)
        command, args = subs[0], args[1:]
        path.append(names[0])
    if line.split() == path and isinstance(command, click.Group):
        return
    known = _options(command)
    for token in args:
        if token.startswith("-") and not re.match(r"-\d", token) and token != "-":
            name = token.split("=", 1)[0]
            assert name in known, (f"{line!r}: {' '.join(path)} has no option {name} "
                                   f"(it has {', '.join(sorted(known))})")
    if concrete:
        try:
            command.make_context(path[-1], list(args), parent=ctx.parent,
                                 resilient_parsing=False)
        except click.BadParameter as e:  # a file the example names need not exist here
            if "does not exist" not in str(e):
                raise


#: An example that trains (a grid through ``run``, a classifier's ``fit``) takes seconds
#: to a minute: it runs with the slow tests; every example compiles in the fast suite.
TRAINS = re.compile(r"(?<![\w.])run\(|\.fit\(")


def _example(block: Block):
    if block.not_run is None and TRAINS.search(block.code):
        return pytest.param(block, id=block.id, marks=pytest.mark.slow(
            "the example trains models (a grid or a classifier) in a fresh interpreter"))
    return pytest.param(block, id=block.id)


@pytest.mark.parametrize("block", PYTHON, ids=lambda b: b.id)
def test_every_python_example_compiles(block):
    assert compile(block.code, block.id, "exec") is not None


def test_the_training_examples_are_told_apart():
    """The rule that sends an example to the slow tests sees a grid and a fit, not
    ``plan(`` or a method named ``rerun(``."""
    assert TRAINS.search("report = run(scene)") and TRAINS.search("clf.fit(x, y)")
    assert not TRAINS.search("p = plan(scene)") and not TRAINS.search("x.rerun(1)")


@pytest.mark.parametrize("block", [_example(b) for b in PYTHON])
def test_python_example_runs(block, tmp_path):
    code = compile(block.code, block.id, "exec")
    assert code is not None
    if block.not_run is not None:
        assert len(block.not_run) > 10, f"{block.id}: say why the example is not run"
        return
    env = dict(os.environ, OMP_NUM_THREADS="1", MPLBACKEND="Agg",
               PYTHONPATH=os.pathsep.join([str(REPO), *filter(None, [
                   os.environ.get("PYTHONPATH")])]))
    if re.search(r"^def test_", block.code, re.M):  # a test file: run it under pytest
        (tmp_path / "test_example.py").write_text(block.code)
        argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                "test_example.py"]
    else:
        argv = [sys.executable, "-c", block.code]
    done = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, (f"{block.id} failed:\n{done.stdout[-2000:]}\n"
                                  f"{done.stderr[-3000:]}")


@pytest.mark.parametrize("block, line", COMMANDS, ids=lambda x: getattr(x, "id", x))
def test_command_line_parses(block, line):
    check_command(line)


SCRIPTS = [(b, line.strip()) for b in blocks() if b.lang in ("", "bash", "sh", "console")
           for line in b.code.splitlines() if re.match(r"\s*(\$ )?python3? benchmarks/", line)]


def check_script_line(line: str, repo: Path = REPO) -> None:
    """A ``python benchmarks/X.py --opt ...`` line names a script that has those options."""
    tokens = shlex.split(re.split(r"\s+#\s", line)[0].removeprefix("$ "))
    script = repo / tokens[1]
    assert script.is_file(), f"{line!r}: no such script {tokens[1]}"
    source = script.read_text()
    for token in tokens[2:]:
        if token.startswith("--"):
            name = token.split("=", 1)[0]
            assert f'"{name}"' in source, f"{line!r}: {tokens[1]} has no option {name}"


@pytest.mark.parametrize("block, line", SCRIPTS, ids=lambda x: getattr(x, "id", x))
def test_benchmark_command_names_real_options(block, line):
    check_script_line(line)


def test_the_examples_are_found():
    # the documents' examples are all seen: a change of fence syntax would hide them
    assert len(PYTHON) >= 12
    assert len(COMMANDS) >= 40
    assert {b.doc for b in PYTHON} >= {"README.md", "docs/classifiers.md", "docs/data.md",
                                       "docs/runner.md", "docs/simulator.md"}
    reasons = [b for b in blocks() if b.not_run]
    assert len(reasons) <= 3, [b.id for b in reasons]
    assert any(b.doc == "docs/runner.md" and "verify_entry" in b.code for b in PYTHON)
    assert any(b.doc == "docs/api.md" and "report.table()" in b.code for b in PYTHON)
    assert len(SCRIPTS) >= 4


def test_the_checker_catches_what_it_should(tmp_path):
    check_command("tactbench run --encoder raw -L 5 --seed 0 --out x")
    check_command("tactbench list [--kind encoder] [--json]")
    check_command("tactbench cache ls|clear")
    check_command("tactbench encode --encoder farneback --input seq.npy --out enc.npy")
    with pytest.raises(AssertionError, match="no option --encoders"):
        check_command("tactbench run --encoders raw")
    with pytest.raises(AssertionError, match="no option --colour"):
        check_command("tactbench list [--colour]")
    with pytest.raises(AssertionError, match="no command"):
        check_command("tactbench cache ls|purge")
    with pytest.raises(click.UsageError):
        check_command("tactbench run --threads many")
    with pytest.raises(click.UsageError):
        check_command("tactbench run --profile fast")
    doc = tmp_path / "x.md"
    doc.write_text("text\n<!-- example: not run (needs a SLURM cluster) -->\n```python\n"
                   "import nowhere\n```\n\n```console\n$ tactbench run \\\n"
                   "    --seed 1  # a comment\n$ python x.py\n```\n")
    with pytest.raises(AssertionError, match="has no option --sweep"):
        check_script_line("python benchmarks/live_latency.py --sweep 10")
    with pytest.raises(AssertionError, match="no such script"):
        check_script_line("python benchmarks/nowhere.py")
    python, console = blocks([doc], root=tmp_path)
    assert (python.lang, python.not_run, python.line) == ("python", "needs a SLURM cluster", 3)
    assert console.not_run is None
    assert command_lines(console) == ["tactbench run --seed 1"]


@pytest.mark.parametrize("block", [b for b in blocks() if b.lang == "toml"],
                         ids=lambda b: b.id)
def test_toml_example_parses(block, tmp_path):
    tomllib = pytest.importorskip("tomllib")  # Python ≥ 3.11
    data = tomllib.loads(block.code)
    if "encoders" in data:  # a scene file: its fields are checked, and it makes a Scene
        from tactbench.runner import Scene, load_scene_file

        scene_file = tmp_path / "scene.toml"
        scene_file.write_text(block.code)
        Scene(**load_scene_file(scene_file))


def test_the_concepts_figure_is_made_by_its_script(tmp_path):
    text = (REPO / "docs" / "concepts.md").read_text()
    assert "](img/concepts-path.png)" in text and "benchmarks/concepts_figure.py" in text
    assert (REPO / "docs" / "img" / "concepts-path.png").stat().st_size > 10_000
    out = tmp_path / "figure.png"
    done = subprocess.run([sys.executable, str(REPO / "benchmarks" / "concepts_figure.py"),
                           "--out", str(out)], env=dict(os.environ, MPLBACKEND="Agg"),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_runner_synopsis_lists_every_run_option():
    from tactbench.cli import cli

    synopsis = next(b for b in blocks([REPO / "docs" / "runner.md"])
                    if b.code.startswith("tactbench run ["))
    ctx = click.Context(cli, info_name="tactbench", **cli.context_settings)
    run = cli.get_command(ctx, "run")
    missing = [p.opts[0] for p in run.params if isinstance(p, click.Option)
               and not any(re.search(rf"\[{re.escape(o)}\b", synopsis.code) for o in p.opts)]
    assert not missing, f"docs/runner.md's synopsis lacks {missing}"
