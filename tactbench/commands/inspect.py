"""``tactbench list`` and ``tactbench plugins``: what is installed, and what failed."""

from __future__ import annotations

import click

from tactbench.cli import get_registry, json_text
from tactbench.contracts import CLASSIFIER
from tactbench.registry import KINDS


def _component_dict(comp) -> dict:
    missing = set(comp.missing_requirements())
    return {
        "kind": comp.kind,
        "name": comp.name,
        "summary": comp.summary,
        "plugin": comp.plugin,
        "distribution": comp.distribution,
        "target": comp.target,
        "requires": [{"module": m, "available": m not in missing} for m in comp.requires],
        "available": not missing,
    }


#: What a classifier of each frame rank is fed (the contract's ``frame_rank``).
_INPUTS = {3: "images", 1: "vectors", None: "images or vectors (--input)"}


def _classifier_input(comp) -> str:
    """``images``, ``vectors`` or ``images or vectors (--input)``; ``-`` when the
    classifier cannot be loaded here (a missing requirement)."""
    if comp.missing_requirements():
        return "-"

    try:
        rank = CLASSIFIER.get(comp.load(), "frame_rank")  # the contract's default where unset
    except Exception:  # noqa: BLE001 - a broken plugin is listed, not fatal to `list`
        return "-"
    return _INPUTS.get(rank, "-")


def _problem_dict(problem) -> dict:
    return {"plugin": problem.plugin, "distribution": problem.distribution,
            "error": problem.message}


@click.command("list")
@click.option("--kind", type=click.Choice(list(KINDS)), help="Only components of this kind.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def list_cmd(kind: str | None, as_json: bool) -> None:
    """List registered sensors, datasets, encoders, classifiers, splits and test windows."""
    registry = get_registry()
    components = list(registry.components(kind))
    rows = [_component_dict(c) for c in components]
    for comp, row in zip(components, rows):
        if comp.kind == "classifier":
            row["input"] = _classifier_input(comp)
    if as_json:
        click.echo(json_text({"components": rows,
                               "problems": [_problem_dict(p) for p in registry.problems]},
                              indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="tactbench components", title_justify="left")
    for col in ("kind", "name", "summary", "input", "plugin", "requires"):
        table.add_column(col)
    for row in rows:
        reqs = " ".join(f"{r['module']} {'✓' if r['available'] else '✗ missing'}"
                        for r in row["requires"]) or "-"
        table.add_row(row["kind"], row["name"], row["summary"], row.get("input", "-"),
                      row["plugin"], reqs)
    Console().print(table)


@click.command("plugins")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def plugins_cmd(as_json: bool) -> None:
    """List plugins (built-in and installed), their versions and load errors."""
    registry = get_registry(warn=False)
    by_plugin: dict[str, list[str]] = {}
    for problem in registry.problems:
        by_plugin.setdefault(problem.plugin, []).append(problem.message)
    rows = [{"name": p.name, "distribution": p.distribution, "version": p.version,
             "source": p.source, "hooks": list(p.hooks),
             "errors": by_plugin.get(p.name, [])} for p in registry.plugins]
    if as_json:
        click.echo(json_text({"plugins": rows}, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="tactbench plugins", title_justify="left")
    for col in ("plugin", "distribution", "version", "source", "hooks", "errors"):
        table.add_column(col)
    for row in rows:
        errors = "\n".join(row["errors"])
        table.add_row(row["name"], row["distribution"], row["version"], row["source"],
                      ", ".join(row["hooks"]) or "-",
                      f"[red]{errors}[/red]" if errors else "-")
    Console().print(table)
