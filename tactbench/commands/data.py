"""``tactbench data``: inspect, simulate and preview datasets."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from tactbench.errors import InputError


@click.group("data")
def data_group() -> None:
    """Inspect, simulate and preview datasets."""


def _progress(description: str):
    """A rich progress bar on stderr; returns (context manager, callback)."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                        TimeRemainingColumn(), console=Console(stderr=True), transient=True)
    task = progress.add_task(description, total=None)

    def update(done: int, total: int) -> None:
        progress.update(task, completed=done, total=total)

    return progress, update


def _load(path: str):
    from tactbench.cli import get_registry
    from tactbench.datasets.loading import load_dataset

    if Path(path).exists():
        return load_dataset(path)
    return load_dataset(path, registry=get_registry())


@data_group.command("info")
@click.argument("path")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def info_cmd(path: str, as_json: bool) -> None:
    """Counts, shapes, classes and users of a dataset.

    PATH is a dataset folder, a CySkin text file or folder, a CoST .csv, or a
    registered dataset (``synthetic-forearm:users=4``).
    """
    ds = _load(path)
    summary = ds.summary()
    summary["path"] = path
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    console = Console()
    fps = summary["frames_per_sample"]
    lay = summary["layout"]
    console.print(f"[bold]{summary['name']}[/bold] ({path})")
    console.print(f"  samples: {summary['samples']}   taxels: {summary['taxels']}   "
                  f"frames per sample: {fps['min']} / {fps['median']:g} / {fps['max']} "
                  f"(min / median / max)   rate: {summary['frame_rate_hz']} Hz")
    console.print("  layout: " + ("none" if lay is None else
                                  f"{lay['name']}: {lay['taxels']} taxels, "
                                  f"{lay['extent_mm'][0]:g} × {lay['extent_mm'][1]:g} mm, "
                                  f"spacing {lay['median_spacing_mm']:g} mm"))
    console.print(f"  normalisation: {summary['normalisation']}   missing readings: "
                  f"{summary['missing_readings']}")
    console.print(f"  content hash: {summary['content_hash']}")
    table = Table(title="samples per class", title_justify="left")
    table.add_column("class")
    table.add_column("samples", justify="right")
    for cls, n in summary["samples_per_class"].items():
        table.add_row(cls, str(n))
    console.print(table)
    users = summary["samples_per_user"]
    if len(users) > 1 or "" not in users:
        shown = ", ".join(f"{u or '(none)'}: {n}" for u, n in list(users.items())[:40])
        more = f" … ({len(users)} users)" if len(users) > 40 else f" ({len(users)} users)"
        console.print(f"samples per user: {shown}{more}")


@data_group.command("synth")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False),
              help="Folder to write the dataset to.")
@click.option("--users", default=38, show_default=True, type=click.IntRange(1),
              help="Simulated users.")
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed.")
@click.option("--repetitions", default=5, show_default=True, type=click.IntRange(1),
              help="Repetitions of each gesture per position.")
@click.option("--positions", default=2, show_default=True, type=click.IntRange(1, 2),
              help="Positions (1: front only, 2: front and side).")
def synth_cmd(out: str, users: int, seed: int, repetitions: int, positions: int) -> None:
    """Generate the synthetic-forearm gesture dataset into a folder."""
    from tactbench.datasets.synthetic import generate

    progress, update = _progress("simulating gestures")
    with progress:
        ds = generate(users=users, positions=positions, repetitions=repetitions, seed=seed,
                      progress=update)
    ds.save(out)
    click.echo(f"wrote {len(ds)} samples ({len(ds.classes)} classes, {users} users) to {out}; "
               f"content hash {ds.content_hash()[:16]}", err=True)


