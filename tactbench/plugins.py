"""Plugin discovery: the plugin manager, built-in plugins and entry points.

Where plugins come from, in this order:

1. the built-in modules in :data:`BUILTIN_PLUGINS` (registered like any other);
2. the entry-point group ``tactbench`` of installed distributions.

A plugin that fails to import, implements an unknown hook, or whose hook raises
is recorded as a :class:`~tactbench.registry.PluginProblem` and skipped; the rest keep
working. With ``TACTBENCH_STRICT_PLUGINS=1`` the first such problem raises
:class:`~tactbench.errors.PluginError` instead. :func:`collect_registry` calls every
plugin's ``register_*`` hooks and gathers what they register into a
:class:`~tactbench.registry.Registry` (:mod:`tactbench.registry`); the spec grammar
``name:key=value`` is :mod:`tactbench.specs`.
"""

from __future__ import annotations

import contextlib
import difflib
import importlib
import io
import logging
import os
import re
from dataclasses import replace
from importlib.metadata import entry_points
from typing import Any, Callable, Iterable

import pluggy

from tactbench import __version__, hookspecs
from tactbench.errors import InputError, PluginError
from tactbench.events import EventLanes
from tactbench.registry import KIND_HOOKS, Component, PluginInfo, PluginProblem, Registry

ENTRY_POINT_GROUP = "tactbench"
#: The hooks called while a benchmark runs (:mod:`tactbench.hookspecs`, "events").
EVENT_HOOKS = ("cell_finished", "run_finished", "look_finished")
STRICT_ENV = "TACTBENCH_STRICT_PLUGINS"

log = logging.getLogger("tactbench.plugins")

#: Modules whose hooks register the built-in components, in load order.
BUILTIN_PLUGINS: tuple[str, ...] = (
    "tactbench.data",  # splits and test windows
    "tactbench.encoders",
    "tactbench.datasets",
    "tactbench.sensors",
    "tactbench.classifiers",
    "tactbench.paired",  # paired tests
    "tactbench.commands",
)

_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_.-]*$")
_TARGET_RE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


