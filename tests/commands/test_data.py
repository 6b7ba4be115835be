"""``tactbench data``: info, synth, preview."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.data.dataset import Dataset


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def synth_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "ds"
    result = run("data", "synth", "--out", out, "--users", 1, "--repetitions", 1, "--seed", 3)
    assert result.exit_code == 0, result.output
    return out


def test_synth_writes_a_dataset(synth_folder):
    ds = Dataset.load(synth_folder)
    assert len(ds) == 10 and ds.classes[0] == "Grasp" and ds.layout is not None


def test_info_json_is_one_document(synth_folder):
    result = run("data", "info", synth_folder, "--json")
    assert result.exit_code == 0
    doc = json.loads(result.stdout)
    assert doc["samples"] == 10 and doc["taxels"] == 1558
    assert doc["samples_per_class"]["Twist"] == 2 and doc["samples_per_user"] == {"u00": 10}
    assert doc["layout"]["taxels"] == 1558
    assert doc["content_hash"] == Dataset.load(synth_folder).content_hash()
    fps = doc["frames_per_sample"]
    assert 5 <= fps["min"] <= fps["median"] <= fps["max"] <= 80  # simulator: 16–80 frames


def test_info_table(synth_folder):
    result = run("data", "info", synth_folder)
    assert result.exit_code == 0
    assert "samples per class" in result.output and "2hGrasp" in result.output


def test_info_of_a_cyskin_text_file_without_layout(tmp_path):
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "s.txt").write_text("1 2\n0 0 1 2\n1 0.1 3 nan\n")
    doc = json.loads(run("data", "info", tmp_path / "c" / "s.txt", "--json").stdout)
    assert doc["layout"] is None and doc["missing_readings"] == 1 and doc["classes"] == ["c"]


def test_info_of_a_registered_dataset():
    doc = json.loads(run("data", "info", "synthetic-forearm:users=1,repetitions=1,positions=1",
                         "--json").stdout)
    assert doc["samples"] == 5


def test_info_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2\n0 0 1\n")
    result = run("data", "info", bad)
    assert result.exit_code != 0
    assert "bad.txt, line 2: truncated or ragged row" in result.output
    assert "Traceback" not in result.output


def _png_shape(path):
    from matplotlib.image import imread

    return imread(path).shape


def test_preview_strip(synth_folder, tmp_path):
    out = tmp_path / "p.png"
    result = run("data", "preview", synth_folder, "--sample", 2, "--out", out,
                 "--max-frames", 4)
    assert result.exit_code == 0, result.output
    h, w, _ = _png_shape(out)
    assert w > 3 * h  # a strip of 4 frames


def test_preview_with_an_encoder(synth_folder, tmp_path):
    out = tmp_path / "e.png"
    result = run("data", "preview", synth_folder, "--out", out, "--encoder", "frame-diff",
                 "--pixel-mm", 6)
    assert result.exit_code == 0, result.output
    assert _png_shape(out)[2] in (3, 4)


def test_preview_without_layout_shows_taxel_values(tmp_path):
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "s.txt").write_text("1 2 3\n0 0 1 2 3\n1 0.1 3 4 5\n")
    out = tmp_path / "v.png"
    result = run("data", "preview", tmp_path / "c", "--out", out)
    assert result.exit_code == 0 and "no layout" in result.output
    assert _png_shape(out)[:2] == (16, 3)
    result = run("data", "preview", tmp_path / "c", "--out", out, "--encoder", "raw")
    assert result.exit_code != 0 and "has no taxel layout" in result.output


def test_preview_sample_out_of_range(synth_folder, tmp_path):
    result = run("data", "preview", synth_folder, "--sample", 99, "--out", tmp_path / "x.png")
    assert result.exit_code != 0 and "out of range" in result.output
