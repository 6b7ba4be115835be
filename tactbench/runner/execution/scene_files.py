"""Scene files: a :class:`~tactbench.runner.execution.scene.Scene` written as TOML (or
JSON, for a ``.json`` file) with the same fields; ``encoder``, ``classifier`` and ``seed``
are accepted for their plural fields, and a single value for a list field. A renamed
field (``lengths``) is refused with a line naming the new one; an unknown field or a
field given twice (``seed`` and ``seeds``, or a JSON key twice) is refused in one line
naming the file and the field. Paths in the file are taken from the file's folder.
"""

from __future__ import annotations

import difflib
import json
import os
from dataclasses import fields
from pathlib import Path
from typing import Any

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from tactbench.datasets.loading import is_path_spec
from tactbench.errors import InputError, MissingFileError
from tactbench.integrity import check_regular_file, read_regular_bytes
from tactbench.runner.execution.scene import _ALIASES, RENAMED, Scene, _show

#: A scene file is a few lines; a larger file is refused before it is read.
MAX_SCENE_FILE_BYTES = 1 << 20


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    seen: dict[str, Any] = {}
    for key, value in pairs:
        if key in seen:
            raise InputError(f"key '{key}' is given twice")
        seen[key] = value
    return seen


def load_scene_file(path: str | Path) -> dict[str, Any]:
    """Read a scene file (TOML, or JSON when it ends in ``.json``) into a dict of
    :class:`Scene` fields, checked by the Scene they make (:meth:`Scene.of`, messages
    naming the file and the field), normalised (lists, parsed lengths and seeds), paths
    taken from the file's folder."""
    path = Path(path)
    raw = read_scene_file(path)
    labels = {name: f"{path}: field '{name}'" for name in raw}
    scene = Scene.of(raw, labels=labels)
    return {name: getattr(scene, name) for name in raw}


def read_scene_file(path: str | Path) -> dict[str, Any]:
    """A scene file's fields as written (TOML, or JSON when it ends in ``.json``): field
    names checked (an unknown or renamed field, one given twice), aliases taken
    (``seed`` → ``seeds``), text paths taken from the file's folder; values unchecked
    (the :class:`Scene` they make checks them)."""
    path = Path(path)
    is_json = path.suffix.lower() == ".json"
    try:
        size = check_regular_file(path, what="scene file")  # a FIFO, a dangling link
        if size > MAX_SCENE_FILE_BYTES:
            raise InputError(f"{path}: a scene file of {size} bytes; scene files are a few "
                             f"lines (at most {MAX_SCENE_FILE_BYTES} bytes)")
        text = read_regular_bytes(path, limit=MAX_SCENE_FILE_BYTES,  # never a FIFO
                                  what="scene file").decode("utf-8")
    except FileNotFoundError:
        raise MissingFileError(f"scene file not found: {path}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (not UTF-8)") from None
    except (OSError, ValueError) as exc:  # a folder, no permission, a NUL in the name
        raise InputError(f"{path}: cannot read the scene file: "
                         f"{getattr(exc, 'strerror', None) or exc}") from None
    fmt = "JSON" if is_json else "TOML"
    try:
        if is_json:
            data = json.loads(text, object_pairs_hook=_no_duplicate_keys)
        else:
            data = tomllib.loads(text)
    except InputError as exc:
        raise InputError(f"{path}: not valid {fmt}: {exc}") from None
    except (ValueError, RecursionError) as exc:  # TOMLDecodeError, JSONDecodeError: ValueErrors
        raise InputError(f"{path}: not valid {fmt}: {str(exc).splitlines()[0][:200]}") \
            from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: a scene file holds a table of fields, got "
                         f"{type(data).__name__}")
    known = {f.name for f in fields(Scene)}
    raw: dict[str, Any] = {}
    given_as: dict[str, str] = {}
    for key, value in data.items():
        if key in RENAMED:
            raise InputError(f"{path}: field '{key}' is now '{RENAMED[key]}'")
        name = _ALIASES.get(key, key)
        if name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise InputError(f"{path}: unknown field {_show(key)}{hint}")
        if name in given_as:
            raise InputError(f"{path}: field '{name}' is given twice (as "
                             f"'{given_as[name]}' and '{key}')")
        given_as[name] = key
        raw[name] = value
    return _relative_to(raw, path.parent)


def _relative_to(values: dict[str, Any], folder: Path) -> dict[str, Any]:
    """A scene file's paths (``out``, a ``dataset`` path) with ``~`` expanded and,
    when relative, taken from the scene file's folder, not the working folder."""
    for name in ("out", "dataset"):
        text = values.get(name)
        if isinstance(text, str) and text.strip() and "\x00" not in text \
                and (name == "out" or is_path_spec(text)):
            path = Path(os.path.expanduser(text))
            values[name] = str(path if path.is_absolute() else folder / path)
    return values