class PluginManager(pluggy.PluginManager):
    """A pluggy manager that also remembers where each plugin came from and what failed."""

    def __init__(self, *, strict: bool = False) -> None:
        super().__init__(ENTRY_POINT_GROUP)
        self.add_hookspecs(hookspecs)
        self.strict = strict
        self.infos: dict[str, PluginInfo] = {}
        self.problems: list[PluginProblem] = []
        self.events = EventLanes(self._event_problem)

    def report(self, plugin: str, distribution: str, message: str, *,
               mark: bool = True) -> None:
        problem = PluginProblem(plugin, distribution, message)
        self.problems.append(problem)
        info = self.infos.get(plugin) if mark else None  # mark=False: not this one's info
        if info is not None and info.error is None:
            self.infos[plugin] = replace(info, error=message)
        if self.strict:
            raise PluginError(f"{problem} ({STRICT_ENV} is set)")

    def add_plugin(self, obj: Any, *, name: str, distribution: str, version: str,
                   source: str) -> None:
        """Register one plugin object, recording invalid or misspelled hooks."""
        self.infos[name] = PluginInfo(name, distribution, version, source)
        try:
            self.register(obj, name=name)
        except Exception as exc:  # pluggy validation (bad signature), duplicates
            self.infos[name] = PluginInfo(name, distribution, version, source,
                                          error=f"{type(exc).__name__}: {exc}")
            self.report(name, distribution, f"not registered: {type(exc).__name__}: {exc}")
            return
        callers = self.get_hookcallers(obj) or []
        hooks = tuple(sorted(c.name for c in callers if c.has_spec()))
        self.infos[name] = PluginInfo(name, distribution, version, source, hooks=hooks)
        for caller in callers:
            if not caller.has_spec():
                close = difflib.get_close_matches(caller.name, _hook_names(), n=1)
                hint = f"; did you mean '{close[0]}'?" if close else "."
                self.report(name, distribution,
                            f"implements unknown hook '{caller.name}'{hint} "
                            f"(known hooks: {', '.join(_hook_names())})")

    def call_each(self, hook_name: str, make_kwargs: Callable[[str, str], dict[str, Any]],
                  on_success: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        """Call ``hook_name`` on each plugin separately, so one failure skips one plugin.

        ``make_kwargs(plugin, distribution)`` builds that plugin's arguments;
        ``on_success(plugin, kwargs)`` runs only when its hook returned normally.
        """
        caller = getattr(self.hook, hook_name)
        for impl in caller.get_hookimpls():
            info = self.infos.get(impl.plugin_name)
            dist = info.distribution if info else "?"
            kwargs = make_kwargs(impl.plugin_name, dist)
            try:
                impl.function(**{k: kwargs[k] for k in impl.argnames})
            except PluginError:
                raise
            except Exception as exc:
                self.report(impl.plugin_name, dist,
                            f"hook {hook_name} raised {type(exc).__name__}: {exc}")
                continue
            if on_success is not None:
                on_success(impl.plugin_name, kwargs)

    def notify(self, hook_name: str, **arguments: Any) -> None:
        """Call the event hook ``hook_name`` of each plugin with its own deep copy of
        ``arguments``, on that plugin's thread, without waiting (:mod:`tactbench.events`);
        what an earlier call did wrong (raised, exited, overran its bound) is warned
        about on stderr here, once, and the run goes on."""
        caller = getattr(self.hook, hook_name)
        calls = [(impl.plugin_name, impl.function, list(impl.argnames))
                 for impl in caller.get_hookimpls()]
        self.events.notify(hook_name, calls, arguments)

    def settle(self) -> None:
        """Wait for the event hooks called so far (each within its bound), then warn
        about what they did wrong (:meth:`tactbench.events.EventLanes.settle`)."""
        self.events.settle()

    def _event_problem(self, plugin: str, message: str) -> None:
        info = self.infos.get(plugin)
        before = len(self.problems)
        self.report(plugin, info.distribution if info else "?", message)
        for problem in self.problems[before:]:
            log.warning("tactbench: warning: %s (the run goes on)", problem)


def _hook_names() -> list[str]:
    return sorted(n for n in dir(hookspecs) if n.startswith("register_")
                  or n in EVENT_HOOKS)


def strict_from_env() -> bool:
    return os.environ.get(STRICT_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def make_plugin_manager(*, builtins: bool = True, entry_points: bool = True,
                        strict: bool | None = None,
                        extra: Iterable[tuple[str, Any]] = ()) -> PluginManager:
    """Build a fresh plugin manager (no global state).

    ``extra`` adds ``(name, plugin_object)`` pairs after the installed ones,
    which is how tests and scripts add a plugin without installing it.
    """
    pm = PluginManager(strict=strict_from_env() if strict is None else strict)
    if builtins:
        for module_name in BUILTIN_PLUGINS:
            try:
                module = importlib.import_module(module_name)
            except Exception as exc:  # a broken built-in must not take the CLI down either
                pm.infos[module_name] = PluginInfo(module_name, "tactbench", __version__,
                                                   "builtin", error=f"{type(exc).__name__}: {exc}")
                pm.report(module_name, "tactbench", f"failed to import: "
                                                    f"{type(exc).__name__}: {exc}")
                continue
            pm.add_plugin(module, name=module_name, distribution="tactbench",
                          version=__version__, source="builtin")
    if entry_points:
        _load_entry_points(pm)
    for name, obj in extra:
        pm.add_plugin(obj, name=name, distribution="(added)", version="", source="added")
    return pm


def _load_entry_points(pm: PluginManager) -> None:
    seen: set[str] = set()
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        dist = ep.dist.name if ep.dist is not None else "?"
        version = ep.dist.version if ep.dist is not None else ""
        if ep.name in pm.infos and pm.infos[ep.name].source == "builtin":
            pm.report(ep.name, dist, f"entry point '{ep.name}' = '{ep.value}' of "
                                     f"distribution '{dist}' has the name of a built-in "
                                     f"plugin and is skipped; rename the entry point",
                      mark=False)
            continue
        if ep.name in seen or ep.name in pm.infos:
            # The same distribution found twice on sys.path: the first one wins, as in Python.
            continue
        seen.add(ep.name)
        obj, problem = _import_quietly(ep)
        if problem is not None:
            pm.infos[ep.name] = PluginInfo(ep.name, dist, version, "entry point",
                                           error=problem)
            pm.report(ep.name, dist, f"failed to import '{ep.value}': {problem}")
            continue
        pm.add_plugin(obj, name=ep.name, distribution=dist, version=version,
                      source="entry point")


def _import_quietly(ep: Any) -> tuple[Any, str | None]:
    """``(plugin object, None)``, or ``(None, problem)`` when importing the entry point
    raised (``SystemExit`` too: a plugin's ``sys.exit`` must not end the command) or
    wrote to stdout (which would break ``--json`` output; what it wrote is dropped)."""
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            obj = ep.load()
    except (Exception, SystemExit) as exc:
        what = f"exit status {exc.code!r}" if isinstance(exc, SystemExit) else str(exc)
        return None, f"{type(exc).__name__}: {what}"
    if printed.getvalue():
        text = " ".join(printed.getvalue().split())
        return None, (f"it printed to stdout when imported ({text[:60]!r}), which would "
                      f"break --json output; skipped")
    return obj, None


def collect_registry(pm: PluginManager) -> Registry:
    """Call every ``register_*`` hook and gather the components into a :class:`Registry`."""
    accepted: dict[tuple[str, str], Component] = {}
    for kind, hook_name in KIND_HOOKS.items():
        pending: dict[str, list[Component]] = {}

        def make_kwargs(plugin: str, dist: str, kind: str = kind) -> dict[str, Any]:
            pending[plugin] = []
            return {"register": _make_register(kind, plugin, dist, pending[plugin])}

        def on_success(plugin: str, _kwargs: dict[str, Any]) -> None:
            for comp in pending[plugin]:
                key = (comp.kind, comp.name)
                if key in accepted:
                    first = accepted[key]
                    pm.report(plugin, comp.distribution,
                              f"{comp.kind} '{comp.name}' is already registered by plugin "
                              f"'{first.plugin}' ({first.distribution}); this one "
                              f"(plugin '{comp.plugin}', target '{comp.target}') is skipped. "
                              f"Rename one of them.")
                    continue
                accepted[key] = comp

        pm.call_each(hook_name, make_kwargs, on_success)
    return Registry(accepted.values(), pm.infos.values(), pm.problems, events=pm.notify,
                    settle=pm.settle)


def _make_register(kind: str, plugin: str, dist: str,
                   sink: list[Component]) -> Callable[..., None]:
    def register(name: str, target: str, *, summary: str,
                 requires: Iterable[str] = ()) -> None:
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise InputError(f"{kind} name {name!r} is invalid: use lower-case letters, "
                             f"digits, '-', '_' and '.'")
        if not isinstance(target, str) or not _TARGET_RE.match(target):
            raise InputError(f"{kind} '{name}': target {target!r} must look like "
                             f"'package.module:Attribute'")
        if not isinstance(summary, str) or not summary.strip():
            raise InputError(f"{kind} '{name}': summary must be a non-empty string")
        if isinstance(requires, str):
            requires = (requires,)
        reqs = tuple(requires)
        if not all(isinstance(r, str) and r for r in reqs):
            raise InputError(f"{kind} '{name}': requires must be module names, got {reqs!r}")
        if any(c.name == name for c in sink):
            raise InputError(f"{kind} '{name}' registered twice by the same plugin")
        sink.append(Component(kind, name, target, summary.strip(), reqs, plugin, dist))

    return register


def load_registry(*, strict: bool | None = None) -> Registry:
    """The registry of everything installed: built-ins and entry-point plugins."""
    return collect_registry(make_plugin_manager(strict=strict))
