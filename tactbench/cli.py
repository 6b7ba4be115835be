"""The ``tactbench`` command line.

Start-up stays cheap: built-in commands are imported when they run (see
:data:`BUILTIN_COMMANDS`; ``--help`` lists them from :data:`BUILTIN_SUMMARIES` without
importing them), plugins load on first need, and heavy libraries are imported by the
components that use them.
"""

from __future__ import annotations

import errno
import importlib
import json
import math
import os
import sys
import traceback
from typing import Any

import click

from tactbench import __version__
from tactbench.errors import InputError, PluginError, TactbenchError, check_number
from tactbench.machine import pin_cpu_kernels
from tactbench.plugins import collect_registry, make_plugin_manager

#: command name → "module:attribute" of its click command, imported on use.
BUILTIN_COMMANDS: dict[str, str] = {
    "list": "tactbench.commands.inspect:list_cmd",
    "plugins": "tactbench.commands.inspect:plugins_cmd",
    "data": "tactbench.commands.data:data_group",
    "can": "tactbench.commands.can:can_group",
    "live": "tactbench.commands.live:live_cmd",
    "layout": "tactbench.commands.layout:layout_group",
    "run": "tactbench.commands.run:run_cmd",
    "cache": "tactbench.commands.cache:cache_group",
    "encode": "tactbench.commands.encode:encode_cmd",
    "flowbench": "tactbench.commands.flowbench:flowbench_cmd",
    "stability": "tactbench.commands.stability:stability_cmd",
}

#: command name → its one-line summary, as ``tactbench --help`` lists it: the list is
#: drawn without importing the commands (whose modules import the library they drive).
#: ``tests/test_cli.py`` checks each is the command's own short help.
BUILTIN_SUMMARIES: dict[str, str] = {
    "list": "List registered sensors, datasets, encoders and classifiers.",
    "plugins": "List plugins (built-in and installed), their versions and load errors.",
    "data": "Inspect, simulate and preview datasets.",
    "can": "CySkin taxel traffic on a CAN bus: simulate, record, bus load, log info.",
    "live": "Classify gestures live: each sweep is encoded once and the last L frames "
            "classified.",
    "layout": "Inspect and generate taxel layouts.",
    "run": "Run a benchmark grid and report accuracy beside its cost.",
    "cache": "Inspect or clear cached encodings (TACTBENCH_CACHE, default "
             "~/.cache/tactbench).",
    "encode": "Encode a (T, H, W) sequence into (T, C, H, W) feature images.",
    "flowbench": "Endpoint error, angular error and ms per frame pair of flow encoders.",
    "stability": "Every encoder on stiff and extreme inputs: pass or fail, with the reason.",
}

DEBUG_ENV = "TACTBENCH_DEBUG"


class TactbenchGroup(click.Group):
    """A group whose built-in commands load lazily and whose plugins add commands."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._plugin_commands_loaded = False

    def _load_plugin_commands(self, ctx: click.Context) -> None:
        if self._plugin_commands_loaded:
            return
        self._plugin_commands_loaded = True
        pm = plugin_manager(ctx)
        before = set(self.commands)
        pm.call_each("register_commands", lambda _p, _d: {"cli": self})
        for name in set(self.commands) - before:
            if name in BUILTIN_COMMANDS:  # a plugin may not replace a built-in command
                del self.commands[name]

    def list_commands(self, ctx: click.Context) -> list[str]:
        self._load_plugin_commands(ctx)
        return sorted(set(BUILTIN_COMMANDS) | set(self.commands))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        target = BUILTIN_COMMANDS.get(cmd_name)
        if target is not None:
            module_name, _, attr = target.partition(":")
            return getattr(importlib.import_module(module_name), attr)
        self._load_plugin_commands(ctx)
        return self.commands.get(cmd_name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list of ``--help``, as click draws it, with the built-in commands'
        summaries taken from :data:`BUILTIN_SUMMARIES` rather than imported."""
        listed: list[tuple[str, click.Command]] = []
        for name in self.list_commands(ctx):
            if name in BUILTIN_COMMANDS:
                listed.append((name, click.Command(name, help=BUILTIN_SUMMARIES[name])))
                continue
            cmd = self.commands.get(name)
            if cmd is not None and not cmd.hidden:
                listed.append((name, cmd))
        if listed:
            limit = formatter.width - 6 - max(len(name) for name, _ in listed)
            with formatter.section("Commands"):
                formatter.write_dl([(name, cmd.get_short_help_str(limit))
                                    for name, cmd in listed])

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except TactbenchError as exc:  # the user's mistake: one line, exit status 2
            if os.environ.get(DEBUG_ENV):
                raise
            raise UserError(" ".join(str(exc).split())) from exc
        except KeyboardInterrupt:  # Ctrl-C: not a failure, not a bug
            interrupted()
        except OSError as exc:  # stdout closed or full: the user's pipe or disk, not a bug
            if exc.errno not in OUTPUT_ERRNOS:
                raise
            raise UserError(output_lost(exc)) from exc


#: Exit statuses of every command (the CLI reference lists them).
EXIT_OK, EXIT_FAILED, EXIT_USER_ERROR, EXIT_INTERRUPTED = 0, 1, 2, 130
EXIT_CODES_TEXT = ("Exit status: 0 everything done; 1 a run's cells failed (listed), or a "
                   "bug (with its traceback); 2 a mistake in what was given (one 'Error:' "
                   "line, nothing done); 130 interrupted (Ctrl-C).")


