"""``tactbench live``: classify gestures from a sensor as its sweeps arrive."""

from __future__ import annotations

import json
import sys
from typing import Any

import click

from tactbench.errors import TactbenchError


def _build_sensor(ctx: click.Context, spec: str, source: str | None, model: Any,
                  bus: dict[str, Any]) -> Any:
    """The sensor for ``spec`` (+ ``source``), with the model's taxels when it needs them."""
    from tactbench.cli import get_registry
    from tactbench.plugins import parse_spec

    name, options = parse_spec(spec)
    if name == "replay" and source is not None:
        from tactbench.can.logs import LogReplay, is_can_log

        if is_can_log(source):
            # A CAN log plays all its sweeps (every sample in it), like the live bus would.
            return LogReplay(source, realtime=bool(options.get("realtime", False)))
        options.setdefault("path", source)
    elif name == "replay" and "path" not in options:
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


def _reorder(sensor_ids: Any, model_ids: Any):
    """Column index that puts a sensor's values in the model's taxel order (None: same)."""
    import numpy as np

    sensor_ids = np.asarray(sensor_ids, dtype=np.int64)
    if sensor_ids.shape == model_ids.shape and np.array_equal(sensor_ids, model_ids):
        return None
    where = {int(t): i for i, t in enumerate(sensor_ids)}
    missing = [int(t) for t in model_ids if int(t) not in where]
    if missing:
        raise TactbenchError(f"the sensor lacks {len(missing)} of the model's taxels "
                             f"(first: {', '.join(map(str, missing[:5]))}); is it the same "
                             f"skin and layout?")
    return np.array([where[int(t)] for t in model_ids], dtype=np.int64)


class _Reordered:
    """Frames with values re-indexed into the model's taxel order."""

    def __init__(self, frames, index) -> None:
        self.frames, self.index = frames, index

    def __iter__(self):
        for f in self.frames:
            yield _Frame(f, f.values[self.index])


class _Frame:
    def __init__(self, frame, values) -> None:
        self.timestamp = frame.timestamp
        self.values = values
        self.missing = getattr(frame, "missing", 0)
        self.label = getattr(frame, "label", None)


