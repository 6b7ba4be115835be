"""``tactbench run --until answered`` and ``--primary``: looks from the rows, resumable,
the same looks when the report is rendered again."""

from __future__ import annotations

import json
import os

import pytest
from click.testing import CliRunner

from tactbench.cli import cli

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = ["--dataset", "synthetic-forearm:users=2,repetitions=1", "--encoder", "raw",
        "--encoder", "frame-diff", "--classifier", "logreg:max_iter=20", "-L", "3",
        "--pixel-mm", "10", "--threads", "1"]
PRIMARY = "encoder=raw..encoder=frame-diff"


def _invoke(tmp_path, monkeypatch, *args: str):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    return CliRunner().invoke(cli, [*args, str(scene)], catch_exceptions=False)


def test_runs_are_added_until_the_primary_is_answered_and_the_looks_replay(tmp_path,
                                                                          monkeypatch):
    out = tmp_path / "out"
    args = ["run", *TINY, "--seed", "0", "--out", str(out), "--primary", PRIMARY,
            "--until", "answered", "--max-runs", "7", "--look-every", "1"]
    first = _invoke(tmp_path, monkeypatch, *args)
    assert first.exit_code == 0, first.output
    text = first.output  # the primary question leads, before the tables
    assert text.index("primary: frame-diff against raw") < text.index("· test window")
    doc = json.loads((out / "results.json").read_text())
    looks = doc["looks"]
    assert [lk["runs"] for lk in looks["looks"]] == [5, 6, 7][:len(looks["looks"])]
    seeds = {r["seed"] for r in doc["rows"]}
    assert seeds == set(range(looks["looks"][-1]["runs"]))  # no seed past the last look
    if not looks["answered"]:
        assert len(looks["looks"]) == 3 and "7 of 7" in looks["stopped"]
    report = (out / "report.md").read_text()
    assert report.index("## Primary questions") < report.index("| encoder | classifier")
    assert "### Primary questions (confirmatory)" in report
    [primary] = [c for c in doc["comparisons"] if c["family"] == "primary"]
    assert (primary["a"], primary["b"]) == ("raw", "frame-diff")
    # its verdict is the looks' decision, not a fixed-design test at the last run count
    [name] = looks["looks"][-1]["comparisons"]
    decided = looks["decisions"].get(name)
    if decided == "not learned":  # the tiny logreg is within noise of chance: no verdict
        assert primary["verdict"] == decided and looks["answered"]
        assert primary["note"].startswith("no verdict rests on a model at chance: ")
        assert "a model did not learn" in looks["stopped"]
    elif decided in ("A better", "B better", "equivalent"):
        assert primary["verdict"] == decided
    else:
        assert primary["verdict"] == "unresolved"
    if decided != "not learned":
        assert primary["note"].startswith("group-sequential: ")
    # resumed: nothing computed again, the same looks
    again = _invoke(tmp_path, monkeypatch, *args, "--json")
    assert again.exit_code == 0, again.output
    assert json.loads(again.output)["meta"]["computed"] == 0
    assert json.loads((out / "results.json").read_text())["looks"] == looks
    # rendered again from the cells: the same looks, replayed from the rows
    rendered = CliRunner().invoke(cli, ["report", str(out), "--no-plots"],
                                  catch_exceptions=False)
    assert rendered.exit_code == 0, rendered.output
    assert json.loads((out / "results.json").read_text())["looks"] == looks


def test_what_a_run_until_answered_did_counts_every_look(tmp_path, monkeypatch):
    """meta's computed / skipped / seconds are the whole command's, not its last look's:
    a report saying "N reused from an earlier run" of cells this run made misleads."""
    out = tmp_path / "out"
    args = ["run", *TINY, "--seed", "0", "--out", str(out), "--primary", PRIMARY,
            "--until", "answered", "--max-runs", "7", "--look-every", "1", "--json"]
    first = _invoke(tmp_path, monkeypatch, *args)
    assert first.exit_code == 0, first.output
    meta = json.loads(first.output)["meta"]
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert (meta["computed"], meta["skipped"]) == (len(rows), 0)
    looks = json.loads((out / "results.json").read_text())["looks"]["looks"]
    assert len(rows) == 2 * looks[-1]["runs"]  # two encoders, one classifier, one L
    # the whole command's seconds hold every look's training, side by side at most on
    # every core (a comparison of two commands' wall times flaked under a busy suite)
    trained = sum(float(r["train_s"]) for r in rows)
    assert meta["seconds"] >= trained / max(1, os.cpu_count() or 1)
    again = json.loads(_invoke(tmp_path, monkeypatch, *args).output)["meta"]
    assert (again["computed"], again["skipped"]) == (0, len(rows))


