"""The component registry: every registered component, by kind and name, built on demand.

Plugins register *descriptions* of components (``name → "module:Attribute"``, a
:class:`Component`); nothing a component needs is imported until :meth:`Registry.build`
builds it and checks it against its kind's contract. Where the descriptions come from
(built-ins, entry points) is :mod:`tactbench.plugins`' job.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.util
import inspect
from dataclasses import dataclass
from typing import Any, Callable, Iterable

from tactbench.contracts import check
from tactbench.errors import ComponentLoadError, InputError, TactbenchError, UnknownComponentError
from tactbench.specs import POSITIONAL, format_spec, parse_spec

#: kind → the hook that registers components of that kind.
KIND_HOOKS: dict[str, str] = {
    "sensor": "register_sensors",
    "dataset": "register_datasets",
    "encoder": "register_encoders",
    "classifier": "register_classifiers",
    "split": "register_splits",
    "test-window": "register_test_windows",
    "paired-test": "register_paired_tests",
}
KINDS: tuple[str, ...] = tuple(KIND_HOOKS)


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
        events: Callable[..., None] | None = None,
        settle: Callable[[], None] | None = None,
    ) -> None:
        self._events = events  # the plugin manager's event caller (PluginManager.notify)
        self._settle = settle  # and its wait for the calls (PluginManager.settle)
        self._by_kind: dict[str, dict[str, Component]] = {kind: {} for kind in KINDS}
        for comp in components:
            self._by_kind[comp.kind][comp.name] = comp
        self.plugins: list[PluginInfo] = list(plugins)
        self.problems: list[PluginProblem] = list(problems)

    def notify(self, event: str, **arguments: Any) -> None:
        """Call the event hook ``event`` (``cell_finished``, ``look_finished``: see
        :mod:`tactbench.hookspecs`) of every plugin implementing it, each with its own
        copy of ``arguments`` and without waiting (:mod:`tactbench.events`); nothing for
        a registry made without plugins."""
        if self._events is not None:
            self._events(event, **arguments)

    def without_events(self) -> "Registry":
        """This registry's components and plugins, calling no event hook: for work that
        is not a result to report (``tactbench reproduce``'s check of stored cells)."""
        return Registry(self.components(), self.plugins, self.problems)

    def settle(self) -> None:
        """Wait for the event hooks notified so far, each within its bound, and warn
        about what they did wrong (:mod:`tactbench.events`); nothing for a registry made
        without plugins."""
        if self._settle is not None:
            self._settle()

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
