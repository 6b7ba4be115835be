"""Layout files (CySkin JSON, CSV) and THE layout ↔ dict format."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tactbench.data.layout import TaxelLayout
from tactbench.data.layout_io import (
    layout_from_dict,
    layout_to_dict,
    load_layout,
    read_layout_csv,
    read_layout_json,
    write_layout_csv,
)
from tactbench.datasets.forearm import cyskin_forearm


def write_json(path, doc):
    path.write_text(json.dumps(doc))
    return path


def skin_taxels(points_m, normals=None):
    out = []
    for k, p in enumerate(points_m):
        tax = {"id": 100 + k, "x": list(map(float, p)), "type": "pressure", "cut": 0}
        if normals is not None:
            tax["n"] = list(map(float, normals[k]))
        out.append(tax)
    return out


# ------------------------------------------------------------------------ CSV


def test_csv_round_trip_is_exact(tmp_path):
    lay = cyskin_forearm(200, circumference_mm=150, length_mm=160)
    write_layout_csv(lay, tmp_path / "l.csv")
    back = read_layout_csv(tmp_path / "l.csv")
    assert np.array_equal(back.ids, lay.ids)
    assert np.array_equal(back.positions, lay.positions)
    assert back.bounds == lay.bounds


def test_csv_with_z(tmp_path):
    path = tmp_path / "z.csv"
    path.write_text("id,x_mm,y_mm,z_mm\n1,0,0,5\n2,7.5,0,5\n3,0,7.5,6\n")
    lay = load_layout(path)
    assert lay.positions_3d[:, 2].tolist() == [5, 5, 6]


@pytest.mark.parametrize("text, message", [
    ("", "empty layout file"),
    ("id,x,y\n1,0,0\n", "line 1: header must be"),
    ("id,x_mm,y_mm\n1,0,0\n2,1\n", "line 3: expected 3 columns"),
    ("id,x_mm,y_mm\n1,0,0\nA,1,1\n", "line 3: taxel id 'A' is not an integer"),
    ("id,x_mm,y_mm\n1,0,0\n2,one,1\n", "line 3: x_mm 'one' is not a number"),
    ("id,x_mm,y_mm\n1,0,0\n2,inf,1\n", "line 3: x_mm is inf"),
    ("id,x_mm,y_mm\n1,0,0\n1,1,1\n", "duplicate taxel ids 1"),
    ("id,x_mm,y_mm\n", "no taxels"),
    ("# bounds_mm=1,2\nid,x_mm,y_mm\n1,0,0\n", "line 1: bounds_mm must be four"),
])
def test_bad_csv(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        read_layout_csv(path)
    assert "bad.csv" in str(info.value) or "duplicate" in str(info.value)


def test_unknown_suffix_and_missing_file(tmp_path):
    with pytest.raises(ValueError, match="unknown layout format"):
        load_layout(tmp_path / "x.xml")
    with pytest.raises(FileNotFoundError):
        load_layout(tmp_path / "absent.csv")


# ----------------------------------------------------------------------- JSON


def test_json_2d_map_object_in_metres(tmp_path):
    doc = {"tactile_maps": {"taxels": [{"id": 5, "x": [0.0, 0.0]}, {"id": 6, "x": [0.0075, 0.0]},
                                       {"id": 7, "x": [0.0, 0.0075]}]}}
    lay = read_layout_json(write_json(tmp_path / "m.json", doc))
    assert lay.ids.tolist() == [5, 6, 7]
    assert lay.positions[1] == pytest.approx([7.5, 0.0])  # metres → mm
    assert lay.positions_3d is None


def test_json_map_list_and_skin_are_combined(tmp_path):
    pts = [[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]]
    normals = [[0, 0, 1]] * 3
    doc = {"skin": {"taxels": skin_taxels(pts, normals)},
           "tactile_maps": [{"taxels": [{"id": 102, "x": [0, 1]}, {"id": 100, "x": [0, 0]},
                                        {"id": 101, "x": [1, 0]}]}]}
    lay = read_layout_json(write_json(tmp_path / "h.json", doc))
    assert lay.ids.tolist() == [102, 100, 101]
    assert lay.positions_3d[0] == pytest.approx([0, 10, 0])  # matched by id
    assert lay.normals[0] == pytest.approx([0, 0, 1])
    with pytest.raises(ValueError, match="map_index 3 out of range"):
        read_layout_json(tmp_path / "h.json", map_index=3)


def test_json_3d_cylinder_is_unrolled_keeping_distances(tmp_path):
    radius, n_around, n_along = 0.05, 12, 4
    ang = np.linspace(-0.8, 0.8, n_around)
    pts, nrm = [], []
    for a in ang:
        for z in np.arange(n_along) * 0.0075:
            pts.append([radius * math.cos(a), radius * math.sin(a), z])
            nrm.append([math.cos(a), math.sin(a), 0])
    lay = read_layout_json(write_json(tmp_path / "c.json",
                                           {"skin": {"taxels": skin_taxels(pts, nrm)}}))
    arc = radius * 1000 * (ang[-1] - ang[0])
    w, h = lay.extent_mm()
    assert sorted([w, h]) == pytest.approx(sorted([arc, 7.5 * (n_along - 1)]), rel=1e-3)


@pytest.mark.parametrize("text, message", [
    ("{", "not valid JSON"),
    ('{"a": 1}', "not a CySkin calibration file"),
    ('{"tactile_maps": {"taxels": []}}', "is empty"),
    ('{"tactile_maps": []}', "empty list"),
    ('{"tactile_maps": {"taxels": [{"id": 1}]}}', r"taxels\[0\]: each taxel needs"),
    ('{"tactile_maps": {"taxels": [{"id": "a", "x": [0, 0]}]}}', "is not an integer"),
    ('{"tactile_maps": {"taxels": [{"id": 1, "x": [0]}]}}', "list of 2 finite numbers"),
    ('{"tactile_maps": {"taxels": [{"id": 1, "x": [0, 0]}, {"id": 1, "x": [1, 0]}]}}',
     "duplicate taxel ids"),
    ('{"skin": {"taxels": [{"id": 1, "x": [0, 0, 0]}]}, '
     '"tactile_maps": {"taxels": [{"id": 2, "x": [0, 0]}]}}', "missing from 'skin.taxels'"),
])
def test_bad_json(tmp_path, text, message):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        read_layout_json(path)
    assert "bad.json" in str(info.value)


# ------------------------------------------------------------------- real data


@pytest.mark.parametrize("name, n", [
    ("ur10e_link1_patch1.json", 642), ("ur10e_link1_patch1_flatmap.json", 642),
    ("ur10e_link2_patch1.json", 524), ("ur10e_link2_patch1_flatmap.json", 524),
    ("hexagon_cyskin_full_isomap.json", 61)])
def test_real_cyskin_layouts_load(shared_data, name, n):
    lay = load_layout(shared_data / "cyskin-layouts" / name)
    assert lay.n_taxels == n
    assert np.all(np.isfinite(lay.positions))
    if name.startswith("ur10e_link1_patch1_flat"):  # the README's numbers
        w, h = lay.extent_mm()
        assert (w, h) == pytest.approx((153, 130), abs=1.0)
        assert lay.median_spacing() == pytest.approx(4.3, abs=0.1)


def test_real_3d_unroll_keeps_the_taxel_spacing(shared_data):
    lay = load_layout(shared_data / "cyskin-layouts" / "ur10e_link1_patch1.json")
    from scipy.spatial import cKDTree

    d3, _ = cKDTree(lay.positions_3d).query(lay.positions_3d, k=2)
    assert lay.median_spacing() == pytest.approx(np.median(d3[:, 1]), rel=0.05)


def assert_same_layout(a, b):
    assert a.name == b.name and a.bounds == b.bounds
    assert a.ids.dtype == b.ids.dtype and np.array_equal(a.ids, b.ids)
    for key in ("positions", "positions_3d", "normals"):
        x, y = getattr(a, key), getattr(b, key)
        assert (x is None) == (y is None)
        if x is not None:
            assert x.dtype == y.dtype and np.array_equal(x, y)


def test_dict_round_trip_is_exact_through_json_with_3d_positions_and_normals():
    lay = cyskin_forearm(120, circumference_mm=120, length_mm=110)
    assert lay.positions_3d is not None and lay.normals is not None
    doc = layout_to_dict(lay)
    assert set(doc) == {"name", "ids", "positions", "bounds", "positions_3d", "normals"}
    back = layout_from_dict(json.loads(json.dumps(doc)), "model.json")
    assert_same_layout(back, lay)


def test_dict_round_trip_from_numpy_arrays_and_without_3d():
    lay = TaxelLayout(ids=[4, 5, 6], positions=[[0, 0], [1.25, 0], [0, 1 / 3]], name="tri")
    doc = {k: np.asarray(v) for k, v in layout_to_dict(lay).items() if k != "name"}
    assert set(doc) == {"ids", "positions", "bounds"}
    back = layout_from_dict({**doc, "name": "tri"}, "arrays.npz")
    assert_same_layout(back, lay)


def test_dict_without_bounds_gets_the_default_bounds():
    lay = layout_from_dict({"ids": [1, 2, 3], "positions": [[0, 0], [10, 0], [0, 10]]}, "x")
    assert lay.bounds == pytest.approx((-5, -5, 15, 15)) and lay.name == ""


@pytest.mark.parametrize("obj, message", [
    ([1, 2], "a layout must be a dict"),
    ({"ids": [1]}, "no 'positions'"),
    ({"ids": [1], "positions": [[0, 0]], "normal": [[0, 0, 1]]}, "unknown layout key.*'normal'"),
    ({"ids": ["a"], "positions": [[0, 0]]}, "'ids' must hold numbers"),
    ({"ids": [1, 2], "positions": [[0, 0], [1]]}, "'positions' is not a regular array"),
    ({"ids": [1], "positions": [[0, 0]], "bounds": [0, 1]}, "'bounds' must be 4 numbers"),
    ({"ids": [1, 2], "positions": [[0, 0]]}, r"positions must be \(N=2, D=2\)"),
    ({"ids": [1], "positions": [[0, 0]], "name": 3}, "'name' must be a string"),
])
def test_bad_dicts_name_where_they_came_from(obj, message):
    with pytest.raises(ValueError, match=message) as info:
        layout_from_dict(obj, "model.json: layout")
    assert str(info.value).startswith("model.json: layout: ")



# ------------------------------------------------------------- malformed files: one line

_MAP = '{"tactile_maps": {"taxels": [%s]}}'
_TWO = '{"id": 2, "x": [0.01, 0]}, {"id": 3, "x": [0, 0.01]}'


@pytest.mark.parametrize("text, message", [
    (_MAP % ('{"id": 100000000000000000000000, "x": [0, 0]}, ' + _TWO),
     r"tactile_maps.taxels\[0\]: id 100000000000000000000000 is outside the 64-bit"),
    (_MAP % ('{"id": 1, "x": [1e999, 0]}, ' + _TWO),
     r"tactile_maps.taxels\[0\]: 'x' must be a list of 2 finite numbers"),
    (_MAP % ('{"id": 1, "x": [' + "9" * 400 + ', 0]}, ' + _TWO),
     r"tactile_maps.taxels\[0\]: 'x' must be a list of 2 finite numbers"),
    (_MAP % ('{"id": 1, "x": [NaN, 0]}, ' + _TWO), "'x' must be a list of 2 finite numbers"),
    (_MAP % ('{"id": 1, "x": [null, 0]}, ' + _TWO), "'x' must be a list of 2 finite numbers"),
    ('{"skin": {"taxels": [{"id": 1, "x": [0, 0, 0], "n": ["a", 0, 1]}]}}',
     r"skin.taxels\[0\]: 'n' must be a list of 3 finite numbers, got \[\"a\", 0, 1\]"),
    ('{"skin": {"taxels": [{"id": 1, "x": [0, 0, 0], "n": [null, 0, 1]}]}}',
     r"skin.taxels\[0\]: 'n' must be a list of 3 finite numbers"),
    ('{"skin": {"taxels": [{"id": 1, "x": [0, 0, 0], "n": [1e999, 0, 1]}]}}',
     r"skin.taxels\[0\]: 'n' must be a list of 3 finite numbers"),
    ('{"skin": {"taxels": [{"id": 1, "x": [0, 0, 0], "n": [0, 1]}]}}',
     r"skin.taxels\[0\]: 'n' must be a list of 3 finite numbers"),
    ('{"skin": {"taxels": [{"id": 1, "x": [0, 0, 0]}, {"id": 2, "x": [0, 0.1, 0]}]}}',
     "'skin.taxels' has 2 taxel\\(s\\) and no 'tactile_maps'; flattening 3-D positions needs"),
    (_MAP % ", ".join('{"id": %d, "x": [0.01, 0.01]}' % i for i in range(4)),
     r"image bounds \(.*\), which are not a finite area"),
    (_MAP % '{"id": 1, "x": [1e307, 0]}, {"id": 2, "x": [-1e307, 0]}',
     "'tactile_maps' has non-finite taxel positions"),
    ('{"skin": [1], "tactile_maps": {"taxels": [{"id": 1, "x": [0, 0]}]}}',
     "'skin' has no 'taxels' list"),
    ('{"tactile_maps": [3]}', r"'tactile_maps\[0\]' has no 'taxels' list"),
    ("[" * 50_000 + "]" * 50_000, "not valid JSON: nested too deeply"),
])
def test_malformed_json_layouts_are_one_line_naming_file_and_field(tmp_path, text, message):
    from tactbench.errors import TactbenchError

    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(TactbenchError, match=message) as info:
        load_layout(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


@pytest.mark.parametrize("text, message", [
    ("id,x_mm,y_mm\n" + "9" * 23 + ",0,0\n2,1,1\n",
     "line 2: taxel id 99999999999999999999999 is outside the 64-bit integer range"),
    ("id,x_mm,y_mm\n1,1e308,0\n2,-1e308,0\n", "not a finite area"),
    ("id,x_mm,y_mm\n1,5,5\n2,5,5\n3,5,5\n", "not a finite area"),
])
def test_malformed_csv_layouts_are_one_line(tmp_path, text, message):
    from tactbench.errors import TactbenchError

    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(TactbenchError, match=message) as info:
        load_layout(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


def test_a_folder_or_a_byte_order_mark(tmp_path):
    from tactbench.errors import TactbenchError

    (tmp_path / "dir.json").mkdir()
    with pytest.raises(TactbenchError, match="a folder, not a layout file"):
        load_layout(tmp_path / "dir.json")
    path = tmp_path / "excel.csv"
    path.write_text("\ufeffid,x_mm,y_mm\n1,0,0\n2,7.5,0\n", encoding="utf-8")
    assert load_layout(path).ids.tolist() == [1, 2]


@pytest.mark.parametrize("ids", [[1e30, 2.0], [np.nan, 2.0], np.array([2**64 - 1, 1], np.uint64)])
def test_dict_ids_outside_int64_are_refused(ids):
    with pytest.raises(ValueError, match="'ids' hold .* outside the 64-bit integer range"):
        layout_from_dict({"ids": ids, "positions": [[0, 0], [1, 0]]}, "model.json: layout")