@click.command("live")
@click.option("--model", "model_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="A trained model file (.safetensors) with live metadata.")
@click.option("--sensor", "sensor_spec", default="cyskin-can", show_default=True,
              help="Sensor spec: 'cyskin-can:channel=vcan0,interface=socketcan', 'replay', ...")
@click.argument("source", required=False)
@click.option("--interface", default=None, help="cyskin-can: python-can interface.")
@click.option("--channel", default=None, help="cyskin-can: interface channel.")
@click.option("--bitrate", type=int, default=None, help="cyskin-can: bitrate, bit/s.")
@click.option("--format", "format_spec", default=None, help="cyskin-can: frame format spec.")
@click.option("--layout", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Layout file, when the model's metadata has none.")
@click.option("--encoder", default=None, help="Override the model's encoder spec.")
@click.option("--length", "length", type=int, default=None, help="Override the window length L.")
@click.option("--pixel-mm", type=float, default=None, help="Override the image pixel size.")
@click.option("--warmup", type=click.Choice(["wait", "pad"]), default="wait", show_default=True,
              help="Before L sweeps: predict nothing, or pad with blank frames.")
@click.option("--max-sweeps", type=int, default=None, help="Stop after N sweeps.")
@click.option("--threads", type=int, default=1, show_default=True,
              help="torch threads: one window at a time gains nothing from more, and the "
                   "bus reader needs a core.")
@click.option("--jsonl", is_flag=True, help="One JSON object per prediction, as they come.")
@click.option("--json", "as_json", is_flag=True,
              help="One JSON document at the end: every prediction and the latency summary.")
@click.pass_context
def live_cmd(ctx: click.Context, model_path: str, sensor_spec: str, source: str | None,
             interface: str | None, channel: str | None, bitrate: int | None,
             format_spec: str | None, layout: str | None, encoder: str | None,
             length: int | None, pixel_mm: float | None, warmup: str, max_sweeps: int | None,
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
              layout, encoder, length, pixel_mm, warmup, max_sweeps, jsonl, as_json)
    finally:  # the command may run inside another program (tests, notebooks)
        torch.set_num_threads(previous_threads)


def _live(ctx, model_path, sensor_spec, source, interface, channel, bitrate, format_spec,
          layout, encoder, length, pixel_mm, warmup, max_sweeps, jsonl, as_json) -> None:
    import itertools

    import numpy as np

    from tactbench.cli import get_registry
    from tactbench.live import LiveClassifier, LiveModel

    registry = get_registry(ctx, warn=not (as_json or jsonl))
    model = LiveModel.from_file(model_path, layout=layout, encoder=encoder, length=length,
                                pixel_mm=pixel_mm, registry=registry)
    live = LiveClassifier(model, warmup=warmup)
    bus = {"interface": interface, "channel": channel, "bitrate": bitrate,
           "format": format_spec}
    sensor = _build_sensor(ctx, sensor_spec, source, model, bus)
    quiet = as_json or jsonl
    if not quiet:
        where = f" ({sensor.bus_load().describe()})" if hasattr(sensor, "bus_load") else ""
        click.echo(f"live: {len(model.classes)} classes, L = {model.length}, encoder "
                   f"{model.encoder_spec if model.uses_images else '(taxel vectors)'}; "
                   f"sensor {sensor_spec}{where}", err=True)
    predictions = []
    latencies = []
    try:
        with sensor:
            index = _reorder(sensor.taxel_ids, model.taxel_ids)
            frames = sensor.frames()
            if index is not None:
                frames = iter(_Reordered(frames, index))
            if max_sweeps is not None:
                frames = itertools.islice(frames, max(0, max_sweeps))
            for frame in frames:
                pred = live.push(frame.values, frame.timestamp,
                                 missing=int(getattr(frame, "missing", 0)))
                if pred is None:
                    continue
                latencies.append(pred.latency_ms)
                row = pred.to_dict(model.classes)
                truth = getattr(frame, "label", None)
                if truth is not None:
                    row["marker"] = truth
                if as_json:
                    predictions.append(row)
                elif jsonl:
                    click.echo(json.dumps(row))
                    sys.stdout.flush()
                else:
                    ranked = np.argsort(pred.probabilities)[::-1]
                    runner = (f"  ({model.classes[ranked[1]]} {pred.probabilities[ranked[1]]:.2f})"
                              if len(ranked) > 1 else "")
                    mark = f"  [marker: {truth}]" if truth is not None else ""
                    miss = f"  missing {pred.missing}" if pred.missing else ""
                    click.echo(f"{pred.timestamp:14.3f}  {pred.label:<12} "
                               f"{pred.confidence:5.2f}{runner}  {pred.latency_ms:6.1f} ms"
                               f"{miss}{mark}")
    except KeyboardInterrupt:
        click.echo("live: stopped", err=True)
    summary = {"sweeps": live.frames, "predictions": len(latencies),
               "latency_ms": ({"p50": float(np.percentile(latencies, 50)),
                               "p99": float(np.percentile(latencies, 99)),
                               "max": float(np.max(latencies))} if latencies else None)}
    stats = getattr(sensor, "stats", None)
    if stats is not None and hasattr(stats, "to_dict"):
        summary["bus"] = stats.to_dict()
    if as_json:
        click.echo(json.dumps({"model": model_path, "classes": model.classes,
                               "length": model.length, "encoder": model.encoder_spec,
                               "predictions": predictions, "summary": summary}, indent=2))
    elif not jsonl and latencies:
        lat = summary["latency_ms"]
        click.echo(f"live: {live.frames} sweeps, {len(latencies)} predictions; latency "
                   f"p50 {lat['p50']:.1f} ms, p99 {lat['p99']:.1f} ms", err=True)
