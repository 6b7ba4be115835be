"""``tactbench data``: inspect, simulate and preview datasets."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from tactbench.cli import Number, get_registry, json_text
from tactbench.data.dataset import Dataset
from tactbench.data.preview import preview_strip, write_png, written_by_tactbench
from tactbench.datasets.loading import check_loaded, load_dataset, takes_progress
from tactbench.datasets.synthetic_forearm import generate
from tactbench.errors import InputError, MissingFileError
from tactbench.specs import parse_spec
from tactbench.paths import check_output_file, check_output_folder, publish_folder
from tactbench.ui import Progress


@click.group("data")
def data_group() -> None:
    """Inspect, simulate and preview datasets."""


def _load(path: str):
    """The dataset at ``path`` (or registered as ``path``), with a bar while it is made."""
    registry = None if Path(path).exists() else get_registry()
    with Progress() as bars:
        return load_dataset(path, registry=registry,
                            progress=bars.callback(f"loading {path}"))


def _load_as(fmt: str, src: str):
    """``src`` read by the registered dataset ``fmt`` (with options), ``src`` as its path."""
    name, options = parse_spec(fmt)
    if "path" in options:
        raise InputError(f"--format {fmt}: give the path as SRC, not as path=")
    if not Path(src).exists():
        raise MissingFileError(f"{src}: no such file or folder")
    source = get_registry().build("dataset", name, **options, path=src)
    with Progress() as bars:
        if takes_progress(source.load):
            ds = source.load(progress=bars.callback(f"loading {src} as {name}"))
        else:
            ds = source.load()
    return check_loaded(ds, fmt)


@data_group.command("info")
@click.argument("path")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def info_cmd(path: str, as_json: bool) -> None:
    """Counts, shapes, classes and users of a dataset.

    PATH is a dataset folder, a folder of recordings (ROOT/<class>/*.npy|.npz|.csv),
    a CySkin text file or folder, a CoST .csv, a CAN log, or a registered dataset
    (``synthetic-forearm:users=4``, ``folder:path=ROOT,users=prefix``).
    """
    ds = _load(path)
    summary = ds.summary()
    summary["path"] = path
    if as_json:
        click.echo(json_text(summary, indent=2))
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
    for name, counts in summary.get("attributes", {}).items():  # a corpus's variant, cover
        console.print(f"samples per {name}: "
                      + ", ".join(f"{v or '(none)'}: {n}" for v, n in counts.items()))


@data_group.command("synth")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False),
              help="Folder to write the dataset to (new or empty).")
@click.option("--users", default=38, show_default=True, type=click.IntRange(1),
              help="Simulated users.")
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed.")
@click.option("--repetitions", default=5, show_default=True, type=click.IntRange(1),
              help="Repetitions of each gesture per position.")
@click.option("--positions", default=2, show_default=True, type=click.IntRange(1, 2),
              help="Positions (1: front only, 2: front and side).")
@click.option("--version", "version", default=2, show_default=True, type=click.IntRange(1, 2),
              help="Simulator version: 2 the person model (the default), 1 the first "
                   "(recordings from contact on, kept so past results reproduce).")
def synth_cmd(out: str, users: int, seed: int, repetitions: int, positions: int,
              version: int) -> None:
    """Generate the synthetic-forearm gesture dataset into a new or empty folder."""
    check_output_folder(out)

    with Progress() as bars:
        ds = generate(users=users, positions=positions, repetitions=repetitions, seed=seed,
                      version=version, progress=bars.callback("simulating gestures"))
    with publish_folder(out) as tmp:  # whole or not at all; a second writer is refused
        ds.save(tmp)
    click.echo(f"wrote {len(ds)} samples ({len(ds.classes)} classes, {users} users) to {out}; "
               f"content hash {ds.content_hash()[:16]}", err=True)


@data_group.command("import")
@click.argument("src")
@click.option("--out", "out", required=True, type=click.Path(),
              help="Folder to write the dataset to (new or empty).")
@click.option("--format", "fmt", default=None,
              help="Reader to use, with options, SRC becoming its path: "
                   "folder:users=prefix,pitch_mm=8 or cost:pitch_mm=10 [default: "
                   "detected from SRC].")
def import_cmd(src: str, out: str, fmt: str | None) -> None:
    """Convert any readable dataset into tactbench's own dataset folder, once.

    SRC is a path (a folder of recordings, CySkin text, CoST .csv, CAN log, dataset
    folder) or a registered dataset spec. The folder written is verified by reading it
    back: its content hash must equal the source's.
    """
    dest = check_output_folder(out, inputs=[src] if Path(src).exists() else [])
    ds = _load(src) if fmt is None else _load_as(fmt, src)
    with publish_folder(dest) as tmp:  # whole or not at all; a second writer is refused
        ds.save(tmp)
    back = Dataset.load(dest)  # verifies the stored content hash against the arrays
    if back.content_hash() != ds.content_hash():
        raise RuntimeError(f"{dest}: read back with content hash {back.content_hash()[:16]} "
                           f"instead of {ds.content_hash()[:16]}")  # a bug, not user error
    click.echo(f"imported {len(ds)} samples ({len(ds.classes)} classes, {ds.n_taxels} taxels"
               f"{', layout ' + ds.layout.name if ds.layout is not None else ', no layout'}) "
               f"into {out}; content hash {ds.content_hash()[:16]}, verified", err=True)


@data_group.command("preview")
@click.argument("path")
@click.option("--sample", "index", default=0, show_default=True, type=click.IntRange(0),
              help="Which sample (0-based).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False),
              help="PNG file to write (replaced only when tactbench wrote it).")
@click.option("--encoder", default=None,
              help="Show this encoder's channels as RGB (e.g. farneback).")
@click.option("--pixel-mm", default=4.0, show_default=True,
              type=Number(minimum=0, exclusive_minimum=True),
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
    check_output_file(out, inputs=[path] if Path(path).exists() else [],
                      ours=written_by_tactbench)
    ds = _load(path)
    enc = None
    if encoder:
        enc = get_registry().build("encoder", encoder)
    shown = preview_strip(ds, index, encoder=enc, pixel_mm=pixel_mm, method=method,
                          max_frames=max_frames)
    write_png(out, shown.image)
    sample = ds[index]
    label = ds.classes[sample.label]
    if shown.frame_shape is None:
        click.echo(f"{ds.name} sample {index} ({label}): no layout; wrote {shown.frames} "
                   f"frames × {shown.taxels} taxels to {out}", err=True)
        return
    h, w = shown.frame_shape
    click.echo(f"{ds.name} sample {index} ({label}, {sample.user or 'no user'}): "
               f"{shown.frames} frames of {h}×{w} px"
               f"{' encoded by ' + encoder if encoder else ''} → {out}", err=True)


if __name__ == "__main__":  # pragma: no cover
    data_group(sys.argv[1:])
