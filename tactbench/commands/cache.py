"""``tactbench cache ls|prune|clear``: the encoded datasets kept on disk."""

from __future__ import annotations

import time

import click

from tactbench.budget import human_bytes, parse_bytes
from tactbench.cli import json_text
from tactbench.errors import InputError
from tactbench.runner import EncodingCache, KEEP_RECENT_S, parse_duration, show_duration


@click.group("cache")
def cache_group() -> None:
    """Inspect, prune or clear cached encodings (TACTBENCH_CACHE, default
    ~/.cache/tactbench)."""


@cache_group.command("ls")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def cache_ls(as_json: bool) -> None:
    """List cached encodings: encoder, dataset, imaging, storage precision, frames, size,
    state (ok, or damaged: rebuilt by the next run that needs it; and whether a running
    run uses it, which prune and clear leave alone); then temporary folders
    (being written, or orphaned by a killed process: removed by the next run)."""
    cache = EncodingCache()
    entries = cache.entries()
    temporaries = cache.temporaries()
    leased = cache.leased()  # key → the running run that uses it
    if as_json:
        click.echo(json_text({"root": str(cache.root), "entries": entries,
                               "temporaries": temporaries, "leased": leased},
                              indent=2, default=str))
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
        if e["key"] in leased:
            state += f"; in use by a running run ({leased[e['key']]})"
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
    are kept; entries a running run uses and folders a running process is writing are
    left to it)."""
    cache = EncodingCache()
    if not yes and not click.confirm(f"Delete cached encodings in {cache.root}?"):
        return
    removed = cache.clear()
    busy = [t for t in cache.temporaries() if t["state"] != "orphaned"]
    leased = cache.leased()
    for key, who in sorted(leased.items()):
        click.echo(f"kept: {key[:12]}: in use by a running run ({who})")
    click.echo(f"removed {removed} cached encoding(s) and orphaned temporary folder(s) "
               f"from {cache.root}"
               + (f"; kept {len(leased)} in use by running runs" if leased else "")
               + (f"; kept {len(busy)} being written by running processes" if busy else ""))


@cache_group.command("prune")
@click.option("--max-size", metavar="SIZE",
              help="Remove the least recently used entries until the cache holds at most "
                   "SIZE (20GB, 500MiB, 0).")
@click.option("--unused-for", metavar="DURATION",
              help="Remove the entries no run has used for DURATION (7d, 12h, 90m).")
@click.option("--dry-run", is_flag=True, help="Say what would be removed; remove nothing.")
@click.option("--yes", is_flag=True, help="Do not ask.")
def cache_prune(max_size: str | None, unused_for: str | None, dry_run: bool,
                yes: bool) -> None:
    """Remove the cached encodings a run is least likely to need, least recently used
    first: damaged ones, those unused for --unused-for, then as many as --max-size asks;
    and orphaned temporary folders. An entry a running run holds a lease on, or one a run
    used in the last 15 minutes, is kept (it may be reading it). A later run that needs a
    removed entry encodes it again."""
    if max_size is None and unused_for is None:
        raise InputError("say what to prune: --max-size SIZE, --unused-for DURATION, "
                         "or both")
    _no_bare_number(max_size, "--max-size", "20GB, 500MiB, or 20B for bytes")
    _no_bare_number(unused_for, "--unused-for", "7d, 12h, 90m, or 7s for seconds")
    limits = {"max_bytes": None if max_size is None else parse_bytes(max_size, "--max-size"),
              "unused_for": None if unused_for is None else parse_duration(unused_for)}
    cache = EncodingCache()
    planned = cache.prune(**limits, dry_run=True)
    _show_pruned(cache, planned, "would remove" if dry_run else "to remove")
    if dry_run or not (planned["removed"] or planned["orphans"]):
        return
    if not yes and not click.confirm(
            f"Remove {len(planned['removed'])} cached encoding(s) "
            f"({human_bytes(planned['bytes_before'] - planned['bytes_after'])})?"):
        return
    done = cache.prune(**limits)
    left = len(cache.entries())
    for e in done["stuck"]:
        click.echo(f"could not remove {cache.path(e['key'])}: check its permissions and "
                   f"whether its disk is read-only")
    click.echo(f"removed {len(done['removed'])} cached encoding(s) "
               f"({human_bytes(done['bytes_before'] - done['bytes_after'])}) and "
               f"{len(done['orphans'])} orphaned temporary folder(s); {cache.root} now "
               f"holds {human_bytes(done['bytes_after'])} in {left} entr"
               f"{'y' if left == 1 else 'ies'}")
    if done["stuck"]:
        raise SystemExit(1)  # asked to remove what it could not


def _no_bare_number(text: str | None, option: str, examples: str) -> None:
    """Refuse a number without its unit (``--max-size 20``: bytes or gigabytes?); a
    size of 0 needs none."""
    if text is None:
        return
    try:
        value = float(text.strip())
    except ValueError:
        return  # has a unit (or is not a number: the parser says so)
    if value == 0 and option == "--max-size":
        return
    raise InputError(f"{option} {text.strip()} has no unit: write it with one, e.g. "
                     f"{examples} (nothing was removed)")


def _show_pruned(cache: EncodingCache, planned: dict, verb: str) -> None:
    """What prune removes (or would), and what it keeps because a run used it lately."""
    now = time.time()

    def ago(e: dict) -> str:  # a use dated in the future (a clock set wrong) is "now"
        return show_duration(max(0.0, now - e["last_used"]))

    for e in planned["removed"]:
        click.echo(f"{verb}: {e['key'][:12]} {e.get('encoder', '?')} "
                   f"({e.get('dataset', '?')}), {human_bytes(e['bytes'])}, last used "
                   f"{ago(e)} ago ({e['why']})")
    for e in planned["leased"]:
        click.echo(f"kept: {e['key'][:12]} {e.get('encoder', '?')}, "
                   f"{human_bytes(e['bytes'])}: in use by a running run ({e['lease']})")
    for e in planned["held"]:
        click.echo(f"kept: {e['key'][:12]} {e.get('encoder', '?')}, "
                   f"{human_bytes(e['bytes'])}: used {ago(e)} ago, within "
                   f"{show_duration(KEEP_RECENT_S)}")
    freed = planned["bytes_before"] - planned["bytes_after"]
    click.echo(f"{verb}: {len(planned['removed'])} cached encoding(s), {human_bytes(freed)}, "
               f"and {len(planned['orphans'])} orphaned temporary folder(s); "
               f"{cache.root} holds {human_bytes(planned['bytes_before'])}"
               + (f", {human_bytes(planned['bytes_after'])} after" if freed else ""))
