"""``tactbench report DIR``: a run folder's report rendered again from its cells alone."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.runner.presentation.writers import RENDERED

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY_DATASET = "synthetic-forearm:users=2,repetitions=1"
FAST_CLF = "logreg:max_iter=20"
FILES = ("results.json", "results.csv", "report.md")


def _run(tmp_path, monkeypatch, *extra: str):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    out = tmp_path / "out"
    args = ["run", "--dataset", TINY_DATASET, "--encoder", "raw", "--encoder", "frame-diff",
            "--classifier", FAST_CLF, "-L", "3", "--seed", "0-2", "--pixel-mm", "10",
            "--threads", "1", "--out", str(out), *extra, str(scene)]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return out


def _without_rendered(name: str, data: bytes):
    """A report file with its one line (key) saying when and by what it was rendered
    taken out, and that line (key)."""
    if name == "results.json":
        doc = json.loads(data)
        return {k: v for k, v in doc.items() if k != "rendered"}, doc["rendered"]
    if name == "report.md":
        lines = data.decode().splitlines()
        (said,) = [x for x in lines if x.startswith(RENDERED)]
        return [x for x in lines if x != said], said
    return data, None


def test_deleted_reports_come_back_byte_for_byte_from_the_cells(tmp_path, monkeypatch):
    out = _run(tmp_path, monkeypatch, "--margin", "3")
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert {*FILES, "cost_vs_accuracy.png", "confusion_raw_logreg_L3.png"} <= set(before)
    for name in before:  # results.json, report.md and the figures: all gone (the
        if name not in ("results.csv", "run-record.json"):  # run's record is its own)
            (out / name).unlink()
    result = CliRunner().invoke(cli, ["report", str(out)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert "6 cell row(s) read, none computed" in result.output
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert set(after) == set(before)
    for name in before:  # byte for byte, but for the line saying when and by what
        old, was = _without_rendered(name, before[name])
        new, now = _without_rendered(name, after[name])
        assert old == new, name
        if name == "report.md":
            assert "at the end of the run" in was and "re-rendered from the stored rows " \
                "of cells/ (nothing trained)" in now
    report = after["report.md"].decode()
    assert "- statistics: margin 3 points; contrasts none" in report  # the run's options
    assert json.loads(after["results.json"])["statistics"]["per_user"] is True


def test_statistics_options_change_the_comparisons_and_the_report_says_so(
        tmp_path, monkeypatch):
    out = _run(tmp_path, monkeypatch, "--no-plots")
    cells = sorted((out / "cells").iterdir())
    stored = [p.read_bytes() for p in cells]
    result = CliRunner().invoke(cli, ["report", str(out), "--margin", "2", "--contrast",
                                      "encoder=raw..encoder=frame-diff", "--json",
                                      "--no-plots"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    printed = json.loads(result.stdout)
    doc = json.loads((out / "results.json").read_text())
    assert doc["statistics"]["margin"] == 2.0
    assert doc["statistics"]["contrasts"] == ["encoder=raw..encoder=frame-diff"]
    assert printed["comparisons"] == doc["comparisons"]
    assert [c["factor"] for c in doc["comparisons"]] == ["encoder", "contrast"]
    assert doc["comparisons"][0]["equivalence_p"] is not None  # the margin's test
    assert printed["meta"]["computed"] == 0 and printed["meta"]["rendered"]["how"] \
        .startswith("re-rendered")
    report = (out / "report.md").read_text()
    assert "- statistics: margin 2 points; contrasts `encoder=raw..encoder=frame-diff`" \
        in report
    assert [p.read_bytes() for p in sorted((out / "cells").iterdir())] == stored
    bad = CliRunner().invoke(cli, ["report", str(out), "--contrast", "encoder=dis..L=9"])
    assert bad.exit_code == 2 and "Traceback" not in bad.output


def test_a_folder_without_cells_is_one_line(tmp_path):
    missing = CliRunner().invoke(cli, ["report", str(tmp_path / "nope")])
    assert missing.exit_code == 2 and "does not exist" in missing.output
    assert missing.output.count("Error: ") == 1 and "Traceback" not in missing.output
    (tmp_path / "empty" / "cells").mkdir(parents=True)
    (tmp_path / "empty" / "results.json").write_text('{"rows": []}')  # not a source
    empty = CliRunner().invoke(cli, ["report", str(tmp_path / "empty")])
    assert empty.exit_code == 2 and "holds no cell rows" in empty.output
    (tmp_path / "empty" / "cells" / "0123456789abcdef.json").write_text("{")
    damaged = CliRunner().invoke(cli, ["report", str(tmp_path / "empty")])
    assert damaged.exit_code == 2 and "every cell row" in damaged.output
    assert "Traceback" not in damaged.output


def test_a_report_md_tactbench_did_not_write_is_not_replaced(tmp_path):
    from tactbench.runner import ResultStore

    from tactbench.runner.execution.planning import digest, row_identity

    row = {"status": "ok", "encoder": "raw", "dataset": "d", "split": "paper",
           "dataset_hash": "h", "classifier": "logreg", "L": 3, "seed": 0, "accuracy": 0.5,
           "classes": ["a", "b"], "confusion": [[1, 0], [1, 0]],
           "per_class_accuracy": {"a": 1.0, "b": 0.0}}
    ResultStore(tmp_path).put({**row, "key": digest(row_identity(row))})  # a real key
    (tmp_path / "report.md").write_text("# My notes\n")
    (tmp_path / "timing.json").write_text("{}")  # a benchmark's, beside the run's files
    result = CliRunner().invoke(cli, ["report", str(tmp_path), "--no-plots"])
    assert result.exit_code == 2 and "holds a report.md tactbench did not write" in \
        result.output
    assert (tmp_path / "report.md").read_text() == "# My notes\n"
    (tmp_path / "report.md").unlink()
    result = CliRunner().invoke(cli, ["report", str(tmp_path), "--no-plots"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "report.md").read_text().startswith("# tactbench report")
    assert (tmp_path / "timing.json").read_text() == "{}"
