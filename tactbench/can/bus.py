"""Opening a python-can bus: the one place that turns tactbench's bus options into one.

Every bus-facing part (the ``cyskin-can`` sensor, ``tactbench can simulate`` and
``tactbench can record``) opens its bus here, so a bitrate, FD or filter rule is
written once.
"""

from __future__ import annotations

from typing import Any

from tactbench.errors import InputError


def open_bus(interface: str = "virtual", channel: str = "tactbench", *,
             bitrate: int = 1_000_000, data_bitrate: int | None = None, fd: bool = False,
             receive_own_messages: bool = False, can_filters: list[dict] | None = None,
             who: str = "") -> Any:
    """A python-can bus on ``interface``/``channel``.

    Parameters
    ----------
    interface, channel : str
        python-can interface (``virtual``, ``socketcan``, ``pcan``, ...) and its channel
        (``vcan0``, ``PCAN_USBBUS1``; any name for ``virtual``).
    bitrate : int
        Nominal bitrate in bit/s; passed to real interfaces (``virtual`` has none).
    data_bitrate : int, optional
        CAN FD data-phase bitrate in bit/s (default: ``bitrate``), used when ``fd``.
    receive_own_messages : bool
        ``virtual`` only: also receive what this bus sends (tests).
    can_filters : list of dict, optional
        python-can filters (``can_id``, ``can_mask``, ``extended``).
    who : str
        Prefix of the error message (``"cyskin-can"``).

    Raises :class:`~tactbench.errors.InputError` naming the interface and channel when
    the bus cannot be opened (no such device, driver missing, ...).
    """
    import can

    kwargs: dict[str, Any] = {"interface": interface, "channel": channel}
    if interface != "virtual":
        kwargs["bitrate"] = bitrate
        if fd:
            kwargs.update(fd=True, data_bitrate=data_bitrate or bitrate)
    else:
        kwargs["receive_own_messages"] = receive_own_messages
    if can_filters is not None:
        kwargs["can_filters"] = can_filters
    try:
        return can.Bus(**kwargs)
    except Exception as exc:  # python-can raises many types (CanError, OSError, ImportError)
        prefix = f"{who}: " if who else ""
        raise InputError(f"{prefix}cannot open {interface} channel '{channel}': "
                         f"{type(exc).__name__}: {exc}") from exc
