"""``tactbench report DIR``: a run folder's report rendered again from its cells."""

from __future__ import annotations

import click

from tactbench.cli import get_registry
from tactbench.commands.run import print_report
from tactbench.errors import require
from tactbench.runner import EXPORT_EXTRA as EXTRA, render_folder


@click.command("report")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--margin", type=float, metavar="POINTS", default=None,
              help="Equivalence margin in accuracy points. [default: the run's]")
@click.option("--contrast", "contrasts", multiple=True, metavar="A..B",
              help="Compare two cells differing in several factors, repeatable (see "
                   "`tactbench run --contrast`). [default: the run's]")
@click.option("--primary", multiple=True, metavar="A..B",
              help="A confirmatory comparison, repeatable (see `tactbench run --primary`). "
                   "[default: the run's]")
@click.option("--paired-test", metavar="NAME", default=None,
              help="The paired test of every comparison (see `tactbench run --paired-test`). "
                   "[default: the run's]")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document (the summary).")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@click.option("--parquet", is_flag=True,
              help="Also write cells.parquet (one row per cell) and comparisons.parquet "
                   "(one per comparison), typed tables for pandas and pyarrow "
                   "(pip install \"tactbench[export]\").")
def report_cmd(folder: str, margin: float | None, contrasts: tuple[str, ...],
               primary: tuple[str, ...], paired_test: str | None, as_json: bool,
               no_plots: bool, parquet: bool) -> None:
    """Render a run folder's report again from its stored cell rows, training nothing.

    FOLDER is the --out of a `tactbench run`. Its results.json, results.csv, report.md
    and plots are written again from the rows in FOLDER/cells alone (results.json is
    never read), with the statistics options given here, which change no cell; without
    them, the run's own. report.md says it was re-rendered, and with which options.
    With --parquet, the tables are also written as Parquet files.
    """
    if parquet:  # before any file is written: a missing library is one line
        require("pandas", EXTRA)
        require("pyarrow", EXTRA)
    report = render_folder(folder, margin=margin, contrasts=contrasts or None,
                           primary=primary or None, plots=not no_plots, paired_test=paired_test,
                           registry=get_registry(), parquet=parquet)
    print_report(report, as_json=as_json, title=f"{folder} · re-rendered from its cells",
                 done=f"{len(report.rows)} cell row(s) read, none computed. Reports in "
                      f"{folder}/ (report.md, results.csv, results.json, plots"
                      + (", cells.parquet, comparisons.parquet" if parquet else "") + ")")
