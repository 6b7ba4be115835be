"""Built-in encoders, registered through the same hook as third-party ones.

This module only *describes* encoders; each is imported when it is built.
"""

from __future__ import annotations

from tactbench import hookimpl


@hookimpl
def register_encoders(register):
    register("raw", "tactbench.encoders.simple:Raw",
             summary="pressure image only (the study's baseline), 1 channel")
    register("frame-diff", "tactbench.encoders.simple:FrameDiff",
             summary="pressure + signed difference to the previous frame, 2 channels")
