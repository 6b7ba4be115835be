"""The command-line surface of the foundation: --version, --help, list, plugins."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from click.testing import CliRunner

import tactbench
from tactbench.cli import cli
from tactbench.commands import COMMANDS

HEAVY = ("torch", "kornia", "cv2", "can", "skimage", "matplotlib", "dask", "pandas", "pyarrow",
         "mlflow")


def run(*args):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def test_version():
    result = run("--version")
    assert result.exit_code == 0 and tactbench.__version__ in result.output


def test_help_lists_builtin_commands():
    result = run("--help")
    assert result.exit_code == 0
    for name in ("list", "plugins"):
        assert name in result.output


def test_every_builtin_command_target_imports():
    for name, (target, _summary) in COMMANDS.items():
        module, _, attr = target.partition(":")
        command = getattr(__import__(module, fromlist=[attr]), attr)
        assert command.name == name, f"COMMANDS['{name}'] points at '{command.name}'"


def test_every_command_module_is_registered():
    """A built-in command is one entry of COMMANDS: a module of tactbench/commands/ that no
    entry names would be a command nobody can run."""
    from pathlib import Path

    folder = Path(tactbench.__file__).parent / "commands"
    modules = {f"tactbench.commands.{p.stem}" for p in folder.glob("*.py")
               if p.stem != "__init__"}
    named = {target.partition(":")[0] for target, _summary in COMMANDS.values()}
    assert modules == named


def test_help_summaries_are_the_commands_own():
    """``--help`` lists the built-ins from their COMMANDS summaries: the same lines click
    would draw from the imported commands, at any width."""
    import click

    ctx = click.Context(cli)
    for name, (_target, summary) in COMMANDS.items():
        real = cli.get_command(ctx, name)
        stand_in = click.Command(name, help=summary)
        for limit in (30, 45, 60, 80, 200):
            assert stand_in.get_short_help_str(limit) == real.get_short_help_str(limit), name


def test_builtin_commands_come_through_the_register_commands_hook():
    doc = json.loads(run("plugins", "--json").output)
    builtin = next(p for p in doc["plugins"] if p["name"] == "tactbench.commands")
    assert builtin["source"] == "builtin" and builtin["hooks"] == ["register_commands"]


def test_help_imports_no_command_and_no_numpy():
    code = ("import sys; from tactbench.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "bad = sorted(m for m in sys.modules if m.startswith('tactbench.commands.') "
            "or m.split('.')[0] in ('numpy', 'torch', 'cv2', 'kornia', 'can', 'matplotlib', "
            "'pandas', 'pyarrow', 'mlflow'))\n"
            "print('imported:', bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert "imported: []" in out.stdout, out.stdout + out.stderr
    assert "stability" in out.stdout and "Every encoder on stiff" in out.stdout


def test_list_json_is_one_document_with_every_field():
    result = CliRunner().invoke(cli, ["list", "--json"])
    doc = json.loads(result.stdout)
    raw = next(c for c in doc["components"] if c["name"] == "raw")
    assert set(raw) == {"kind", "name", "summary", "plugin", "distribution", "target",
                        "requires", "available"}
    assert raw["kind"] == "encoder" and raw["plugin"] == "tactbench.encoders"


def test_list_filters_by_kind():
    doc = json.loads(CliRunner().invoke(cli, ["list", "--kind", "encoder", "--json"]).stdout)
    assert doc["components"] and {c["kind"] for c in doc["components"]} == {"encoder"}


def test_list_says_what_each_classifier_is_fed():
    doc = json.loads(CliRunner().invoke(cli, ["list", "--kind", "classifier", "--json"]).stdout)
    fed = {c["name"]: c["input"] for c in doc["components"]}
    assert fed["small-cnn-lstm"] == "images" and fed["taxel-lstm"] == "vectors"
    assert fed["logreg"] == "images or vectors (--input)"
    assert "input" in run("list", "--kind", "classifier").output


def test_list_table_shows_requirements():
    result = run("list")
    assert result.exit_code == 0 and "raw" in result.output and "frame-diff" in result.output


def test_plugins_json_lists_builtins_with_their_hooks():
    doc = json.loads(run("plugins", "--json").output)
    builtin = next(p for p in doc["plugins"] if p["name"] == "tactbench.encoders")
    assert builtin["source"] == "builtin" and "register_encoders" in builtin["hooks"]
    assert builtin["version"] == tactbench.__version__ and builtin["errors"] == []


def test_unknown_command_fails_with_a_reason():
    result = CliRunner().invoke(cli, ["no-such-command"])
    assert result.exit_code != 0 and "No such command" in result.output


@pytest.mark.parametrize("argv", [
    ["-c", "import tactbench.cli"],
    ["-m", "tactbench", "--help"],
    ["-m", "tactbench", "list"],
    ["-m", "tactbench", "list", "--json"],
    ["-m", "tactbench", "plugins"],
])
def test_startup_leaves_heavy_libraries_out(argv):
    """The CLI's start-up (and listing what is installed) imports no heavy library."""
    probe = (
        "import runpy, sys, atexit\n"
        f"heavy = {HEAVY!r}\n"
        "def report():\n"
        "    loaded = [m for m in heavy if m in sys.modules]\n"
        "    sys.__stderr__.write('HEAVY:' + ','.join(loaded) + '\\n')\n"
        "atexit.register(report)\n"
        f"argv = {argv!r}\n"
        "if argv[0] == '-c':\n"
        "    exec(argv[1])\n"
        "else:\n"
        "    sys.argv = ['tactbench', *argv[2:]]\n"
        "    runpy.run_module(argv[1], run_name='__main__')\n"
    )
    env = {**os.environ, "COLUMNS": "200"}
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                            env=env, timeout=120)
    assert result.returncode == 0, result.stderr
    line = [ln for ln in result.stderr.splitlines() if ln.startswith("HEAVY:")][-1]
    assert line == "HEAVY:", f"{argv} imported heavy modules: {line[6:]}"


def test_commands_are_those_of_the_invocations_plugins():
    """Each invocation registers its own plugins' commands: one without plugins has no
    command, and leaves none missing for the next."""
    from tactbench.plugins import make_plugin_manager

    bare = make_plugin_manager(builtins=False, entry_points=False)
    result = CliRunner().invoke(cli, ["list"], obj={"pm": bare})
    assert result.exit_code == 2 and "No such command 'list'" in result.output
    assert run("list", "--kind", "encoder").exit_code == 0
