"""``tactbench live``: classify gestures from a sensor as its sweeps arrive."""

from __future__ import annotations

import sys
from typing import Any

import click

from tactbench.cli import Number, get_registry, json_text
from tactbench.contracts import SENSOR
from tactbench.errors import InputError
from tactbench.live import LiveClassifier, LiveModel, run_summary
from tactbench.specs import parse_spec


def _build_sensor(ctx: click.Context, spec: str, source: str | None, model: Any,
                  bus: dict[str, Any]) -> Any:
    """The sensor for ``spec`` (+ ``source``, the file ``replay`` plays), with the
    model's taxels when a bus sensor needs them."""
    name, options = parse_spec(spec)
    if name == "replay":
        if source is not None:
            options.setdefault("path", source)
        if "path" not in options:
            raise click.UsageError("'--sensor replay' needs the file to play: "
                                   "'--sensor replay FILE' (a CAN log, dataset or CySkin text)")
    elif source is not None:
        raise click.UsageError(f"SOURCE is only for '--sensor replay' (got sensor '{name}'); "
                               f"give the sensor's options as '{name}:key=value,...'")
    if name == "cyskin-can":
        for key, value in bus.items():
            if value is not None:
                options.setdefault(key, value)
        if "taxel_ids" not in options and "layout" not in options:
            options["taxel_ids"] = model.taxel_ids
    return get_registry(ctx).build("sensor", name, **options)


def _renamed(old: str, new: str):
    """A hidden option ``old`` that refuses itself, naming ``new`` (no silent aliases)."""
    def refuse(ctx: click.Context, param: click.Parameter, value: Any) -> None:
        if value is not None:
            raise InputError(f"{old} is now {new}")

    return click.option(old, hidden=True, expose_value=False, callback=refuse,
                        help=f"Renamed: {new}.")


def _print_prediction(pred: Any, classes: list[str]) -> None:
    """One human-readable line: time, class, confidence, runner-up, latency, marker."""
    import numpy as np

    ranked = np.argsort(pred.probabilities)[::-1]
    runner = (f"  ({classes[ranked[1]]} {pred.probabilities[ranked[1]]:.2f})"
              if len(ranked) > 1 else "")
    mark = f"  [marker: {pred.marker}]" if pred.marker is not None else ""
    miss = f"  missing {pred.missing}" if pred.missing else ""
    click.echo(f"{pred.timestamp:14.3f}  {pred.label:<12} {pred.confidence:5.2f}{runner}  "
               f"{pred.latency_ms:6.1f} ms{miss}{mark}")


