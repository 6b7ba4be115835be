"""tactbench: benchmark toolkit for tactile-image preprocessing in gesture recognition.

Importing this package is cheap: it pulls in pluggy and nothing heavy. Heavy
libraries (torch, kornia, cv2, python-can, ...) are imported by the components
that use them, when they are built.
"""

from __future__ import annotations

import pluggy

from tactbench.errors import TactbenchError
from tactbench.kernels import pin_cpu_kernels

__version__ = "0.1.0"

#: Marker for plugin hook implementations: ``@hookimpl def register_encoders(register): ...``
hookimpl = pluggy.HookimplMarker("tactbench")

__all__ = ["__version__", "hookimpl"]


# The CPU kernels are pinned (TACTBENCH_CPU_KERNELS, avx2 by default) when tactbench is
# imported, before numpy, OpenCV or torch are, so that a notebook's run computes what a
# command's does (docs/reliability.md, "Numbers across machines"). A bad value is left
# for the command line or the run to refuse in one line.
try:
    pin_cpu_kernels()
except TactbenchError:
    pass
