"""Built-in sensors, registered through the same hook as third-party ones.

This module only *describes* sensors (no numpy at import time); each is
imported when it is built.
"""

from __future__ import annotations

from tactbench import hookimpl


@hookimpl
def register_sensors(register):
    register("replay", "tactbench.sensors.replay:Replay",
             summary="plays a recorded sample, or every sweep of a CAN log, as frames; "
                     "path, sample, realtime, loop (CAN logs: taxel_ids, format, missing)")
    register("cyskin-can", "tactbench.sensors.cyskin_can:CySkinCAN", summary="CySkin sweeps from a CAN bus via python-can; options interface, channel, bitrate, taxel_ids or layout, format", requires=("can",))
