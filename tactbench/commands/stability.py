"""``tactbench stability``: every encoder on stiff and extreme inputs, pass or fail."""

from __future__ import annotations

import sys

import click

from tactbench.cli import get_registry, json_text
from tactbench.encoders.evaluation import stability as st
from tactbench.ui import Progress


@click.command("stability")
@click.option("--encoder", "-e", "specs", multiple=True,
              help="Encoder (repeatable, options allowed). Default: every registered encoder.")
@click.option("--case", "cases", multiple=True,
              help="Only these cases (repeatable). Default: all; see the list in the docs.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
def stability_cmd(specs: tuple[str, ...], cases: tuple[str, ...], as_json: bool) -> None:
    """Every encoder on stiff and extreme inputs: pass or fail, with the reason.

    Cases: all-zero, constant, saturated, hot pixel, checkerboard, NaN/Inf,
    huge and sub-pixel motion, tiny images, T = 1 and 1000, integer and
    float16/64 input, and values far outside [0, 1]. Each case × encoder passes (finite, in range, deterministic, the documented
    result) or fails with the reason. The exit status is 1 when anything failed.
    """
    registry = get_registry(warn=not as_json)
    explicit = bool(specs)
    specs = specs or tuple(registry.names("encoder"))
    encoders, unbuildable = [], {}
    for spec in specs:
        try:
            encoders.append((spec, registry.build("encoder", spec)))
        except Exception as exc:  # a plugin that cannot be built fails every case
            if explicit:
                raise
            unbuildable[spec] = f"cannot build: {type(exc).__name__}: {exc}"
    all_cases = st.select_cases(cases)
    with Progress() as bars:
        outcomes = st.run_stability(encoders, all_cases, progress=bars.callback("stability"))
    outcomes += [st.Outcome(case.name, spec, False, reason, 0.0)
                 for spec, reason in unbuildable.items() for case in all_cases]
    failed = [o for o in outcomes if not o.passed]
    if as_json:
        click.echo(json_text({
            "passed": not failed, "failed": len(failed), "total": len(outcomes),
            "cases": [{"name": c.name, "description": c.description,
                       "expects_error": c.expect_error} for c in all_cases],
            "results": [o.to_dict() for o in outcomes]}, indent=2))
    else:
        from rich.console import Console
        from rich.table import Table

        console = Console()
        table = Table(title="stability: case × encoder", title_justify="left")
        table.add_column("case", no_wrap=True)
        for spec in specs:
            table.add_column(spec, justify="center")
        by = {(o.case, o.encoder): o for o in outcomes}
        for case in all_cases:
            table.add_row(case.name, *("[green]✓[/green]" if by[case.name, s].passed
                                       else "[red]✗[/red]" for s in specs))
        console.print(table)
        for o in failed:
            console.print(f"[red]FAILED[/red] {o.case} × {o.encoder}: {o.reason}",
                          highlight=False)
        console.print(f"{len(outcomes) - len(failed)}/{len(outcomes)} passed", highlight=False)
    if failed:
        sys.exit(1)
