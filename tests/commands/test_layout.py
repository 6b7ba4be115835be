"""``tactbench layout``: info (counts, extent, image shapes) and generate."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.data.imaging import Imager, image_shape
from tactbench.data.layout_io import load_layout


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_layout_generate_and_info(tmp_path):
    out = tmp_path / "forearm.csv"
    assert run("layout", "generate", "--out", out).exit_code == 0
    doc = json.loads(run("layout", "info", out, "--json").stdout)
    assert doc["taxels"] == 1558 and doc["modules"] == 142
    assert doc["image_shapes"] == {"1": [357, 334], "4": [90, 84], "5": [72, 67]}
    assert 7.0 < doc["median_spacing_mm"] <= 7.5
    text = run("layout", "info", out).output
    assert "1558 taxels" in text and "357 × 334" in text


def test_layout_info_of_real_files(shared_data):
    doc = json.loads(run("layout", "info", shared_data / "cyskin-layouts" /
                         "ur10e_link1_patch1_flatmap.json", "--json").stdout)
    assert doc["taxels"] == 642
    assert np.allclose(doc["extent_mm"], [153.3, 130.0], atol=0.5)


def test_layout_info_bad_file(tmp_path):
    bad = tmp_path / "l.csv"
    bad.write_text("id,x_mm\n")
    result = run("layout", "info", bad)
    assert result.exit_code != 0 and "l.csv, line 1: header must be" in result.output


@pytest.mark.parametrize("pixel_mm", [1.0, 4.0, 5.0, 7.3])
def test_layout_info_reports_the_shape_the_imager_produces(tmp_path, pixel_mm):
    path = tmp_path / "patch.csv"  # bounds that are no whole number of pixels
    path.write_text("# bounds_mm=-3.2,0,61.7,40.05\nid,x_mm,y_mm\n"
                    + "".join(f"{k},{(k % 8) * 7.5},{(k // 8) * 7.5}\n" for k in range(40)))
    doc = json.loads(run("layout", "info", path, "--pixel-mm", pixel_mm, "--json").stdout)
    shape = Imager(load_layout(path), pixel_mm=pixel_mm).apply(np.zeros(40)).shape
    assert doc["image_shapes"] == {f"{pixel_mm:g}": list(shape)}


def test_layout_info_never_reports_an_empty_image(tmp_path):
    path = tmp_path / "tiny.csv"
    path.write_text("id,x_mm,y_mm\n1,0,0\n2,7.5,0\n3,0,7.5\n")
    doc = json.loads(run("layout", "info", path, "--pixel-mm", 1e12, "--json").stdout)
    assert doc["image_shapes"] == {"1e+12": [1, 1]} == {"1e+12": list(image_shape(
        load_layout(path), 1e12))}


def test_layout_info_refuses_a_bad_pixel_size_in_one_line(tmp_path):
    path = tmp_path / "tiny.csv"
    path.write_text("id,x_mm,y_mm\n1,0,0\n2,7.5,0\n3,0,7.5\n")
    result = run("layout", "info", path, "--pixel-mm", 0)
    assert result.exit_code == 2 and "pixel_mm must be > 0" in result.output
    assert "Traceback" not in result.output