@click.command("live")
@click.option("--model", "model_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="A trained model file (.safetensors) with live metadata.")
@click.option("--sensor", "sensor_spec", default="cyskin-can", show_default=True,
              help="Sensor spec: 'cyskin-can:channel=vcan0,interface=socketcan', 'replay', ...")
@click.argument("source", required=False)
@click.option("--interface", default=None, help="cyskin-can: python-can interface.")
@click.option("--channel", default=None, help="cyskin-can: interface channel.")
@click.option("--bitrate", type=Number(minimum=1, maximum=100_000_000, integer=True),
              default=None, help="cyskin-can: bitrate, bit/s.")
@click.option("--format", "format_spec", default=None, help="cyskin-can: frame format spec.")
@click.option("--layout", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Layout file, when the model's metadata has none.")
@click.option("--encoder", default=None, help="Override the model's encoder spec.")
@click.option("-L", "L", type=Number(minimum=1, maximum=100_000, integer=True),
              default=None, help="Override the window length L (frames).")
@_renamed("--length", "-L")
@click.option("--pixel-mm", type=Number(minimum=0, exclusive_minimum=True),
              default=None, help="Override the image pixel size.")
@click.option("--warmup", type=click.Choice(["wait", "pad"]), default="wait", show_default=True,
              help="Before L sweeps: predict nothing, or pad with blank frames.")
@click.option("--max-sweeps", type=Number(minimum=1, integer=True), default=None,
              help="Stop after N sweeps.")
@click.option("--threads", type=Number(minimum=1, maximum=1024, integer=True),
              default=1, show_default=True,
              help="torch threads: one window at a time gains nothing from more, and the "
                   "bus reader needs a core.")
@click.option("--jsonl", is_flag=True, help="One JSON object per prediction, as they come.")
@click.option("--json", "as_json", is_flag=True,
              help="One JSON document at the end: every prediction and the latency summary.")
@click.pass_context
def live_cmd(ctx: click.Context, model_path: str, sensor_spec: str, source: str | None,
             interface: str | None, channel: str | None, bitrate: int | None,
             format_spec: str | None, layout: str | None, encoder: str | None,
             L: int | None, pixel_mm: float | None, warmup: str, max_sweeps: int | None,
             threads: int, jsonl: bool, as_json: bool) -> None:
    """Classify gestures live: each sweep is encoded once and the last L frames classified.

    Examples: 'tactbench live --model m.safetensors --sensor cyskin-can --channel vcan0
    --interface socketcan', or 'tactbench live --model m.safetensors --sensor replay
    run.blf' (a CAN log, a dataset or a CySkin text file).
    """
    if jsonl and as_json:
        raise click.UsageError("--json and --jsonl are exclusive")
    import torch

    previous_threads = torch.get_num_threads()
    torch.set_num_threads(max(1, threads))
    try:
        _live(ctx, model_path, sensor_spec, source, interface, channel, bitrate, format_spec,
              layout, encoder, L, pixel_mm, warmup, max_sweeps, jsonl, as_json)
    finally:  # the command may run inside another program (tests, notebooks)
        torch.set_num_threads(previous_threads)


def _live(ctx, model_path, sensor_spec, source, interface, channel, bitrate, format_spec,
          layout, encoder, L, pixel_mm, warmup, max_sweeps, jsonl, as_json) -> None:
    quiet = as_json or jsonl
    registry = get_registry(ctx, warn=not quiet)
    # The model is loaded and verified (checksum, finite weights, classes against the
    # network) before the sensor is opened: a bad model never sees a sweep.
    model = LiveModel.from_file(model_path, layout=layout, encoder=encoder, L=L,
                                pixel_mm=pixel_mm, registry=registry)
    live = LiveClassifier(model, warmup=warmup)
    bus = {"interface": interface, "channel": channel, "bitrate": bitrate,
           "format": format_spec}
    sensor = _build_sensor(ctx, sensor_spec, source, model, bus)
    if not quiet:
        load = SENSOR.get(sensor, "bus_load")
        where = f" ({load().describe()})" if load is not None else ""
        click.echo(f"live: {len(model.classes)} classes, L = {model.L}, encoder "
                   f"{model.encoder_spec if model.uses_images else '(taxel vectors)'}; "
                   f"sensor {sensor_spec}{where}", err=True)
    rows: list[dict[str, Any]] = []
    latencies: list[float] = []
    try:
        with sensor:
            for pred in live.run(sensor.frames(), taxel_ids=sensor.taxel_ids,
                                 max_sweeps=max_sweeps):
                latencies.append(pred.latency_ms)
                if as_json:
                    rows.append(pred.to_dict(model.classes))
                elif jsonl:
                    click.echo(json_text(pred.to_dict(model.classes)))
                    sys.stdout.flush()
                else:
                    _print_prediction(pred, model.classes)
    except KeyboardInterrupt:
        click.echo("live: stopped", err=True)
    summary = run_summary(live, latencies, sensor)
    if as_json:
        click.echo(json_text({"model": model_path, "classes": model.classes,
                               "L": model.L, "encoder": model.encoder_spec,
                               "predictions": rows, "summary": summary}, indent=2))
    elif not jsonl and latencies:
        lat = summary["latency_ms"]
        click.echo(f"live: {live.frames} sweeps, {len(latencies)} predictions; latency "
                   f"p50 {lat['p50']:.1f} ms, p99 {lat['p99']:.1f} ms", err=True)
