"""The ``tactbench`` command line.

Start-up stays cheap: built-in commands come through the ``register_commands`` hook like
a plugin's (:mod:`tactbench.commands`), as lazy commands that ``--help`` lists without
importing them; plugins load on first need, and heavy libraries are imported by the
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
from tactbench.kernels import pin_cpu_kernels
from tactbench.plugins import collect_registry, make_plugin_manager

DEBUG_ENV = "TACTBENCH_DEBUG"


class LazyCommand(click.Command):
    """A command known by its name and summary, imported when it is used: ``target`` is
    ``"module:attribute"`` of the click command. ``--help`` draws the group's command list
    from the summary alone."""

    def __init__(self, name: str, target: str, *, summary: str) -> None:
        module_name, _, attr = target.partition(":")
        if not module_name or not attr:
            raise InputError(f"command '{name}': target {target!r} must look like "
                             f"'package.module:attribute'")
        super().__init__(name, help=summary)
        self.target = target

    def load(self) -> click.Command:
        module_name, _, attr = self.target.partition(":")
        return getattr(importlib.import_module(module_name), attr)


class TactbenchGroup(click.Group):
    """The ``tactbench`` group: every command, built-in or a plugin's, comes through the
    ``register_commands`` hook (:func:`registered_commands`), once per invocation, from
    that invocation's plugin manager; lazy commands are imported when they are used."""

    def add_lazy_command(self, name: str, target: str, *, summary: str) -> None:
        """Add command ``name`` whose click command is ``target`` (``"module:attribute"``),
        imported only when the command runs or shows its own help; ``summary`` is its line
        in ``tactbench --help`` (the command's own short help)."""
        self.add_command(LazyCommand(name, target, summary=summary))

    def registered(self, ctx: click.Context) -> dict[str, click.Command]:
        """This invocation's commands: those added to the group in code, then those the
        plugins register."""
        state = _state(ctx)
        if "commands" not in state:
            state["commands"] = registered_commands(plugin_manager(ctx), dict(self.commands))
        return state["commands"]

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(self.registered(ctx))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        commands = self.registered(ctx)
        command = commands.get(cmd_name)
        if isinstance(command, LazyCommand):
            command = commands[cmd_name] = command.load()
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list of ``--help``, as click draws it, but from the commands as
        registered: a lazy command shows its summary and is not imported."""
        listed = [(name, command) for name, command in sorted(self.registered(ctx).items())
                  if not command.hidden]
        if listed:
            limit = formatter.width - 6 - max(len(name) for name, _ in listed)
            with formatter.section("Commands"):
                formatter.write_dl([(name, command.get_short_help_str(limit))
                                    for name, command in listed])

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


def registered_commands(pm, commands: dict[str, click.Command] | None = None
                        ) -> dict[str, click.Command]:
    """``commands`` (name → command) with those of every plugin's ``register_commands``
    (built-ins first) added. Each plugin adds to a group of its own, merged when its hook
    returns: a hook that raises adds nothing, and a name already taken is refused and
    reported (the first keeps it), as for components."""
    commands = dict(commands or {})
    owners = dict.fromkeys(commands, "tactbench.cli")
    staged: dict[str, tuple[str, TactbenchGroup]] = {}

    def make_kwargs(plugin: str, dist: str) -> dict[str, Any]:
        staged[plugin] = (dist, TactbenchGroup(name="tactbench"))
        return {"cli": staged[plugin][1]}

    def on_success(plugin: str, _kwargs: dict[str, Any]) -> None:
        dist, group = staged[plugin]
        for name, command in group.commands.items():
            if name in owners:
                pm.report(plugin, dist, f"command '{name}' is already registered by plugin "
                                        f"'{owners[name]}'; this one is skipped. Rename one "
                                        f"of them.")
                continue
            owners[name], commands[name] = plugin, command

    try:
        pm.call_each("register_commands", make_kwargs, on_success)
    except PluginError as exc:  # strict mode: a broken plugin is the user's to fix
        raise UserError(str(exc)) from exc
    return commands


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
