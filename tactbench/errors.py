"""Exceptions tactbench raises on purpose; the CLI turns them into one-line errors."""

from __future__ import annotations


class TactbenchError(Exception):
    """Base class: something the user can fix (bad input, bad name, broken plugin)."""


class PluginError(TactbenchError):
    """A plugin failed to load or registered something invalid (fatal in strict mode)."""


class UnknownComponentError(TactbenchError, LookupError):
    """No component of that kind and name is registered."""

    def __str__(self) -> str:  # LookupError would quote the message
        return str(self.args[0]) if self.args else ""


class ComponentLoadError(TactbenchError):
    """A component's target did not import, or its requirements are missing."""
