"""A run's results as pandas data frames and Parquet files (tactbench/runner/presentation/frames.py),
and ``tactbench report OUT --parquet``."""

from __future__ import annotations

import sys

import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.errors import MissingExtraError
from tactbench.runner import Scene, cells_frame, comparisons_frame, render_folder, run, \
    write_parquet
from tactbench.runner.presentation.frames import COMPARISON_KINDS, PARQUET_FILES

pd = pytest.importorskip("pandas", reason="the extra tactbench[export] (pandas) is not "
                                          "installed")
pa = pytest.importorskip("pyarrow", reason="the extra tactbench[export] (pyarrow) is not "
                                           "installed")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A finished run folder: 2 encoders × 3 seeds of a fast logreg (one comparison)."""
    out = tmp_path_factory.mktemp("frames") / "out"
    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1",
                  encoders=["raw", "frame-diff"], classifiers=["logreg:max_iter=20"],
                  L=[3], seeds=[0, 1, 2], pixel_mm=10, test_per_class=1, threads=1,
                  out=str(out))
    run(scene, progress=False, plots=False)
    return out


def test_one_row_per_cell_with_typed_columns(folder):
    report = render_folder(folder, write=False)
    cells = cells_frame(report)
    assert len(cells) == 6 and list(cells["key"]) == [r["key"] for r in report.rows]
    assert {"encoder", "classifier", "L", "seed", "split", "test_window", "accuracy",
            "train_s", "encode_ms_per_frame", "machine", "git", "finished"} <= set(cells)
    assert str(cells["encoder"].dtype) == "string" and str(cells["L"].dtype) == "Int64"
    assert str(cells["seed"].dtype) == "Int64" and cells["accuracy"].dtype == "float64"
    assert str(cells["finished"].dtype).startswith("datetime64") and \
        str(cells["finished"].dt.tz) == "UTC"
    row = report.rows[0]
    assert row["status"] == "ok", row.get("error")
    assert cells.loc[0, "accuracy"] == row["accuracy"]
    assert cells.loc[0, "git"] == row["run"]["git"]
    assert row["machine"]["cpu"] in cells.loc[0, "machine"]
    assert set(cells["test_window"]) == {"vote"}


def test_one_row_per_comparison_naming_the_cells_it_compared(folder):
    report = render_folder(folder, write=False)
    pairs = comparisons_frame(report)
    assert len(pairs) == len(report.comparisons) == 1
    assert list(pairs.columns) == list(COMPARISON_KINDS)
    c, line = report.comparisons[0], pairs.iloc[0]
    assert (line["a"], line["b"]) == (c.a, c.b) == ("raw", "frame-diff")
    assert line["difference"] == c.difference and (line["low"], line["high"]) == (c.low, c.high)
    assert line["p_holm"] == c.p_holm and line["verdict"] == c.verdict
    assert line["runs"] == 3 and line["family"] == "exploratory"
    by_key = {r["key"]: r for r in report.rows}
    assert {by_key[k]["encoder"] for k in line["cells_a"]} == {"raw"}
    assert {by_key[k]["encoder"] for k in line["cells_b"]} == {"frame-diff"}
    assert len(line["cells_a"]) == len(line["cells_b"]) == 3


def test_parquet_reads_back_with_pandas_and_with_pyarrow_alone(folder, tmp_path):
    import pyarrow.parquet as pq

    report = render_folder(folder, write=False)
    paths = write_parquet(report, tmp_path)
    assert {p.name for p in paths.values()} == set(PARQUET_FILES.values())
    pd.testing.assert_frame_equal(pd.read_parquet(paths["cells"]), cells_frame(report),
                                  check_dtype=False)
    assert str(pd.read_parquet(paths["cells"])["L"].dtype) == "Int64"
    cells = pq.read_table(paths["cells"])
    assert cells.schema.field("L").type == pa.int64()
    assert pa.types.is_string(cells.schema.field("encoder").type) or \
        pa.types.is_large_string(cells.schema.field("encoder").type)
    assert pa.types.is_timestamp(cells.schema.field("finished").type)
    pairs = pq.read_table(paths["comparisons"])
    assert pairs.num_rows == 1 and pa.types.is_list(pairs.schema.field("cells_a").type) or \
        pa.types.is_large_list(pairs.schema.field("cells_a").type)
    assert pairs.column("verdict").to_pylist() == [report.comparisons[0].verdict]


def test_nothing_is_written_when_a_table_cannot_be_made(folder, tmp_path, monkeypatch):
    from tactbench.runner.presentation import frames

    def broken(report):
        raise RuntimeError("no comparisons today")

    monkeypatch.setattr(frames, "comparisons_frame", broken)
    with pytest.raises(RuntimeError):
        write_parquet(render_folder(folder, write=False), tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_report_parquet_writes_both_tables_beside_the_report(folder):
    result = CliRunner().invoke(cli, ["report", str(folder), "--parquet", "--no-plots"])
    assert result.exit_code == 0, result.output
    assert "cells.parquet, comparisons.parquet" in result.output
    assert len(pd.read_parquet(folder / "cells.parquet")) == 6
    again = CliRunner().invoke(cli, ["report", str(folder), "--no-plots"])
    assert again.exit_code == 0, again.output  # the Parquet files are the run's own


def test_a_missing_extra_is_one_line_and_nothing_is_written(folder, monkeypatch):
    before = {p.name: p.stat().st_mtime_ns for p in folder.iterdir() if p.is_file()}
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # as if not installed
    result = CliRunner().invoke(cli, ["report", str(folder), "--parquet", "--no-plots"])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and 'pip install "tactbench[export]"' in lines[0]
    assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir() if p.is_file()} == before
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(MissingExtraError, match=r"pandas is not installed"):
        cells_frame(render_folder(folder, write=False))


def test_a_folder_that_is_not_a_run_is_one_line(tmp_path):
    (tmp_path / "notes.txt").write_text("not a run")
    result = CliRunner().invoke(cli, ["report", str(tmp_path), "--parquet"])
    assert result.exit_code == 2 and "holds no cell rows" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
