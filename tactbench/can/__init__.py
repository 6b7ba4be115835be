"""CySkin taxel data over CAN: frame format, codec, sweep assembly, bus load, logs.

The frame format is tactbench's own, documented in ``docs/cyskin-can.md``
(CySkin's vendor protocol is not public); :class:`~tactbench.can.codec.FrameFormat`
makes every assumed number configurable. Modules:

- :mod:`tactbench.can.codec`: taxel values ↔ CAN messages (exact for 16-bit values);
- :mod:`tactbench.can.assembler`: messages → complete sweeps, tolerant of loss,
  duplicates, reordering and malformed traffic;
- :mod:`tactbench.can.busload`: frames and bus load per sweep for a layout and bitrate;
- :mod:`tactbench.can.logs`: label markers, writing/reading ``.blf``/``.asc`` logs;
- :mod:`tactbench.can.simulate`: playing recordings as CySkin traffic.

This package imports nothing heavy at import time; python-can is imported by the
functions that send, receive or write messages.
"""