def _to_rgb(encoded, encoder):
    """(T, C, H, W) encoder output → (T, H, W, 3) in [0, 1], channels as R, G, B."""
    import numpy as np

    t, c, h, w = encoded.shape
    ranges = getattr(encoder, "ranges", None) or [(0.0, 1.0)] * c
    rgb = np.zeros((t, h, w, 3), dtype=np.float32)
    if c == 1:
        lo, hi = ranges[0]
        grey = np.clip((encoded[:, 0] - lo) / ((hi - lo) or 1.0), 0, 1)
        return np.repeat(grey[..., None], 3, axis=-1)
    for k in range(min(c, 3)):
        lo, hi = ranges[k]
        rgb[..., k] = np.clip((encoded[:, k] - lo) / ((hi - lo) or 1.0), 0, 1)
    return rgb


@data_group.command("preview")
@click.argument("path")
@click.option("--sample", "index", default=0, show_default=True, type=click.IntRange(0),
              help="Which sample (0-based).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False),
              help="PNG file to write.")
@click.option("--encoder", default=None,
              help="Show this encoder's channels as RGB (e.g. farneback).")
@click.option("--pixel-mm", default=4.0, show_default=True, type=float,
              help="Image pixel size in mm (taxels are ~7.5 mm apart).")
@click.option("--method", default="linear", show_default=True,
              type=click.Choice(["linear", "gaussian"]), help="Imaging method.")
@click.option("--max-frames", default=16, show_default=True, type=click.IntRange(1),
              help="Show at most this many frames.")
def preview_cmd(path: str, index: int, out: str, encoder: str | None, pixel_mm: float,
                method: str, max_frames: int) -> None:
    """A strip of one sample's tactile images (or encoded channels) as a PNG.

    A dataset without a layout is shown as its taxel values over time
    (frames down, taxels across).
    """
    import numpy as np
    from matplotlib import colormaps
    from matplotlib.image import imsave

    ds = _load(path)
    if index >= len(ds):
        raise InputError(f"--sample {index} is out of range: {path} has {len(ds)} samples")
    sample = ds[index]
    label = ds.classes[sample.label]
    if ds.layout is None:
        if encoder:
            raise InputError(f"dataset {ds.name!r} has no taxel layout, so it has no images "
                             f"for encoder {encoder!r}; preview without --encoder shows its "
                             f"taxel values")
        vec = np.nan_to_num(ds.normalise(sample.recording.values), nan=0.0)
        rgb = colormaps["inferno"](vec)[..., :3]
        rgb = np.kron(rgb, np.ones((8, 1, 1)))  # make each frame a visible band
        imsave(out, rgb)
        click.echo(f"{ds.name} sample {index} ({label}): no layout; wrote {vec.shape[0]} "
                   f"frames × {vec.shape[1]} taxels to {out}", err=True)
        return
    seq = ds.imager(pixel_mm, method).apply(ds.normalise(sample.recording.values))
    seq = np.clip(seq, 0, 1)
    if encoder:
        from tactbench.cli import get_registry

        enc = get_registry().build("encoder", encoder)
        frames = _to_rgb(np.asarray(enc.encode(seq)), enc)
    else:
        frames = colormaps["inferno"](seq)[..., :3]
    frames = frames[:max_frames]
    t, h, w, _ = frames.shape
    scale = max(1, int(round(96 / max(h, w))))
    if scale > 1:
        frames = frames.repeat(scale, axis=1).repeat(scale, axis=2)
        h, w = h * scale, w * scale
    gap = 2
    strip = np.ones((h, t * (w + gap) - gap, 3), dtype=np.float32)
    for k in range(t):
        strip[:, k * (w + gap):k * (w + gap) + w] = frames[k]
    imsave(out, strip)
    click.echo(f"{ds.name} sample {index} ({label}, {sample.user or 'no user'}): "
               f"{t} frames of {h // scale}×{w // scale} px"
               f"{' encoded by ' + encoder if encoder else ''} → {out}", err=True)


if __name__ == "__main__":  # pragma: no cover
    data_group(sys.argv[1:])
