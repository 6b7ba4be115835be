"""``tactbench run``: compare encoders × classifiers × L × seeds on one split."""

from __future__ import annotations

import dataclasses
import sys
from typing import Any, Callable, Sequence

import click

from tactbench.cli import get_registry, json_text
from tactbench.profiles import PRECISIONS, PROFILE_NAMES, get_profile
from tactbench.runner import (DEFAULT_PRIMARY, EXECUTORS, FIRST_LOOK, INPUT_KINDS, Report, Scene,
                              UNTIL, answer_text, failed_cells, labels_for, load_scene_file,
                              parse_lengths, parse_seeds, print_comparisons, print_table, run,
                              run_until, show_duration)




class SceneOption(click.Option):
    """An option that sets the :class:`~tactbench.runner.execution.scene.Scene` field ``field``.

    Its help ends in ``[default: ...]`` read from the Scene's own field default when the
    help is shown (:func:`scene_default`), so the help cannot drift from the dataclass; a
    field whose default is ``None`` (decided later, by the profile or the machine) says
    what decides it in ``none``. ``convert`` turns the option's value into the field's
    (``-L 1-3`` → ``[1, 2, 3]``). The option's own default stays ``None``: not given, so
    a scene file's value or the Scene's default applies.
    """

    def __init__(self, *args: Any, field: str, none: str | Callable[[], str] | None = None,
                 convert: Callable[[Any], Any] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.field, self.none, self.convert = field, none, convert

    def get_help_record(self, ctx: click.Context) -> tuple[str, str] | None:
        record = super().get_help_record(ctx)
        if record is None:
            return None
        shown = scene_default(self.field, self.none)
        return record if shown is None else (record[0], f"{record[1]} [default: {shown}]")

    def field_value(self, value: Any) -> Any:
        """The Scene field's value for what was given, or None when it was not."""
        if value is None or value == ():
            return None
        if self.multiple:
            value = list(value)
        return self.convert(value) if self.convert is not None else value


def scene_default(name: str, none: str | Callable[[], str] | None = None) -> str | None:
    """The Scene field ``name``'s default as help shows it (lists joined by ", "); for a
    default of ``None``, ``none`` (text, or a function giving it); a flag's ``False`` is
    not shown (None)."""
    (f,) = [f for f in dataclasses.fields(Scene) if f.name == name]
    value = f.default_factory() if f.default is dataclasses.MISSING else f.default  # type: ignore[misc]
    if value is None:
        if none is None:
            raise TypeError(f"scene field {name!r} defaults to None: its option must say "
                            f"what decides it (none=...)")
        return none() if callable(none) else none
    if isinstance(value, bool):
        return None
    if isinstance(value, list):
        return ", ".join(str(v) for v in value)
    return str(value)


def _by_profile(attribute: str) -> Callable[[], str]:
    """``"the profile's: quick 5, paper 1"``: a profile setting, read from the profiles."""
    def text() -> str:
        values = {n: getattr(get_profile(n), attribute) for n in PROFILE_NAMES}
        return "the profile's: " + ", ".join(
            f"{n} {v:g}" if isinstance(v, float) else f"{n} {v}" for n, v in values.items())

    return text


def scene_option(*decls: str, field: str, **kwargs: Any) -> Callable[[Any], Any]:
    """``click.option`` for the Scene field ``field`` (see :class:`SceneOption`)."""
    return click.option(*decls, cls=SceneOption, field=field, **kwargs)


#: The options that set a :class:`Scene`, shared by ``run`` and ``plan`` (same arguments).
SCENE_OPTIONS = [
    click.argument("scene_file", required=False, type=click.Path(dir_okay=False)),
    scene_option("--dataset", field="dataset",
                 help="Registered dataset (with options) or a dataset path."),
    scene_option("--encoder", "encoders", field="encoders", multiple=True,
                 help="Encoder, repeatable, with options: farneback:winsize=9."),
    scene_option("--classifier", "classifiers", field="classifiers", multiple=True,
                 help="Classifier, repeatable, with options."),
    scene_option("-L", "L", field="L", multiple=True, convert=parse_lengths,
                 help="Window length in frames, repeatable or a range: -L 5, -L 1-6."),
    scene_option("--seed", "seeds", field="seeds", multiple=True, convert=parse_seeds,
                 help="Seed, repeatable or a range: --seed 0-9."),
    scene_option("--split", field="split",
                 help="paper: 30 random test samples per class (the study's); users: "
                      "leave a random fifth of the users out; users:folds=K: K-fold over "
                      "users, every user tested once; group:KEY[:folds=K|:test=A] the same "
                      "over any metadata (position, repetition): group:position:test=side "
                      "trains on the front, tests on the side; kfold:folds=K: stratified "
                      "K-fold over recordings, each tested once per seed; sklearn:NAME: a "
                      "scikit-learn splitter (sklearn:GroupKFold:n_splits=5, "
                      "sklearn:LeaveOneGroupOut:groups=position); or a plugin's split "
                      "(tactbench list). The split's design picks the t "
                      "(docs/statistics.md)."),
    scene_option("--test-window", field="test_window",
                 help="Which frames a test sequence is classified on: vote (every window, "
                      "probabilities averaged), onset (L frames from contact onset), first "
                      "(its first L frames, the study's protocol), or a plugin's."),
    scene_option("--profile", field="profile", type=click.Choice(PROFILE_NAMES),
                 help="quick: CPU-sized; paper: the study's settings (a GPU job)."),
    scene_option("--pixel-mm", field="pixel_mm", type=float, none=_by_profile("pixel_mm"),
                 help="Tactile-image pixel size in mm."),
    scene_option("--precision", field="precision", type=click.Choice(PRECISIONS),
                 none=_by_profile("precision"),
                 help="How cached encodings are stored: float32 (exact), float16, or uint8 "
                      "(8 bits per channel value, as the study's images; a quarter of the "
                      "disk)."),
    scene_option("--device", field="device", help="cpu, cuda, cuda:N or auto."),
    scene_option("--threads", field="threads", type=int,
                 help="torch threads per cell (part of a cell's identity: another count "
                      "gives other numbers)."),
    scene_option("--executor", field="executor", type=click.Choice(EXECUTORS),
                 help="Where cells run: this machine, or a dask cluster."),
    scene_option("--workers", field="workers", type=int, none="cores / --threads, GPUs, memory",
                 help="Cells at once (processes)."),
    scene_option("--memory", field="memory", metavar="SIZE", none="this machine's",
                 help="The most memory the run takes in all, its own process and its "
                      "workers (4GiB, 500MiB): the worker count fits each worker's "
                      "forecast peak in it, and a run whose forecast is above it is "
                      "refused before any training."),
    scene_option("--scheduler", field="scheduler", none="a local cluster",
                 help="dask scheduler address tcp://HOST:PORT (with --executor dask)."),
    scene_option("--out", field="out", help="Output folder."),
    scene_option("--rerun", field="rerun", is_flag=True, default=None,
                 help="Recompute finished cells."),
    scene_option("--save-models", field="save_models", is_flag=True, default=None,
                 help="Keep each cell's trained model in OUT/models (for `tactbench live`)."),
    scene_option("--margin", field="margin", type=float, metavar="POINTS",
                 none="none (no equivalence test)",
                 help="Equivalence margin in accuracy points: a comparison whose run-level "
                      "interval lies within ±POINTS (two one-sided tests) is \"equivalent\"."),
    scene_option("--contrast", "contrasts", field="contrasts", multiple=True, metavar="A..B",
                 none="none",
                 help="Also compare two cells differing in several factors, paired over "
                      "runs, repeatable: --contrast encoder=raw,L=6..encoder=farneback,L=3 "
                      "(B − A; factors encoder, classifier, L)."),
    scene_option("--input", "input_kind", field="input", type=click.Choice(INPUT_KINDS),
                 none="images where the dataset has a layout",
                 help="What a classifier taking either input is fed (part of its cells' "
                      "identity)."),
    scene_option("--init-seed", "init_seeds", field="init_seeds", multiple=True, convert=parse_seeds,
                 none="the split seed",
                 help="Initialisation seeds varied apart from the split seeds (--seed), "
                      "repeatable or a range; report.md then splits the variance."),
    scene_option("--primary", "primary", field="primary", multiple=True, metavar="A..B",
                 none=f"{DEFAULT_PRIMARY} where the grid has both",
                 help="A confirmatory comparison (contrast syntax), repeatable: the primary "
                      "questions form their own family (Holm) and lead the report; the "
                      "other comparisons are exploratory."),
    scene_option("--paired-test", field="paired_test", metavar="NAME", none="corrected-t",
                 help="The paired test every comparison's p and interval come from (a "
                      "registered one, `tactbench list`); refused for designs it does not "
                      "declare (wilcoxon: fixed splits and independent runs, no --until)."),
    scene_option("--until", field="until", type=click.Choice(UNTIL),
                 none="the seeds given, once",
                 help=f"answered: run the seeds in batches (the first look after "
                      f"{FIRST_LOOK} runs) "
                      "until every primary question is better, worse, equivalent within "
                      "--margin, or futile, with α spent over the looks."),
    scene_option("--max-runs", field="max_runs", type=int,
                 help="With --until: the most runs (seeds) the looks may reach."),
    scene_option("--look-every", field="look_every", type=int,
                 help="With --until: runs added between two looks."),
    scene_option("--budget", field="budget", metavar="DURATION", none="none",
                 help="With --until: begin no batch that would end past this time "
                      "(90m, 2h, 1h30m)."),
]


def scene_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """``command`` with every option of :data:`SCENE_OPTIONS` (and the scene file)."""
    for option in reversed(SCENE_OPTIONS):
        command = option(command)
    return command


def scene_from(ctx: click.Context, scene_file: str | None, options: dict[str, Any]) -> Scene:
    """The scene of a scene file and the command line's options (which override it), a
    refused value named as it was given."""
    fields = load_scene_file(scene_file) if scene_file else {}
    labels = {}
    for param in ctx.command.params:  # command-line values override the file
        if isinstance(param, SceneOption):
            value = param.field_value(options[param.name])
            if value is not None:
                fields[param.field] = value
                labels[param.field] = max(param.opts, key=len)
    if fields.get("scheduler") and fields.get("executor", "local") != "dask":
        raise click.UsageError("--scheduler needs --executor dask")
    return Scene.of(fields, labels=labels)


@click.command("run")
@scene_options
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document (the summary).")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@click.pass_context
def run_cmd(ctx: click.Context, scene_file: str | None, as_json: bool, no_plots: bool,
            **options: Any) -> None:
    """Run a benchmark grid and report accuracy beside its cost.

    Finished cells are kept in OUT/cells and skipped when the same command runs again;
    encodings are cached (see `tactbench cache ls`). A cell that fails is recorded and the
    others go on; the command then exits with status 1, and running it again retries
    the failed cells.
    """
    scene = scene_from(ctx, scene_file, options)
    if scene.design.budget_seconds is not None:  # echoed as read: "1h30m" is 1 h 30 min
        click.echo(f"budget: {show_duration(scene.design.budget_seconds)} (no batch of "
                   f"runs begun that would end past it)", err=True)
    if scene.until:
        report = run_until(scene, registry=get_registry(), plots=not no_plots,
                           progress=sys.stderr.isatty() or not as_json)
    else:
        report = run(scene, registry=get_registry(), plots=not no_plots,
                     progress=sys.stderr.isatty() or not as_json)
    print_report(report, as_json=as_json,
                 title=f"{scene.dataset} · split {scene.split} · test window "
                       f"{scene.test_window} · profile {scene.profile}",
                 done=f"{report.computed} cell(s) computed, {report.skipped} already done; "
                      f"{report.seconds:.1f} s. Reports in {scene.out}/ (report.md, "
                      f"results.csv, results.json, plots)")
    if report.failed:
        ctx.exit(1)


def print_report(report: Report, *, as_json: bool, title: str, done: str) -> None:
    """Print ``report``: its tables of summaries and comparisons and the line ``done``,
    or (``as_json``) one JSON document (``meta``: the runs that computed the rows, how
    the report was rendered, and what this command did; ``summary``, ``comparisons``,
    ``failed``, ``files``); then each failed cell, on stderr."""
    failed = failed_cells(report.rows)
    labels = labels_for(rows=report.rows)  # variants of one classifier told apart
    if as_json:
        meta = {"runs": report.runs, "rendered": report.rendered,
                "computed": report.computed, "skipped": report.skipped,
                "seconds": report.seconds, "cpu_seconds": report.cpu_seconds,
                "budget_stop": report.budget_stop}
        click.echo(json_text({"meta": meta, "summary": report.summaries,
                              "comparisons": [c.to_dict() for c in report.comparisons],
                              "looks": report.looks, "failed": failed,
                              "files": {k: str(v) for k, v in report.paths.items()}},
                             indent=2))
    else:
        answers = [answer_text(c, labels).replace("**", "")
                   for c in report.comparisons if c.family == "primary"]
        for line in answers:  # the primary questions lead
            click.echo(f"primary: {line}")
        if report.looks:
            click.echo(f"looks: {len(report.looks['looks'])}; {report.looks['stopped']}"
                       + (f"; stopped by {report.budget_stop}" if report.budget_stop else "")
                       + (f"; {report.cpu_seconds:.0f} CPU-s in all"
                          if report.cpu_seconds else ""))
        print_table(report.summaries, title=title, labels=labels)
        print_comparisons(report.comparisons, factors=("encoder", "classifier", "contrast"),
                          labels=labels)
        click.echo(done)
    if failed:
        cells = report.paths["json"].parent / "cells"
        for f in failed:
            click.echo(f"failed: {f['encoder']} × {f['classifier']} L={f['L']} "
                       f"seed={f['seed']}: {f['error']} ({cells / f['key']}.json)", err=True)
        click.echo(f"{len(failed)} cell(s) failed; their rows are in {cells}/ and running "
                   f"the same command again retries them", err=True)


def scene_of_command(args: Sequence[str]) -> Scene:
    """The scene ``tactbench run ARGS`` would run, read by this command's own options
    (nothing is run): for a script that keeps a run's command line, such as
    benchmarks/reports.py, so that no script parses the options again."""
    ctx = run_cmd.make_context("run", list(args))
    return scene_from(ctx, ctx.params["scene_file"], ctx.params)
