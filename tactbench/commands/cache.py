"""``tactbench cache ls|clear``: the encoded datasets kept on disk."""

from __future__ import annotations

import click

from tactbench.cli import json_text
from tactbench.runner import EncodingCache


@click.group("cache")
def cache_group() -> None:
    """Inspect or clear cached encodings (TACTBENCH_CACHE, default ~/.cache/tactbench)."""


@cache_group.command("ls")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def cache_ls(as_json: bool) -> None:
    """List cached encodings: encoder, dataset, imaging, storage precision, frames, size,
    state (ok, or damaged: rebuilt by the next run that needs it); then temporary folders
    (being written, or orphaned by a killed process: removed by the next run)."""
    cache = EncodingCache()
    entries = cache.entries()
    temporaries = cache.temporaries()
    if as_json:
        click.echo(json_text({"root": str(cache.root), "entries": entries,
                               "temporaries": temporaries}, indent=2, default=str))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"cached encodings in {cache.root}", title_justify="left")
    for col in ("key", "encoder", "dataset", "imaging", "precision", "frames", "MB",
                "encode s", "state"):
        table.add_column(col)
    for e in entries:
        imaging = e.get("imaging") if isinstance(e.get("imaging"), dict) else {}
        img = (f"{imaging.get('pixel_mm')} mm {imaging.get('method')}"
               if imaging.get("kind") == "images" else str(imaging.get("kind", "?")))
        seconds = e.get("encode_seconds", 0)
        state = e["state"] if e["state"] == "ok" else f"damaged: {e.get('problem', '')}"
        table.add_row(e["key"][:12], str(e.get("encoder", "?")), str(e.get("dataset", "?")),
                      img, str(e["precision"]), str(e.get("frames", "?")),
                      f"{e['bytes'] / 2**20:.1f}",
                      f"{seconds:.1f}" if isinstance(seconds, (int, float)) else "?", state)
    for t in temporaries:
        table.add_row(t["key"][:12], "", "", "", "", "", f"{t['bytes'] / 2**20:.1f}", "",
                      f"temporary ({t['state']}, pid {t['pid']})")
    Console().print(table)


@cache_group.command("clear")
@click.option("--yes", is_flag=True, help="Do not ask.")
def cache_clear(yes: bool) -> None:
    """Delete every cached encoding and orphaned temporary folder (results in run folders
    are kept; folders that a running process is writing are left to it)."""
    cache = EncodingCache()
    if not yes and not click.confirm(f"Delete cached encodings in {cache.root}?"):
        return
    removed = cache.clear()
    busy = [t for t in cache.temporaries() if t["state"] != "orphaned"]
    click.echo(f"removed {removed} cached encoding(s) and orphaned temporary folder(s) "
               f"from {cache.root}"
               + (f"; kept {len(busy)} being written by running processes" if busy else ""))
