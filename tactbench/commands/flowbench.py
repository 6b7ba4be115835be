"""``tactbench flowbench``: flow error against run time on scenes with known motion."""

from __future__ import annotations

import json
import platform
from pathlib import Path

import click

from tactbench.budget import check_budget
from tactbench.cli import get_registry, json_text
from tactbench.encoders.evaluation import flowbench as fb
from tactbench.encoders.parallel import default_workers
from tactbench.integrity import read_regular_bytes
from tactbench.paths import check_output_folder, publish_folder
from tactbench.ui import Progress


def _parse_size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"'{text}': expected HxW, e.g. 64x64") from None
    if h < 8 or w < 8:
        raise click.BadParameter(f"'{text}': scenes need at least 8x8 pixels")
    return h, w


@click.command("flowbench")
@click.option("--encoder", "-e", "specs", multiple=True,
              help="Flow encoder (repeatable; options allowed: 'dis:preset=fast'). "
                   "Default: farneback, lucas-kanade, kornia-flow, dis, tvl1.")
@click.option("--size", "sizes", multiple=True, metavar="HxW",
              help="Image size (repeatable). Default: 72x67 (the runner's quick profile) and "
                   "the full 357x334.")
@click.option("--repeats", default=5, show_default=True, type=click.IntRange(1, 100),
              help="Timed runs per encoder and size (the median is reported).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False),
              help="Write flowbench.json, flowbench.csv and flow_error_vs_time.png here.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def flowbench_cmd(specs: tuple[str, ...], sizes: tuple[str, ...], repeats: int,
                  out_dir: str | None, as_json: bool) -> None:
    """Endpoint error, angular error and ms per frame pair of flow encoders.

    Scenes: tactile contacts translating, twisting, pushing (expanding),
    pulling (slipping past a still palm) at 0.25-8 px/frame, contacts of two
    sizes, and a pressure change without motion; plus a natural image warped
    by a smooth flow. Errors are averaged over the tactile scenes; the Pareto
    front (no encoder both faster and more accurate) is marked.
    """
    if out_dir:  # the one output rule, before any work
        check_output_folder(out_dir, ours=_ours)
    registry = get_registry(warn=not as_json)
    specs = specs or fb.DEFAULT_ENCODERS
    encoders = [(spec, registry.build("encoder", spec)) for spec in specs]
    shapes = [_parse_size(s) for s in sizes] or [fb.DEFAULT_SHAPE, fb.FULL_SHAPE]
    check_budget(fb.memory_estimate(shapes), "flowbench at "
                 + ", ".join(fb.resolution_label(s) for s in shapes))  # before any scene
    with Progress() as bars:
        results = fb.run_flowbench(encoders, shapes, repeats=repeats,
                                   progress=bars.callback("flowbench"))
    meta = {"command": "tactbench flowbench " + " ".join(f"--encoder {s}" for s in specs),
            "sizes": [fb.resolution_label(s) for s in shapes], "repeats": repeats,
            "machine": f"{platform.machine()}, {_cores()} usable cores, "
                       f"python {platform.python_version()}"}
    doc = fb.to_document(results, meta)
    if out_dir:
        paths = _write(results, Path(out_dir), meta)
        doc["files"] = {k: str(v) for k, v in paths.items()}
    if as_json:
        click.echo(json_text(doc, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="flow error against run time (tactile scenes)", title_justify="left")
    for col in ("encoder", "size", "EPE px", "angular °", "ms / pair", "natural EPE px",
                "Pareto"):
        table.add_column(col, justify="left" if col in ("encoder", "size") else "right")
    for r in results:
        table.add_row(r.encoder, r.resolution, f"{r.epe:.3f}", f"{r.angular:.1f}",
                      f"{r.ms_per_pair:.2f}", f"{r.natural_epe:.3f}", "★" if r.pareto else "")
    console = Console()
    console.print(table)
    if out_dir:
        console.print(f"wrote {', '.join(doc['files'].values())}")


#: The files ``flowbench --out`` writes: a folder holding only these, with a
#: ``flowbench.json`` that flowbench wrote, is its own earlier output and may be replaced.
OUTPUTS = ("flowbench.json", "flowbench.csv", "flow_error_vs_time.png")


def _ours(folder: Path) -> bool:
    names = {p.name for p in Path(folder).iterdir()}
    if not names <= set(OUTPUTS) or "flowbench.json" not in names:
        return False
    try:
        doc = json.loads(read_regular_bytes(Path(folder) / "flowbench.json", limit=1 << 26))
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(doc, dict) and str((doc.get("meta") or {}).get("command", "")) \
        .startswith("tactbench flowbench")


def _write(results, out: Path, meta: dict) -> dict[str, Path]:
    """A new or empty folder is written whole (:func:`publish_folder`: a second writer is
    refused); flowbench's own earlier folder is replaced file by file, atomically."""
    if out.is_dir() and any(out.iterdir()):
        return fb.write_outputs(results, out, meta)
    with publish_folder(out) as tmp:
        written = fb.write_outputs(results, tmp, meta)
    return {k: out / v.name for k, v in written.items()}


def _cores() -> int:
    return default_workers()
