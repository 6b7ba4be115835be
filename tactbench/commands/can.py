"""``tactbench can``: CySkin traffic on a python-can bus — simulate, record, bus load, info."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from tactbench.can.bus import open_bus
from tactbench.can.busload import bus_load, cyskin_like_ids
from tactbench.can.codec import FrameFormat, TaxelMap
from tactbench.can.logs import check_log_out, read_log
from tactbench.can.record import record
from tactbench.can.simulate import load_samples, send_samples, write_samples
from tactbench.cli import Number, json_text
from tactbench.errors import TactbenchError
from tactbench.paths import check_output_file
from tactbench.sensors.cyskin_can import parse_taxel_ids, resolve_taxel_ids
from tactbench.ui import Progress

#: The numbers of these commands, checked before the bus opens (a NaN duration or
#: timeout would never end; a bitrate of 0 is no bus).
BITRATE = Number(minimum=1, maximum=100_000_000, integer=True)
COUNT = Number(minimum=1, integer=True)
RATE = Number(minimum=0, maximum=1e6, exclusive_minimum=True)
SECONDS = Number(minimum=0, maximum=1e9, exclusive_minimum=True)


def _err(text: str) -> None:
    click.echo(text, err=True)


def bus_options(func):
    """The options every bus-facing command shares."""
    opts = [
        click.option("--interface", default="virtual", show_default=True,
                     help="python-can interface (virtual, socketcan, pcan, udp_multicast, ...)."),
        click.option("--channel", default="tactbench", show_default=True,
                     help="Interface channel (vcan0, PCAN_USBBUS1, any name for virtual)."),
        click.option("--bitrate", default=1_000_000, show_default=True, type=BITRATE,
                     help="Nominal bitrate, bit/s."),
        click.option("--data-bitrate", type=BITRATE, default=None,
                     help="CAN FD data-phase bitrate, bit/s."),
        click.option("--format", "format_spec", default="", metavar="SPEC",
                     help="Frame format, e.g. 'ids=standard,base_id=0x200,fd=true' "
                          "(see docs/cyskin-can.md)."),
        click.option("--format-file", type=click.Path(dir_okay=False), default=None,
                     help="Frame format as a JSON file (ids, fd, prefix, base_id, byteorder, "
                          "module_map)."),
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


def _format(format_spec: str, format_file: str | None):
    return FrameFormat.parse(format_spec, format_file)


@click.group("can")
def can_group() -> None:
    """CySkin taxel traffic on a CAN bus: simulate, record, bus load, log info.

    The frame format is documented in docs/cyskin-can.md.
    """


@can_group.command("simulate")
@click.argument("source")
@bus_options
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Write the traffic to a log (.blf/.asc) instead of a bus.")
@click.option("--samples", "limit", type=COUNT, default=None, help="Play at most N samples.")
@click.option("--speed", type=Number(minimum=0, maximum=1e6), default=1.0,
              show_default=True,
              help="Playback speed; 0 sends as fast as possible.")
@click.option("--rate", "rate_hz", type=RATE, default=10.0, show_default=True,
              help="Sweep rate (Hz) for samples without timestamps, and for the bus load.")
@click.option("--gap", "gap_s", type=Number(minimum=0, maximum=86_400), default=0.5, show_default=True,
              help="Seconds between samples.")
@click.option("--no-markers", is_flag=True, help="Send no label markers.")
@click.option("--loop", is_flag=True, help="Repeat until interrupted (bus only).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def simulate_cmd(source: str, interface: str, channel: str, bitrate: int,
                 data_bitrate: int | None, format_spec: str, format_file: str | None,
                 out: str | None, limit: int | None, speed: float, rate_hz: float,
                 gap_s: float, no_markers: bool, loop: bool, as_json: bool) -> None:
    """Play SOURCE's samples as CySkin CAN traffic at the sensor's rate.

    SOURCE is a dataset (folder, or a registered name with options such as
    'synthetic-forearm:users=2') or a CAN log. Each labelled sample is framed
    by label markers, so a recording of the bus keeps the labels.
    """
    fmt = _format(format_spec, format_file)
    if speed < 0:
        raise click.UsageError("--speed must be ≥ 0")
    if loop and out is not None:
        raise click.UsageError("--loop needs a bus, not --out")
    if out is not None:
        check_log_out(out)  # before the samples are loaded
        check_output_file(out, inputs=[source] if Path(source).exists() else [])
    samples, ids = load_samples(source, rate_hz=rate_hz)
    if limit is not None:
        samples = samples[:max(0, limit)]
    if not samples:
        raise TactbenchError(f"{source}: no samples to play")
    taxels = TaxelMap(ids, fmt)
    load = bus_load(taxels, bitrate=bitrate, rate_hz=rate_hz, data_bitrate=data_bitrate)
    if not as_json:
        _err(f"tactbench can simulate: {load.describe()}")
    sweeps = int(sum(len(s.values) for s in samples))
    result: dict[str, Any] = {"source": source, "samples": len(samples), "sweeps": sweeps,
                              "bus_load": load.to_dict(), "format": fmt.to_dict()}
    options = {"rate_hz": rate_hz, "gap_s": gap_s, "markers": not no_markers}
    if out is not None:
        result.update(out=str(out), messages=write_samples(out, samples, taxels, **options))
    else:
        bus = open_bus(interface, channel, bitrate=bitrate, data_bitrate=data_bitrate,
                       fd=fmt.fd)
        sent = 0
        try:
            with Progress(enabled=not as_json) as bars:
                sent = send_samples(bus, samples, taxels, speed=speed, loop=loop,
                                    progress=bars.callback("sending sweeps", sweeps),
                                    **options)
        except KeyboardInterrupt:
            _err("tactbench can simulate: interrupted")
        finally:
            bus.shutdown()
        result.update(interface=interface, channel=channel, messages=sent)
    if as_json:
        click.echo(json_text(result, indent=2))
    else:
        where = result.get("out") or f"{interface}:{channel}"
        _err(f"sent {result['messages']} messages ({result['samples']} samples, "
             f"{result['sweeps']} sweeps) to {where}")


@can_group.command("record")
@click.option("--out", required=True, type=click.Path(dir_okay=False),
              help="Log file to write: .blf or .asc (also .log, .csv, .trc).")
@bus_options
@click.option("--duration", type=SECONDS, default=None, help="Stop after this many seconds.")
@click.option("--idle-timeout", type=SECONDS, default=None,
              help="Stop after this many seconds without a message.")
@click.option("--max-messages", type=COUNT, default=None, help="Stop after N messages.")
@click.option("--label", default=None,
              help="Write a label start marker before and an end marker after the recording.")
@click.option("--user", default=None, help="User recorded in the label marker.")
@click.option("--taxel-ids", default=None,
              help="Announce these taxel ids in the log ('0-10,16-26').")
@click.option("--layout", type=click.Path(dir_okay=False), default=None,
              help="Announce this layout's taxel ids in the log.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def record_cmd(out: str, interface: str, channel: str, bitrate: int, data_bitrate: int | None,
               format_spec: str, format_file: str | None, duration: float | None,
               idle_timeout: float | None, max_messages: int | None, label: str | None,
               user: str | None, taxel_ids: str | None, layout: str | None,
               as_json: bool) -> None:
    """Write the bus to a CAN log (.blf/.asc), with label markers when given.

    Stops at --duration, --idle-timeout, --max-messages or Ctrl-C. The log reads
    back with 'tactbench can info', 'tactbench data info' and the replay sensor.
    """
    fmt = _format(format_spec, format_file)
    check_log_out(out)  # before the bus is opened: nothing recorded is lost to a bad --out
    check_output_file(out)  # an earlier recording is never replaced
    if duration is None and idle_timeout is None and max_messages is None and sys.stdin.isatty():
        _err("recording until Ctrl-C")
    ids = resolve_taxel_ids(taxel_ids, layout) if (taxel_ids or layout) else None
    info = {"label": label, **({"user": user} if user else {})} if label else None
    bus = open_bus(interface, channel, bitrate=bitrate, data_bitrate=data_bitrate, fd=fmt.fd)
    try:
        with Progress(enabled=not as_json) as bars:
            result = record(bus, out, duration=duration, idle_timeout=idle_timeout,
                            max_messages=max_messages, label=info, taxel_ids=ids,
                            bitrate=bitrate, data_bitrate=data_bitrate,
                            progress=bars.callback("recording messages", max_messages))
    finally:
        bus.shutdown()
    if as_json:
        click.echo(json_text(result.to_dict(), indent=2))
    else:
        load = result.bus_load_measured
        if result.stopped == "interrupted":
            _err("tactbench can record: stopped")
        _err(f"recorded {result.messages} messages to {out} in {result.seconds:.1f} s"
             + (f"; bus load {100 * load:.1f} % of {bitrate / 1e6:g} Mbit/s "
                f"(nominal frame lengths)" if load is not None else ""))


@can_group.command("load")
@click.option("--taxels", "n_taxels", type=COUNT, default=None,
              help="A CySkin-like layout of N taxels (modules of 11 in slots 0-10).")
@click.option("--taxel-ids", default=None, help="Taxel ids, e.g. '0-10,16-26'.")
@click.option("--layout", type=click.Path(dir_okay=False), default=None, help="Layout file.")
@click.option("--bitrate", default=1_000_000, show_default=True, type=BITRATE)
@click.option("--data-bitrate", type=BITRATE, default=None, help="CAN FD data-phase bitrate.")
@click.option("--rate", "rate_hz", type=RATE, default=10.0, show_default=True,
              help="Sweeps per second.")
@click.option("--format", "format_spec", default="", metavar="SPEC", help="Frame format.")
@click.option("--format-file", type=click.Path(dir_okay=False), default=None)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def load_cmd(n_taxels: int | None, taxel_ids: str | None, layout: str | None, bitrate: int,
             data_bitrate: int | None, rate_hz: float, format_spec: str,
             format_file: str | None, as_json: bool) -> None:
    """Messages and bus load per sweep for a layout, bitrate and sweep rate."""
    given = [x is not None for x in (n_taxels, taxel_ids, layout)]
    if sum(given) != 1:
        raise click.UsageError("give exactly one of --taxels, --taxel-ids, --layout")
    if n_taxels is not None:
        if n_taxels < 1:
            raise click.UsageError("--taxels must be ≥ 1")
        ids = cyskin_like_ids(n_taxels)
    else:
        ids = resolve_taxel_ids(taxel_ids, layout)
    fmt = _format(format_spec, format_file)
    load = bus_load(TaxelMap(ids, fmt), bitrate=bitrate, rate_hz=rate_hz,
                    data_bitrate=data_bitrate)
    if as_json:
        click.echo(json_text({"format": fmt.to_dict(), **load.to_dict()}, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="CySkin CAN bus load", title_justify="left")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for name, value in [
        ("taxels", f"{load.taxels}"), ("messages per sweep", f"{load.messages_per_sweep}"),
        ("payload bytes per sweep", f"{load.payload_bytes_per_sweep}"),
        ("bits per sweep (nominal / worst)",
         f"{load.bits_per_sweep:.0f} / {load.bits_per_sweep_worst:.0f}"),
        ("sweep time on the wire", f"{load.sweep_ms:.1f} ms"),
        ("messages per second", f"{load.messages_per_second:.0f}"),
        ("bus load (nominal / worst)", f"{100 * load.load:.1f} % / {100 * load.load_worst:.1f} %"),
        ("fits", "yes" if load.fits else "NO"),
    ]:
        table.add_row(name, value)
    Console().print(table)
    click.echo(load.describe())


@can_group.command("info")
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@click.option("--taxel-ids", default=None, help="The layout's taxel ids (default: from the log).")
@click.option("--format", "format_spec", default="", metavar="SPEC", help="Frame format.")
@click.option("--format-file", type=click.Path(dir_okay=False), default=None)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def info_cmd(log: str, taxel_ids: str | None, format_spec: str, format_file: str | None,
             as_json: bool) -> None:
    """What a CAN log holds: sweeps, labelled samples per class, lost messages."""
    fmt = _format(format_spec, format_file)
    ids = parse_taxel_ids(taxel_ids) if taxel_ids else None
    summary = read_log(Path(log), taxel_ids=ids, fmt=fmt).summary()
    if as_json:
        click.echo(json_text(summary, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"CAN log {log}", title_justify="left")
    table.add_column("quantity")
    table.add_column("value")
    asm = summary["assembler"]
    fps = summary["frames_per_sample"]
    for name, value in [
        ("taxels", f"{summary['taxels']} ({summary['taxel_ids_from']})"),
        ("sweeps", str(summary["sweeps"])),
        ("samples", str(summary["samples"])),
        ("samples per class", ", ".join(f"{k}: {v}" for k, v in
                                        summary["samples_per_class"].items()) or "-"),
        ("frames per sample (min/median/max)",
         f"{fps['min']}/{fps['median']:g}/{fps['max']}" if fps else "-"),
        ("unlabelled sweeps", str(summary["unlabelled_sweeps"])),
        ("incomplete sweeps / lost messages",
         f"{asm['incomplete_sweeps']} / {asm['lost_messages']}"),
        ("duplicates / late / lost sweeps",
         f"{asm['duplicates']} / {asm['late']} / {asm['lost_sweeps']}"),
        ("other traffic", ", ".join(f"{k}: {v}" for k, v in asm["rejected"].items()) or "-"),
    ]:
        table.add_row(name, value)
    Console().print(table)
