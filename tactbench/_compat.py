"""Old import paths kept working for one release after the package was reorganised.

Each old module (``tactbench/recording.py``, ...) is a two-line file that calls
:func:`moved`, which warns once and makes the old name *the same module object* as
the new one, so attributes, monkeypatching and ``isinstance`` checks behave alike.
"""

from __future__ import annotations

import importlib
import sys
import warnings

#: old module → its new home; removed in tactbench 0.3.
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
    "tactbench.reports": "tactbench.runner.reports",
}


def moved(old: str) -> None:
    """Alias module ``old`` to its new home (called from the old module's body)."""
    new = MOVED_MODULES[old]
    warnings.warn(f"{old} moved to {new}; the old name goes in tactbench 0.3",
                  DeprecationWarning, stacklevel=3)
    sys.modules[old] = importlib.import_module(new)
