"""``tactbench cache ls|clear``: the encoded datasets kept on disk."""

from __future__ import annotations

import json

import click


@click.group("cache")
def cache_group() -> None:
    """Inspect or clear cached encodings (TACTBENCH_CACHE, default ~/.cache/tactbench)."""


@cache_group.command("ls")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def cache_ls(as_json: bool) -> None:
    """List cached encodings: encoder, dataset, imaging, storage precision, frames, size."""
    from tactbench.runner import EncodingCache

    cache = EncodingCache()
    entries = cache.entries()
    if as_json:
        click.echo(json.dumps({"root": str(cache.root), "entries": entries}, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"cached encodings in {cache.root}", title_justify="left")
    for col in ("key", "encoder", "dataset", "imaging", "precision", "frames", "MB",
                "encode s"):
        table.add_column(col)
    for e in entries:
        imaging = e.get("imaging", {})
        img = (f"{imaging.get('pixel_mm')} mm {imaging.get('method')}"
               if imaging.get("kind") == "images" else imaging.get("kind", "?"))
        table.add_row(e["key"][:12], e.get("encoder", "?"), e.get("dataset", "?"), img,
                      e["precision"], str(e.get("frames", "?")), f"{e['bytes'] / 2**20:.1f}",
                      f"{e.get('encode_seconds', 0):.1f}")
    Console().print(table)


@cache_group.command("clear")
@click.option("--yes", is_flag=True, help="Do not ask.")
def cache_clear(yes: bool) -> None:
    """Delete every cached encoding (results in run folders are kept)."""
    from tactbench.runner import EncodingCache

    cache = EncodingCache()
    if not yes and not click.confirm(f"Delete cached encodings in {cache.root}?"):
        return
    click.echo(f"removed {cache.clear()} cached encoding(s) from {cache.root}")
