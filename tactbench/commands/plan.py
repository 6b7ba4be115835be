"""``tactbench plan``: a run's cells, time, memory and power, before any training."""

from __future__ import annotations

import sys

import click

from tactbench.budget import human_bytes
from tactbench.cli import get_registry, json_text
from tactbench.commands.run import scene_from, scene_options
from tactbench.runner import forecast, points


@click.command("plan")
@scene_options
@click.option("--effect", type=float, default=5.0, show_default=True, metavar="POINTS",
              help="The true difference (accuracy points) each primary comparison's power "
                   "is computed for.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document.")
@click.pass_context
def plan_cmd(ctx: click.Context, scene_file: str | None, effect: float, as_json: bool,
             **options) -> None:
    """Plan a run before it trains: its cells, time and memory, and the power of each
    primary question.

    Takes the same arguments as `tactbench run`. Times and memory come from rows already
    in the out folder (a pilot run of a seed or two), and so does each comparison's
    per-run spread (with its 95 % interval); without a pilot the spread is an assumption,
    said with its value (models disagreeing on 30 % of the test recordings, test sampling
    alone). Power is at the primary family's level; with --until it is also the
    sequential run's own, simulated. An effect inside --margin, or a design short of
    80 % power, is said first, a line each.
    For one data set it also says the floor no number of runs resolves below, and how
    many recordings would lower it to --effect; a dataset drawing its own for every run
    (synthetic-forearm:people=per-run) has none, and only its first run's data set is
    made to plan. With --until, the cells are those of every run the looks may reach.
    """
    if not 0 < effect <= 100 or effect / 100 == 0:  # 5e-324 points: 0 as a fraction
        raise click.BadParameter(f"must be in (0, 100] points and not vanish as a "
                                 f"fraction, got {effect:g}", param_hint="--effect")
    scene = scene_from(ctx, scene_file, options)
    f = forecast(scene, get_registry(), effect=effect)
    if as_json:
        click.echo(json_text(f.as_dict(), indent=2))
        return
    _print_time(f, scene.out)
    click.echo(f"split: {f.n_test} test recordings against {f.n_train} training ones "
               f"per run" + (", each run on a data set of its own (independent "
                             "replications: no overlap correction)" if f.independent else ""))
    if f.runs_not_made:
        click.echo(f"data sets: the first run's made to plan; the other {f.runs_not_made} "
                   f"runs' are made when they run (their making and encoding is not in the "
                   f"time), and a cell of theirs counts as finished where a stored row of "
                   f"its run's data set has its identity")
    _print_distinct(f)
    for line in (w for p in f.primaries for w in p.warnings):
        click.echo(f"warning: {line}")
    for p in f.primaries:
        high = ("" if p.power_at_sd_high is None else
                f" ({p.power_at_sd_high:.0%} if the spread is at the pilot's 95 % upper "
                f"limit, {p.sd_high:.1f} points)")
        click.echo(f"primary {p.name}: one fixed test of {p.runs} runs at the family's "
                   f"level α = {p.level:.4g} ({len(f.primaries)} primary comparison(s)): "
                   f"power {p.power:.0%} for {points(p.effect)} points"
                   f"{high}; 80 % power from {p.detectable:.1f} points; per-run sd "
                   f"{p.sd:.1f} points ({p.sd_source})")
        if p.sequential:
            s = p.sequential
            click.echo(f"  run --until answered (looks after {', '.join(map(str, s['looks']))}"
                       f" runs): {points(p.effect)} points found {s['power']:.0%}"
                       + (f", equivalent {s['equivalent']:.0%}" if p.margin else "")
                       + f", the other side {s['wrong_side']:.0%}; stopped early as futile "
                       f"{s['stopped_futile']:.0%}; reached {s['max_runs']} runs undecided "
                       f"{s['undecided_at_max']:.0%}; {s['expected_runs']:.1f} runs expected"
                       f" (simulated: {s['paths']} paths, ±{s['mc_error']:.3f})")
        if f.independent:
            click.echo("  no floor: every run draws its own data set (independent "
                       "replications of the simulator's population), so more runs resolve "
                       "ever smaller differences")
            continue
        if f.design == "fixed":
            click.echo(f"  no floor: one fixed split, the same {f.n_test} test recordings in "
                       f"every run (runs differ only by initialisation), so more runs "
                       f"resolve ever smaller differences on that split; the answer speaks "
                       f"of it alone, not of new recordings")
            continue
        more = ("" if p.recordings_for_effect is None or p.recordings_for_effect
                <= p.recordings else f"; about {p.recordings_for_effect} recordings (now "
                f"{p.recordings}) would bring it to {points(p.effect)[1:]}")
        click.echo(f"  {p.persistent_said}")
        click.echo(f"  floor: no number of runs of these {p.recordings} recordings "
                   f"resolves less than {p.floor:.1f} points ((z_(1−α/2) + z_0.8) × "
                   f"{p.persistent:.2f}){more}")
    _print_family(f)
    if not f.primaries:
        click.echo("no primary comparison (give --primary A..B)", file=sys.stderr)