def test_until_needs_a_primary_and_a_readable_budget(tmp_path, monkeypatch):
    out = str(tmp_path / "out")
    no_primary = _invoke(tmp_path, monkeypatch, "run", *TINY[:2], "--encoder", "raw",
                         "--classifier", "logreg", "--until", "answered", "--out", out)
    assert no_primary.exit_code == 2 and "primary" in no_primary.output
    bad = _invoke(tmp_path, monkeypatch, "run", *TINY, "--until", "answered",
                  "--primary", PRIMARY, "--budget", "soon", "--out", out)
    assert bad.exit_code == 2 and "duration" in bad.output
    few = _invoke(tmp_path, monkeypatch, "run", *TINY, "--until", "answered",
                  "--primary", PRIMARY, "--max-runs", "3", "--out", out)
    assert few.exit_code == 2 and "max-runs" in few.output
    huge = _invoke(tmp_path, monkeypatch, "run", *TINY, "--until", "answered",
                   "--primary", PRIMARY, "--max-runs", "1000000", "--out", out)
    assert huge.exit_code == 2 and "1000" in huge.output  # refused before any work


def test_a_budget_stops_between_looks_and_the_report_says_so(tmp_path, monkeypatch):
    out = tmp_path / "out"
    args = ["run", *TINY, "--out", str(out), "--primary", PRIMARY, "--until", "answered",
            "--max-runs", "7", "--look-every", "1", "--budget", "1s", "--json"]
    done = _invoke(tmp_path, monkeypatch, *args)
    assert done.exit_code == 0, done.output
    meta = json.loads(done.stdout)["meta"]  # the budget is echoed on stderr
    doc = json.loads((out / "results.json").read_text())
    looks = doc["looks"]
    assert looks["budget"] == "1s"
    if looks["answered"]:  # answered at the first look: the budget never had to act
        assert meta["budget_stop"] is None
    else:  # the first look took longer than 1 s, so no second batch began
        assert len(looks["looks"]) == 1 and "the budget of 1s" in meta["budget_stop"]
    assert meta["cpu_seconds"] > 0
    fits = [r["fit"] for r in doc["rows"]]
    assert looks["train_cpu_seconds"] == pytest.approx(
        sum(f["train_cpu_seconds"] for f in fits))
    assert "no batch begun past 1s" in (out / "report.md").read_text()


@pytest.mark.slow("adds runs look by look until answered, each run drawing and encoding its own people")
def test_until_answered_over_runs_that_each_draw_their_people(tmp_path, monkeypatch):
    """people=per-run, two workers: the looks test with ratio 0 (the plain paired t),
    the runs are the looks' seeds, each on a data set of its own, and the same command
    again computes nothing."""
    import math
    import statistics

    from tactbench.runner.analysis.comparisons import INDEPENDENT_METHOD

    out = tmp_path / "out"
    tiny = ["--dataset", "synthetic-forearm:users=2,repetitions=1,people=per-run",
            *TINY[2:]]
    args = ["run", *tiny, "--out", str(out), "--primary", PRIMARY, "--until", "answered",
            "--max-runs", "6", "--look-every", "1", "--workers", "2", "--json"]
    first = _invoke(tmp_path, monkeypatch, *args)
    assert first.exit_code == 0, first.output
    doc = json.loads((out / "results.json").read_text())
    looks = doc["looks"]["looks"]
    assert [lk["runs"] for lk in looks] == [5, 6][:len(looks)]
    runs = looks[-1]["runs"]
    hashes = {}
    for r in doc["rows"]:
        assert r["independent_runs"] is True and r["status"] == "ok"
        hashes.setdefault(r["seed"], set()).add(r["dataset_hash"])
    assert set(hashes) == set(range(runs))  # the looks' seeds, none past the last look
    assert all(len(h) == 1 for h in hashes.values())  # one data set per run ...
    assert len(set.union(*hashes.values())) == runs  # ... each its own
    [primary] = [c for c in doc["comparisons"] if c["family"] == "primary"]
    assert primary["run_ratio"] == 0 and primary["ratio"] == 0
    assert primary["method"].startswith(INDEPENDENT_METHOD)
    # the last look's standard error is the plain one, sqrt(var/J): ratio 0
    d = list(primary["per_run"].values())
    [seen] = looks[-1]["comparisons"].values()
    assert seen["se"] == pytest.approx(math.sqrt(statistics.variance(d) / runs))
    again = _invoke(tmp_path, monkeypatch, *args)
    assert again.exit_code == 0, again.output
    assert json.loads(again.output)["meta"]["computed"] == 0
    assert json.loads((out / "results.json").read_text())["looks"] == doc["looks"]
