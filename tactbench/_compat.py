"""Old import paths kept working for one release after the package was reorganised.

``import tactbench.recording`` (an old path) gives *the same module object* as
``tactbench.data.recording`` (its new home), with a :class:`DeprecationWarning`, so
attributes, monkeypatching and ``isinstance`` checks behave alike. No file is left at the
old place: a finder on :data:`sys.meta_path` (installed by ``import tactbench``) answers
for the old names.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

#: old module → its new home; the old names go in tactbench 0.3.
MOVED_MODULES: dict[str, str] = {
    "tactbench.recording": "tactbench.data.recording",
    "tactbench.layout": "tactbench.data.layout",
    "tactbench.imaging": "tactbench.data.imaging",
    "tactbench.splits": "tactbench.data.splits",
    "tactbench.windows": "tactbench.data.windows",
    "tactbench.encoding": "tactbench.encoders.parallel",
    "tactbench.flowbench": "tactbench.encoders.flowbench",
    "tactbench.stability": "tactbench.encoders.stability",
    "tactbench.training": "tactbench.classifiers.training",
    "tactbench.reports": "tactbench.runner.writers",
}


#: (module, name) → the module the name moved to, when a module was split; the old
#: place answers through the module's ``__getattr__`` (:func:`moved_name`).
MOVED_NAMES: dict[tuple[str, str], str] = {
    ("tactbench.data.recording", "Dataset"): "tactbench.data.dataset",
    ("tactbench.data.recording", "Normalisation"): "tactbench.data.normalisation",
    ("tactbench.data.recording", "FORMAT_NAME"): "tactbench.data.store",
    ("tactbench.data.recording", "SCHEMA_VERSION"): "tactbench.data.store",
    ("tactbench.data.recording", "MANIFEST"): "tactbench.data.store",
    ("tactbench.data.recording", "ARRAYS"): "tactbench.data.store",
    ("tactbench.data.layout", "load_layout"): "tactbench.data.layout_io",
    ("tactbench.data.layout", "cyskin_forearm"): "tactbench.datasets.forearm",
    ("tactbench.live", "live_metadata"): "tactbench.classifiers.io",
}


def moved_name(module: str, name: str):
    """The object ``name`` that left ``module``, with a warning; ``AttributeError`` for a
    name that never lived there (so ``hasattr`` and ``from ... import`` behave)."""
    new = MOVED_NAMES.get((module, name))
    if new is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    warnings.warn(f"{module}.{name} moved to {new}.{name}; the old place goes in "
                  f"tactbench 0.3", DeprecationWarning, stacklevel=3)
    return getattr(importlib.import_module(new), name)


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old names and loads them as the new modules."""

    def __init__(self) -> None:
        self._specs: dict[str, importlib.machinery.ModuleSpec] = {}

    def find_spec(self, fullname: str, path=None, target=None):
        if fullname not in MOVED_MODULES:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec) -> ModuleType:
        new = MOVED_MODULES[spec.name]
        warnings.warn(f"{spec.name} moved to {new}; the old name goes in tactbench 0.3",
                      DeprecationWarning, stacklevel=2)
        module = importlib.import_module(new)
        self._specs[new] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the new module is already imported. The import system has just
        set ``module.__spec__`` to the old name's spec: give the module its own back."""
        module.__spec__ = self._specs[module.__name__]


def install() -> None:
    """Put the finder on :data:`sys.meta_path` once."""
    if not any(isinstance(f, _MovedModules) for f in sys.meta_path):
        sys.meta_path.append(_MovedModules())
