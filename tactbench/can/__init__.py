"""CySkin taxel data over CAN: frame format, codec, sweep assembly, bus load, logs.

The frame format is tactbench's own, documented in ``docs/cyskin-can.md``
(CySkin's vendor protocol is not public); :class:`~tactbench.can.codec.FrameFormat`
makes every assumed number configurable. Modules:

- :mod:`tactbench.can.codec`: taxel values ↔ CAN messages (exact for 16-bit values);
- :mod:`tactbench.can.assembler`: messages → complete sweeps, tolerant of loss,
  duplicates, reordering and malformed traffic;
- :mod:`tactbench.can.busload`: frames and bus load per sweep for a layout and bitrate;
- :mod:`tactbench.can.meta`: label markers and taxel-map announcements (meta frames);
- :mod:`tactbench.can.logs`: writing/reading ``.blf``/``.asc`` logs, a log as sweeps
  (played by the ``replay`` sensor) or as a dataset;
- :mod:`tactbench.can.bus`: opening a python-can bus from tactbench's bus options;
- :mod:`tactbench.can.simulate`: playing recordings as CySkin traffic (``can simulate``);
- :mod:`tactbench.can.record`: recording a bus to a log with markers (``can record``).

This package imports nothing heavy at import time; python-can is imported by the
functions that send, receive or write messages.
"""
