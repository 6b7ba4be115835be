"""The spec grammar: one component named with its options, ``"name:key=value,..."``.

``parse_spec`` reads it (values typed: int, float, bool, none, text), ``format_spec``
writes the one canonical spelling (options sorted). Scene files, the command line,
cell identities and the data layer's own option strings (normalisation, splits) all use
it; nothing here knows what a component is.
"""

from __future__ import annotations

from typing import Any

from tactbench.errors import InputError

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
    (:meth:`tactbench.registry.Registry.resolve`).
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
