"""``tactbench run``: compare encoders × classifiers × L × seeds on one split."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from tactbench.cli import get_registry
from tactbench.profiles import PRECISIONS, PROFILE_NAMES


@click.command("run")
@click.argument("scene_file", required=False, type=click.Path(dir_okay=False))
@click.option("--dataset", help="Registered dataset (with options) or a dataset path. "
              "[default: synthetic-forearm]")
@click.option("--encoder", "encoders", multiple=True,
              help="Encoder, repeatable, with options: farneback:winsize=9. "
                   "[default: raw, farneback]")
@click.option("--classifier", "classifiers", multiple=True,
              help="Classifier, repeatable, with options. [default: small-cnn-lstm]")
@click.option("-L", "lengths", multiple=True,
              help="Window length in frames, repeatable or a range: -L 5, -L 1-6. "
                   "[default: 5]")
@click.option("--seed", "seeds", multiple=True,
              help="Seed, repeatable or a range: --seed 0-9. [default: 0 1 2]")
@click.option("--split",
              help="paper: 30 random test samples per class (the study's); users: "
                   "leave a random fifth of the users out; users:folds=K: K-fold over "
                   "users, every user tested once; group:KEY[:folds=K|:test=A] the same "
                   "over any metadata (position, repetition): group:position:test=side "
                   "trains on the front, tests on the side. [default: paper]")
@click.option("--test-window", type=click.Choice(["first", "onset", "vote"]),
              help="Which frames a test sequence is classified on: first (its first L "
                   "frames, the study's), onset (L frames from contact onset) or vote "
                   "(every window, probabilities averaged). [default: first]")
@click.option("--profile", type=click.Choice(PROFILE_NAMES),
              help="quick: CPU-sized (default); paper: the study's settings (a GPU job).")
@click.option("--pixel-mm", type=float, help="Tactile-image pixel size in mm "
              "[default: the profile's: quick 5, paper 1].")
@click.option("--precision", type=click.Choice(PRECISIONS),
              help="How cached encodings are stored: float32 (exact), float16, or uint8 "
                   "(8 bits per channel value, as the study's images; a quarter of the "
                   "disk). [default: the profile's: quick float32, paper uint8]")
@click.option("--device", help="cpu, cuda, cuda:N or auto. [default: cpu]")
@click.option("--threads", type=int, help="torch threads per cell [default: cores/workers].")
@click.option("--executor", type=click.Choice(["local", "dask"]), help="[default: local]")
@click.option("--workers", type=int, help="Parallel cells (processes). [default: 1]")
@click.option("--scheduler", help="dask scheduler address tcp://HOST:PORT (with "
              "--executor dask); default: a local cluster.")
@click.option("--out", help="Output folder. [default: tactbench-out]")
@click.option("--rerun", is_flag=True, default=None, help="Recompute finished cells.")
@click.option("--save-models", is_flag=True, default=None,
              help="Keep each cell's trained model in OUT/models (for `tactbench live`).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document (the summary).")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
def run_cmd(scene_file, dataset, encoders, classifiers, lengths, seeds, split, test_window,
            profile,
            pixel_mm, precision, device, threads, executor, workers, scheduler, out, rerun,
            save_models, as_json, no_plots) -> None:
    """Run a benchmark grid and report accuracy beside its cost.

    Finished cells are kept in OUT/cells and skipped when the same command runs again;
    encodings are cached (see `tactbench cache ls`). A cell that fails is recorded and the
    others go on; the command then exits with status 1, and running it again retries
    the failed cells.
    """
    from tactbench.runner import Scene, load_scene_file, parse_lengths, run
    from tactbench.runner.reports import (
        failed_cells,
        print_comparisons,
        print_table,
        summarise,
        write_reports,
    )
    from tactbench.runner.scene import parse_seeds

    fields = load_scene_file(scene_file) if scene_file else {}
    given = {"dataset": dataset, "encoders": list(encoders) or None,
             "classifiers": list(classifiers) or None,
             "lengths": parse_lengths(lengths) if lengths else None,
             "seeds": parse_seeds(seeds) if seeds else None, "split": split,
             "test_window": test_window, "profile": profile,
             "pixel_mm": pixel_mm, "precision": precision, "device": device,
             "threads": threads, "executor": executor, "workers": workers,
             "scheduler": scheduler, "out": out, "rerun": rerun, "save_models": save_models}
    fields.update({k: v for k, v in given.items() if v is not None})
    if fields.get("scheduler") and fields.get("executor", "local") != "dask":
        raise click.UsageError("--scheduler needs --executor dask")
    scene = Scene(**fields)
    registry = get_registry()
    result = run(scene, registry=registry, progress=sys.stderr.isatty() or not as_json)
    meta = {"command": " ".join(["tactbench", *sys.argv[1:]]),
            "git": result.rows[0]["run"]["git"] if result.rows else None,
            "computed": result.computed, "skipped": result.skipped,
            "seconds": result.seconds}
    paths = write_reports(scene.out, result.rows, meta=meta, plots=not no_plots)
    summaries = summarise(result.rows)
    failed = failed_cells(result.rows)
    if as_json:
        comps = json.loads(paths["json"].read_text())["comparisons"]
        click.echo(json.dumps({"meta": meta, "summary": summaries, "comparisons": comps,
                               "failed": failed,
                               "files": {k: str(v) for k, v in paths.items()}}, indent=2))
    else:
        print_table(summaries, title=f"{scene.dataset} · split {scene.split} · test window "
                                     f"{scene.test_window} · profile {scene.profile}")
        print_comparisons(json.loads(paths["json"].read_text())["comparisons"])
        click.echo(f"{result.computed} cell(s) computed, {result.skipped} already done; "
                   f"{result.seconds:.1f} s. Reports in {scene.out}/ (report.md, "
                   f"results.csv, results.json, plots)")
    if failed:
        cells = Path(scene.out) / "cells"
        for f in failed:
            click.echo(f"failed: {f['encoder']} × {f['classifier']} L={f['L']} "
                       f"seed={f['seed']}: {f['error']} ({cells / f['key']}.json)", err=True)
        click.echo(f"{len(failed)} cell(s) failed; their rows are in {cells}/ and running "
                   f"the same command again retries them", err=True)
        click.get_current_context().exit(1)