#: What writing to a closed pipe (``| head``) or a full disk (``> /dev/full``) raises.
OUTPUT_ERRNOS = (errno.EPIPE, errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def output_lost(exc: OSError) -> str:
    """The one line for output that could not be written (stdout closed or on a full
    disk); stdout is pointed at ``/dev/null`` so that Python's last flush at exit does
    not raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no real stdout (a test's capture)
        pass
    return (f"the output could not be written ({exc.strerror or exc}): standard output "
            f"is a closed pipe or a full disk")


def json_text(doc: Any, **dumps: Any) -> str:
    """``doc`` as standard JSON for ``--json`` output: a NaN or infinite number (no JSON
    value) becomes ``null``, so any JSON reader can parse what tactbench prints."""
    def clean(value: Any) -> Any:
        if isinstance(value, float) and not math.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v) for v in value]
        if type(value).__module__ == "numpy":  # numpy scalars and arrays
            return clean(value.tolist()) if hasattr(value, "tolist") else value
        return value

    return json.dumps(clean(doc), allow_nan=False, **dumps)


class Number(click.ParamType):
    """A CLI number checked against its meaning by the one shared check
    (:func:`tactbench.errors.check_number`): finite, within its range, whole where it
    counts something. ``Number(minimum=0, exclusive_minimum=True)`` is a positive float,
    ``Number(minimum=1, integer=True)`` a count. A bad value is a usage error (exit 2)."""

    def __init__(self, *, minimum: float | None = None, maximum: float | None = None,
                 exclusive_minimum: bool = False, integer: bool = False) -> None:
        self.bounds = dict(minimum=minimum, maximum=maximum,
                           exclusive_minimum=exclusive_minimum, integer=integer)
        self.name = "integer" if integer else "number"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None):
        if isinstance(value, str):
            text = value.strip()
            try:
                value = int(text) if self.bounds["integer"] and len(text) < 400 \
                    and text.lstrip("+-").isdigit() else float(text)
            except ValueError:
                self.fail(f"{value!r} is not a number", param, ctx)
        try:
            return check_number(value, "the value", **self.bounds)
        except InputError as exc:
            self.fail(str(exc).replace("the value ", "", 1), param, ctx)


def interrupted() -> None:
    """End the command after Ctrl-C: one line, exit status 130 (128 + SIGINT), what was
    finished is kept."""
    click.echo("tactbench: interrupted; finished work is kept, running it again goes on "
               "from there", err=True)
    raise click.exceptions.Exit(EXIT_INTERRUPTED)


class UserError(click.ClickException):
    """A :class:`~tactbench.errors.TactbenchError` as the CLI shows it: ``Error: ...``."""

    exit_code = 2


def _state(ctx: click.Context) -> dict[str, Any]:
    root = ctx.find_root()
    if root.obj is None:
        root.obj = {}
    return root.obj


def plugin_manager(ctx: click.Context):
    """This invocation's plugin manager, built on first use; problems go to stderr once."""
    state = _state(ctx)
    if "pm" not in state:
        try:
            state["pm"] = make_plugin_manager()
        except PluginError as exc:  # strict mode: a broken plugin is the user's to fix
            raise UserError(str(exc)) from exc
    return state["pm"]


def get_registry(ctx: click.Context | None = None, *, warn: bool = True):
    """This invocation's component registry (plugins loaded once per invocation)."""
    ctx = ctx or click.get_current_context()
    state = _state(ctx)
    if "registry" not in state:
        try:
            state["registry"] = collect_registry(plugin_manager(ctx))
        except PluginError as exc:
            raise UserError(str(exc)) from exc
        if warn:
            for problem in state["registry"].problems:
                click.echo(f"tactbench: warning: {problem} (skipped; see 'tactbench plugins')",
                           err=True)
    return state["registry"]


@click.group(cls=TactbenchGroup, context_settings={"help_option_names": ["-h", "--help"]},
             epilog=EXIT_CODES_TEXT)
@click.version_option(__version__, "--version", prog_name="tactbench")
def cli() -> None:
    """Benchmark preprocessing of tactile data for gesture recognition.

    Sensors, datasets, encoders and classifiers are plugins; `tactbench list`
    shows what is installed.
    """


BUG_REPORT = ("tactbench: this is a bug (in tactbench or in the plugin named in the "
              "traceback above), not a mistake in your input; please report it with the "
              "traceback and the command you ran. Set TACTBENCH_DEBUG=1 to see tracebacks "
              "of user errors too.")


def main(argv: list[str] | None = None) -> None:
    """The console script: user errors are one line (exit 2); a bug keeps its traceback
    and says how to report it (exit 1)."""
    _safe_output()
    try:
        pin_cpu_kernels()  # before anything imports torch
    except TactbenchError as exc:
        click.echo(f"Error: {exc}", err=True)
        sys.exit(EXIT_USER_ERROR)
    try:
        cli.main(args=argv, prog_name="tactbench")
    except KeyboardInterrupt:  # outside a command (plugins loading)
        click.echo("tactbench: interrupted", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except OSError as exc:
        if exc.errno not in OUTPUT_ERRNOS:
            traceback.print_exc()
            click.echo(BUG_REPORT, err=True)
            sys.exit(1)
        click.echo(f"Error: {output_lost(exc)}", err=True)
        sys.exit(EXIT_USER_ERROR)
    except Exception:  # click has handled every user-facing error already
        traceback.print_exc()
        click.echo(BUG_REPORT, err=True)
        sys.exit(1)


def _safe_output() -> None:
    """Never crash on a character the terminal's encoding lacks (a forced ASCII locale
    and "×" in a message): such characters are written as escapes instead."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None and getattr(stream, "errors", None) == "strict":
            try:
                reconfigure(errors="backslashreplace")
            except (ValueError, OSError):  # a closed or detached stream
                pass


if __name__ == "__main__":  # pragma: no cover
    main(sys.argv[1:])
