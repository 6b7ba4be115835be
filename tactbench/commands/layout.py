"""``tactbench layout``: inspect and generate taxel layouts."""

from __future__ import annotations

import click

from tactbench.cli import json_text
from tactbench.data.imaging import image_shape
from tactbench.data.layout_io import load_layout, write_layout_csv
from tactbench.datasets.forearm import cyskin_forearm
from tactbench.paths import check_output_file


@click.group("layout")
def layout_group() -> None:
    """Inspect and generate taxel layouts."""


@layout_group.command("info")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--pixel-mm", "pixel_mm", multiple=True, type=float,
              help="Also give the image shape at this pixel size (repeatable; "
                   "default 1, 4 and 5 mm).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def info_cmd(file: str, pixel_mm: tuple[float, ...], as_json: bool) -> None:
    """Taxel count, extent in mm, median spacing of a layout (.json or .csv)."""
    layout = load_layout(file)
    summary = layout.summary()
    summary["path"] = file
    summary["image_shapes"] = {f"{p:g}": list(image_shape(layout, p))
                               for p in (pixel_mm or (1.0, 4.0, 5.0))}
    if as_json:
        click.echo(json_text(summary, indent=2))
        return
    w, h = summary["extent_mm"]
    click.echo(f"{file}: {summary['taxels']} taxels in {summary['modules']} modules "
               f"(id // 16)")
    click.echo(f"  extent: {w:g} × {h:g} mm (x × y); image bounds "
               f"{', '.join(f'{b:g}' for b in summary['bounds_mm'])} mm")
    click.echo(f"  median nearest-neighbour spacing: {summary['median_spacing_mm']:g} mm")
    click.echo(f"  3-D positions: {'yes' if summary['has_3d'] else 'no'}; "
               f"normals: {'yes' if summary['has_normals'] else 'no'}")
    for p, (rows, cols) in summary["image_shapes"].items():
        click.echo(f"  image at {p} mm/pixel: {rows} × {cols} (H × W)")


@layout_group.command("generate")
@click.option("--out", required=True, type=click.Path(dir_okay=False),
              help="CSV file to write (id,x_mm,y_mm,z_mm).")
@click.option("--taxels", default=1558, show_default=True, type=click.IntRange(1))
@click.option("--seed", default=0, show_default=True, type=int)
def generate_cmd(out: str, taxels: int, seed: int) -> None:
    """Write the generated CySkin-like forearm layout as CSV.

    --out is a new file: an existing one is never replaced.
    """
    check_output_file(out)  # the one output rule: not a user's file, not in the cache
    layout = cyskin_forearm(taxels, seed=seed)
    write_layout_csv(layout, out)
    click.echo(f"wrote {layout.n_taxels} taxels to {out}", err=True)
