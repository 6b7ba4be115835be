"""Plugin discovery and the component registry.

Plugins register *descriptions* of components (``name → "module:Attribute"``);
nothing a component needs is imported until :meth:`Registry.build` builds it.

Where plugins come from, in this order:

1. the built-in modules in :data:`BUILTIN_PLUGINS` (registered like any other);
2. the entry-point group ``tactbench`` of installed distributions.

A plugin that fails to import, implements an unknown hook, or whose hook raises
is recorded as a :class:`PluginProblem` and skipped; the rest keep working.
With ``TACTBENCH_STRICT_PLUGINS=1`` the first such problem raises
:class:`~tactbench.errors.PluginError` instead.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.util
import inspect
import os
import re
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterable

import pluggy

from tactbench import __version__, hookspecs
from tactbench.errors import (
    ComponentLoadError,
    InputError,
    PluginError,
    TactbenchError,
    UnknownComponentError,
)

ENTRY_POINT_GROUP = "tactbench"
STRICT_ENV = "TACTBENCH_STRICT_PLUGINS"

#: Modules whose hooks register the built-in components, in load order.
BUILTIN_PLUGINS: tuple[str, ...] = (
    "tactbench.encoders",
    "tactbench.datasets",
    "tactbench.sensors",
    "tactbench.classifiers",
)

#: kind → the hook that registers components of that kind.
KIND_HOOKS: dict[str, str] = {
    "sensor": "register_sensors",
    "dataset": "register_datasets",
    "encoder": "register_encoders",
    "classifier": "register_classifiers",
}
KINDS: tuple[str, ...] = tuple(KIND_HOOKS)

_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_.-]*$")
_TARGET_RE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


@dataclass(frozen=True)
class PluginInfo:
    """One plugin: a built-in module or an installed entry point."""

    name: str
    distribution: str
    version: str
    source: str  # "builtin" or "entry point"
    hooks: tuple[str, ...] = ()
    error: str | None = None

    def label(self) -> str:
        return f"'{self.name}' ({self.distribution} {self.version})"


@dataclass(frozen=True)
class PluginProblem:
    """Something wrong with a plugin, reported instead of crashing."""

    plugin: str
    distribution: str
    message: str

    def __str__(self) -> str:
        return f"plugin '{self.plugin}' ({self.distribution}): {self.message}"


@dataclass(frozen=True)
class Component:
    """A registered component: what it is called and where its code lives."""

    kind: str
    name: str
    target: str
    summary: str
    requires: tuple[str, ...]
    plugin: str
    distribution: str

    def missing_requirements(self) -> list[str]:
        """Required top-level modules that are not installed (found without importing)."""
        missing = []
        for module in self.requires:
            top = module.split(".", 1)[0]
            if importlib.util.find_spec(top) is None:
                missing.append(module)
        return missing

    def load(self) -> Any:
        """Import and return the target object (usually a class)."""
        missing = self.missing_requirements()
        if missing:
            raise ComponentLoadError(
                f"{self.kind} '{self.name}' (plugin '{self.plugin}') needs "
                f"{', '.join(missing)}, which is not installed"
            )
        module_name, _, attr_path = self.target.partition(":")
        try:
            obj: Any = importlib.import_module(module_name)
            for part in attr_path.split("."):
                obj = getattr(obj, part)
        except Exception as exc:  # any import-time failure of a plugin's code
            raise ComponentLoadError(
                f"{self.kind} '{self.name}' (plugin '{self.plugin}'): cannot import "
                f"target '{self.target}': {type(exc).__name__}: {exc}"
            ) from exc
        return obj


class Registry:
    """All components registered by all plugins, by kind and name."""

    def __init__(
        self,
        components: Iterable[Component],
        plugins: Iterable[PluginInfo] = (),
        problems: Iterable[PluginProblem] = (),
    ) -> None:
        self._by_kind: dict[str, dict[str, Component]] = {kind: {} for kind in KINDS}
        for comp in components:
            self._by_kind[comp.kind][comp.name] = comp
        self.plugins: list[PluginInfo] = list(plugins)
        self.problems: list[PluginProblem] = list(problems)

    def components(self, kind: str | None = None) -> list[Component]:
        kinds = KINDS if kind is None else (_check_kind(kind),)
        return [c for k in kinds for c in self._by_kind[k].values()]

    def names(self, kind: str) -> list[str]:
        return sorted(self._by_kind[_check_kind(kind)])

    def get(self, kind: str, name: str) -> Component:
        table = self._by_kind[_check_kind(kind)]
        if name in table:
            return table[name]
        known = sorted(table)
        close = difflib.get_close_matches(name, known, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else "."
        raise UnknownComponentError(
            f"unknown {kind} '{name}'{hint} Known {kind}s: {', '.join(known) or 'none'}"
        )

    def build(self, kind: str, spec: str, **options: Any) -> Any:
        """Build a component from ``"name"`` or ``"name:key=value,..."``.

        Keyword ``options`` override those in ``spec``. An unknown option name raises
        :class:`~tactbench.errors.InputError` listing the accepted ones; a bad option value
        raises what the component raises (an ``InputError`` for a user's mistake), with
        the component's name put in front of the message. The built object is checked
        against its kind's contract (:func:`tactbench.contracts.check`):
        :class:`~tactbench.errors.ContractError` names what it misses.
        """
        name, spec_options = parse_spec(spec)
        spec_options.update(options)
        comp = self.get(kind, name)
        factory = comp.load()
        spec_options = _resolve_positional(comp, factory, spec_options, spec)
        _check_options(comp, factory, spec_options)
        from tactbench.contracts import check

        try:
            obj = factory(**spec_options)
        except TactbenchError as exc:
            # Keep the type (MissingFileError stays a FileNotFoundError) and traceback;
            # only say which component refused the option.
            who = f"{kind} '{comp.name}'"
            if exc.args and isinstance(exc.args[0], str) and who not in exc.args[0]:
                exc.args = (f"{who}: {exc.args[0]}", *exc.args[1:])
            raise
        return check(kind, obj, name=comp.name, plugin=comp.plugin)


    def resolve(self, kind: str, spec: str) -> str:
        """``spec`` with a bare leading value given its option's name
        (``sklearn:SVC,C=10`` → ``sklearn:C=10,estimator=SVC``), options sorted: the one
        spelling a cell identity records."""
        name, options = parse_spec(spec)
        if POSITIONAL in options:
            comp = self.get(kind, name)
            options = _resolve_positional(comp, comp.load(), options, spec)
        return format_spec(name, options)


def _resolve_positional(comp: Component, factory: Any, options: dict[str, Any],
                        spec: str) -> dict[str, Any]:
    """``options`` with :data:`POSITIONAL` renamed to the factory's ``positional_option``."""
    if POSITIONAL not in options:
        return options
    target = getattr(factory, "positional_option", None)
    if not isinstance(target, str):
        raise InputError(f"{comp.kind} '{comp.name}' takes no value without a name: write "
                         f"key=value in '{spec}'")
    if target in options:
        raise InputError(f"option '{target}' is given twice in '{spec}' (once without its "
                         f"name); give it once")
    out = {k: v for k, v in options.items() if k != POSITIONAL}
    out[target] = options[POSITIONAL]
    return out


def _check_kind(kind: str) -> str:
    if kind not in KIND_HOOKS:
        raise InputError(f"unknown component kind '{kind}'; kinds: {', '.join(KINDS)}")
    return kind


def _check_options(comp: Component, factory: Any, options: dict[str, Any]) -> None:
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):
        return
    params = sig.parameters.values()
    if any(p.kind is p.VAR_KEYWORD for p in params):
        return
    accepted = [p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]
    for key in options:
        if key not in accepted:
            close = difflib.get_close_matches(key, accepted, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else "."
            raise InputError(
                f"{comp.kind} '{comp.name}' has no option '{key}'{hint} "
                f"Options: {', '.join(accepted) or 'none'}"
            )


#: Key under which :func:`parse_spec` keeps a leading value without ``key=``
#: (``sklearn:SVC,C=10``); the component's ``positional_option`` names what it fills.
POSITIONAL = "_"


def parse_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """Split ``"farneback:winsize=9,levels=2"`` into a name and typed options.

    Values become ``int``, ``float``, ``bool`` (``true``/``false``), ``None``
    (``none``) or stay strings. An option given twice is refused (naming it), rather
    than the last one winning silently. The first item may be a bare value
    (``sklearn:SVC,C=10``): it is kept under :data:`POSITIONAL` and given to the option
    the component's factory names in its ``positional_option`` attribute
    (:meth:`Registry.resolve`).
    """
    if not isinstance(spec, str):
        raise InputError(f"a component is named by text such as 'farneback:winsize=9', "
                         f"got {type(spec).__name__} {spec!r}")
    name, _, rest = spec.partition(":")
    name = name.strip()
    if not name:
        raise InputError(f"empty component name in '{spec}'")
    options: dict[str, Any] = {}
    if rest.strip():
        for n, item in enumerate(rest.split(",")):
            key, eq, value = item.partition("=")
            key = key.strip()
            if n == 0 and not eq and key:  # "sklearn:SVC,C=10": the positional value
                options[POSITIONAL] = _coerce(key)
                continue
            if not eq or not key.isidentifier():
                raise InputError(
                    f"bad option '{item}' in '{spec}': expected key=value, as in "
                    f"'{name}:key=value,other=value'"
                )
            if key in options:
                raise InputError(f"option '{key}' is given twice in '{spec}'; give it once")
            options[key] = _coerce(value.strip())
    return name, options


def _coerce(text: str) -> Any:
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    if lowered in ("none", "null"):
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def format_spec(name: str, options: dict[str, Any]) -> str:
    """The inverse of :func:`parse_spec`, with options in sorted order."""
    if not options:
        return name
    return name + ":" + ",".join(f"{k}={_format_value(v)}" for k, v in sorted(options.items()))


def _format_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "none"
    return str(value)


# --------------------------------------------------------------------------- loading


class PluginManager(pluggy.PluginManager):
    """A pluggy manager that also remembers where each plugin came from and what failed."""

    def __init__(self, *, strict: bool = False) -> None:
        super().__init__(ENTRY_POINT_GROUP)
        self.add_hookspecs(hookspecs)
        self.strict = strict
        self.infos: dict[str, PluginInfo] = {}
        self.problems: list[PluginProblem] = []

    def report(self, plugin: str, distribution: str, message: str) -> None:
        problem = PluginProblem(plugin, distribution, message)
        self.problems.append(problem)
        info = self.infos.get(plugin)
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


def _hook_names() -> list[str]:
    return sorted(n for n in dir(hookspecs) if n.startswith("register_"))


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
    from importlib.metadata import entry_points

    seen: set[str] = set()
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        dist = ep.dist.name if ep.dist is not None else "?"
        version = ep.dist.version if ep.dist is not None else ""
        if ep.name in seen or ep.name in pm.infos:
            # The same distribution found twice on sys.path: the first one wins, as in Python.
            continue
        seen.add(ep.name)
        try:
            obj = ep.load()
        except Exception as exc:
            pm.infos[ep.name] = PluginInfo(ep.name, dist, version, "entry point",
                                           error=f"{type(exc).__name__}: {exc}")
            pm.report(ep.name, dist, f"failed to import '{ep.value}': "
                                     f"{type(exc).__name__}: {exc}")
            continue
        pm.add_plugin(obj, name=ep.name, distribution=dist, version=version,
                      source="entry point")


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
    return Registry(accepted.values(), pm.infos.values(), pm.problems)


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
