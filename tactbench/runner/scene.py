"""The run configuration (a *scene*): what to compare, on what, and how to run it.

A scene file is TOML with the same fields as :class:`Scene`; ``encoder``,
``classifier``, ``L`` and ``seed`` are accepted for their plural fields, and a single
value for a list field.

(The runner's scene is the run configuration; the synthetic flow scenes of
:mod:`tactbench.encoders.flowbench` are a different thing with their own name.)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Iterable

from tactbench.errors import InputError, MissingFileError

#: Where cells run: this machine (serially or in ``workers`` processes) or a dask cluster.
EXECUTORS = ("local", "dask")


@dataclass
class Scene:
    """Everything a run needs to know; a scene file holds the same fields (TOML)."""

    dataset: str = "synthetic-forearm"
    encoders: list[str] = field(default_factory=lambda: ["raw", "farneback"])
    classifiers: list[str] = field(default_factory=lambda: ["small-cnn-lstm"])
    lengths: list[int] = field(default_factory=lambda: [5])  # window lengths L, frames
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    split: str = "paper"
    test_per_class: int = 30
    profile: str = "quick"
    pixel_mm: float | None = None  # None: the profile's
    imaging: str = "linear"
    precision: str | None = None  # storage of cached encodings (PRECISIONS); None: the profile's
    device: str = "cpu"
    threads: int | None = None  # torch threads per cell; None: cores / workers
    executor: str = "local"
    workers: int = 1
    scheduler: str | None = None
    out: str = "tactbench-out"
    rerun: bool = False
    save_models: bool = False  # OUT/models/<cell key>.safetensors, usable by `tactbench live`

    def resolved_pixel_mm(self) -> float:
        """The tactile-image pixel size in mm: the scene's, else its profile's."""
        if self.pixel_mm is not None:
            return float(self.pixel_mm)
        from tactbench.profiles import get_profile

        return get_profile(self.profile).pixel_mm

    def resolved_precision(self) -> str:
        """How cached encodings are stored: the scene's precision, else its profile's."""
        if self.precision is not None:
            return str(self.precision)
        from tactbench.profiles import get_profile

        return get_profile(self.profile).precision

    def resolved_threads(self) -> int:
        """torch threads per cell: the scene's, else this machine's cores shared by workers."""
        if self.threads is not None:
            return int(self.threads)
        return max(1, (os.cpu_count() or 1) // max(1, self.workers))


def parse_lengths(values: Iterable[str | int]) -> list[int]:
    """``["5"]``, ``["1-6"]``, ``["2", "4-5"]`` → sorted unique window lengths."""
    out: set[int] = set()
    for value in values:
        text = str(value).strip()
        try:
            if "-" in text.lstrip("-"):
                lo, hi = text.split("-", 1)
                start, stop = int(lo), int(hi)
                if stop < start:
                    raise ValueError
                out.update(range(start, stop + 1))
            else:
                out.add(int(text))
        except ValueError:
            raise InputError(f"bad window length '{value}': use a number (5) or a range "
                             f"(1-6)") from None
    return sorted(out)


_ALIASES = {"encoder": "encoders", "classifier": "classifiers", "L": "lengths",
            "seed": "seeds"}


def load_scene_file(path: str | Path) -> dict[str, Any]:
    """Read a TOML scene file into a dict of :class:`Scene` fields (validated names)."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise MissingFileError(f"scene file not found: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    known = {f.name for f in fields(Scene)}
    scene: dict[str, Any] = {}
    for key, value in data.items():
        name = _ALIASES.get(key, key)
        if name not in known:
            import difflib

            close = difflib.get_close_matches(name, sorted(known), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise InputError(f"{path}: unknown field '{key}'{hint}")
        if name in ("encoders", "classifiers", "seeds") and not isinstance(value, list):
            value = [value]
        if name == "lengths":
            value = parse_lengths(value if isinstance(value, list) else [value])
        scene[name] = value
    return scene