def _print_family(f) -> None:
    """The family's chance of every primary comparison being answered, and how."""
    if f.family is None or len(f.primaries) < 2:
        return
    fam = f.family
    shared = sum(x != 0 for row in fam["corr"] for x in row) > len(f.primaries)
    click.echo(f"family: every one of the {len(f.primaries)} primary comparisons "
               f"answered with chance {fam['answered']:.0%} (simulated through the "
               f"run's own procedure: Holm over the family, α passed on after a "
               f"rejection" + (", the looks" if f.looks else ", one fixed test")
               + (", comparisons sharing a cell correlated" if shared else
                  ", the comparisons share no cell and are drawn independent")
               + f"; {fam['paths']} paths, ±{fam['mc_error']:.3f})")


def _print_distinct(f) -> None:
    """A warning where the data allow fewer distinct splits than the runs planned."""
    if f.distinct_splits is not None and f.distinct_splits < f.runs_asked:
        click.echo(f"warning: the data allow only {f.distinct_splits} distinct splits for "
                   f"{f.runs_asked} runs: the seeds beyond repeat splits already drawn and "
                   f"add no evidence (a run counts each split once); the power below is "
                   f"that of {f.distinct_splits} runs")


def _print_time(f, out: str) -> None:
    """Each cell's time and where it comes from, the total, and the run's wall time."""
    for c in f.cells:
        shown = "?" if c.seconds is None else f"{c.seconds:.0f} s"
        click.echo(f"cell {c.label}: {shown} ({c.source})")
    if f.seconds is None:
        total = f"unknown (no cell has a timing: run a pilot of one seed into {out})"
    else:
        total = f"{f.seconds / 60:.1f} min" + (
            f" for the {len(f.cells) - f.unknown} cells with a timing, {f.unknown} without"
            if f.unknown else "")
    click.echo(f"{len(f.cells)} cells; time on this machine: {total}")
    _print_memory(f)
    if f.wall_s:
        at = (f"{f.wall_s[0] / 60:.1f} min to the first look ({f.looks[0]} runs), "
              f"{f.wall_s[-1] / 60:.1f} min if it runs to {f.looks[-1]}" if f.looks
              else f"{f.wall_s[0] / 60:.1f} min")
        click.echo(f"wall time of the run: about {at} ({f.workers} cell(s) at once, one "
                   f"thread each; encoding what the cache lacks included)")
    _print_cache(f)


def _print_memory(f) -> None:
    """The run's workers, what set their number, and the whole run's peak memory."""
    if f.worker_peak_mb is None:
        click.echo(f"memory: {f.workers} worker(s) ({f.workers_limit}); peak not forecast")
        return
    capped = ((f.record or {}).get("workers") or {}).get("memory_source") == "--memory"
    whose = "the --memory cap's" if capped else "this machine's"
    of = "" if f.memory_mb is None else f" of {whose} {f.memory_mb / 1024:.1f} GiB"
    click.echo(f"memory: {f.workers} worker(s) at once (set by {f.workers_limit}), each "
               f"at about {f.worker_peak_mb / 1024:.2f} GiB ({f.worker_peak_source}); "
               f"the whole run, its own process and every worker, about "
               f"{f.run_peak_mb / 1024:.2f} GiB{of}")


def _print_cache(f) -> None:
    """What the run adds to the encoding cache, and whether its disk has room."""
    if not f.cache_bytes:
        click.echo("cache: every encoding the run needs is already there")
        return
    free = "" if f.cache_free is None else f" ({human_bytes(f.cache_free)} free on its disk)"
    runs = (f" (a data set per run: {f.runs_not_made + 1} runs' entries, each sized as the "
            f"first run's)" if f.independent and f.runs_not_made else "")
    click.echo(f"cache: about {human_bytes(f.cache_bytes)} of new encodings{runs}{free}")
    if f.cache_free is not None and f.cache_bytes > f.cache_free:
        click.echo("warning: the cache's disk is too small for them, and the run would be "
                   "refused: make room (tactbench cache prune --max-size SIZE) or set "
                   "TACTBENCH_CACHE to a folder on another disk")
