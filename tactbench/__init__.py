"""tactbench: benchmark toolkit for tactile-image preprocessing in gesture recognition.

Importing this package is cheap: it pulls in pluggy and nothing heavy. Heavy
libraries (torch, kornia, cv2, python-can, ...) are imported by the components
that use them, when they are built.
"""

from __future__ import annotations

import pluggy

__version__ = "0.1.0"

#: Marker for plugin hook implementations: ``@hookimpl def register_encoders(register): ...``
hookimpl = pluggy.HookimplMarker("tactbench")

__all__ = ["__version__", "hookimpl"]
