"""TaxelLayout: ids and positions, CySkin JSON / CSV loaders, the generated forearm."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tactbench.data.layout import TaxelLayout, cyskin_forearm, load_layout, unroll


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


# ------------------------------------------------------------- the contract


def test_layout_normalises_types_and_default_bounds():
    lay = TaxelLayout(ids=[3, 1, 2], positions=[[0, 0], [10, 0], [0, 10]])
    assert lay.ids.dtype == np.int64 and lay.positions.dtype == np.float64
    assert lay.positions.shape == (3, 2) and len(lay) == 3
    spacing = lay.median_spacing()
    assert spacing == pytest.approx(10.0)
    assert lay.bounds == pytest.approx((-5, -5, 15, 15))  # box grown by half a spacing


@pytest.mark.parametrize("kwargs, message", [
    (dict(ids=[1, 1], positions=[[0, 0], [1, 1]]), "duplicate taxel ids 1"),
    (dict(ids=[1, 2], positions=[[0, 0]]), "positions must have shape"),
    (dict(ids=[1, 2], positions=[[0, 0], [np.nan, 1]]), "NaN or Inf"),
    (dict(ids=[], positions=np.zeros((0, 2))), "non-empty"),
    (dict(ids=[1, 2], positions=[[0, 0], [1, 1]], bounds=(0, 0, -1, 1)), "bounds"),
])
def test_bad_layouts_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TaxelLayout(**kwargs)


def test_indices_of_names_ids_missing_from_the_layout():
    lay = TaxelLayout(ids=[10, 11, 12], positions=[[0, 0], [1, 0], [0, 1]], name="patch")
    assert lay.indices_of([12, 10]).tolist() == [2, 0]
    with pytest.raises(ValueError, match=r"not in layout patch: 99"):
        lay.indices_of([10, 99])


# ---------------------------------------------------------------- the forearm


def test_forearm_matches_the_study():
    lay = cyskin_forearm()
    assert lay.n_taxels == 1558
    assert lay.bounds == (0.0, 0.0, 334.0, 357.0)  # 357 × 334 px at 1 mm
    modules, slots = np.divmod(lay.ids, 16)
    assert slots.max() <= 11  # 12 slots per module
    per_module = np.bincount(modules)[np.unique(modules)]
    assert per_module.max() <= 11 and per_module.min() >= 1  # up to 11 taxels
    # taxels of a module lie on a 7.5 mm lattice
    first = lay.positions[modules == modules[0]]
    d = np.linalg.norm(first[:, None] - first[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert d.min(axis=1) == pytest.approx(np.full(len(first), 7.5))
    assert 7.0 <= lay.median_spacing() <= 7.6
    assert np.all((lay.positions >= 0) & (lay.positions <= [334, 357]))


def test_forearm_is_a_cylinder_and_deterministic():
    lay = cyskin_forearm()
    radius = 334 / (2 * math.pi)
    r = np.hypot(lay.positions_3d[:, 0], lay.positions_3d[:, 1])
    assert r == pytest.approx(np.full(lay.n_taxels, radius))
    assert np.linalg.norm(lay.normals, axis=1) == pytest.approx(np.ones(lay.n_taxels))
    again = cyskin_forearm()
    assert np.array_equal(lay.ids, again.ids) and np.array_equal(lay.positions, again.positions)


def test_forearm_smaller_counts():
    lay = cyskin_forearm(100, circumference_mm=120, length_mm=100)
    assert lay.n_taxels == 100 and len(np.unique(lay.ids)) == 100
    with pytest.raises(ValueError, match="modules"):
        cyskin_forearm(5000, circumference_mm=120, length_mm=100)


# ------------------------------------------------------------------------ CSV


def test_csv_round_trip_is_exact(tmp_path):
    lay = cyskin_forearm(200, circumference_mm=150, length_mm=160)
    lay.to_csv(tmp_path / "l.csv")
    back = TaxelLayout.from_csv(tmp_path / "l.csv")
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
        TaxelLayout.from_csv(path)
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
    lay = TaxelLayout.from_json(write_json(tmp_path / "m.json", doc))
    assert lay.ids.tolist() == [5, 6, 7]
    assert lay.positions[1] == pytest.approx([7.5, 0.0])  # metres → mm
    assert lay.positions_3d is None


def test_json_map_list_and_skin_are_combined(tmp_path):
    pts = [[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]]
    normals = [[0, 0, 1]] * 3
    doc = {"skin": {"taxels": skin_taxels(pts, normals)},
           "tactile_maps": [{"taxels": [{"id": 102, "x": [0, 1]}, {"id": 100, "x": [0, 0]},
                                        {"id": 101, "x": [1, 0]}]}]}
    lay = TaxelLayout.from_json(write_json(tmp_path / "h.json", doc))
    assert lay.ids.tolist() == [102, 100, 101]
    assert lay.positions_3d[0] == pytest.approx([0, 10, 0])  # matched by id
    assert lay.normals[0] == pytest.approx([0, 0, 1])
    with pytest.raises(ValueError, match="map_index 3 out of range"):
        TaxelLayout.from_json(tmp_path / "h.json", map_index=3)


def test_json_3d_cylinder_is_unrolled_keeping_distances(tmp_path):
    radius, n_around, n_along = 0.05, 12, 4
    ang = np.linspace(-0.8, 0.8, n_around)
    pts, nrm = [], []
    for a in ang:
        for z in np.arange(n_along) * 0.0075:
            pts.append([radius * math.cos(a), radius * math.sin(a), z])
            nrm.append([math.cos(a), math.sin(a), 0])
    lay = TaxelLayout.from_json(write_json(tmp_path / "c.json",
                                           {"skin": {"taxels": skin_taxels(pts, nrm)}}))
    arc = radius * 1000 * (ang[-1] - ang[0])
    w, h = lay.extent_mm()
    assert sorted([w, h]) == pytest.approx(sorted([arc, 7.5 * (n_along - 1)]), rel=1e-3)


def test_unroll_flat_patch_keeps_distances():
    rng = np.random.default_rng(0)
    flat = rng.uniform(0, 50, (30, 2))
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    pts = np.column_stack([flat, np.zeros(30)]) @ rot.T
    out = unroll(pts, None)
    d_in = np.linalg.norm(flat[:, None] - flat[None], axis=2)
    d_out = np.linalg.norm(out[:, None] - out[None], axis=2)
    assert d_out == pytest.approx(d_in, abs=1e-9)


@pytest.mark.parametrize("text, message", [
    ("{", "not valid JSON"),
    ('{"a": 1}', "not a CySkin calibration file"),
    ('{"tactile_maps": {"taxels": []}}', "is empty"),
    ('{"tactile_maps": []}', "empty list"),
    ('{"tactile_maps": {"taxels": [{"id": 1}]}}', r"taxels\[0\]: each taxel needs"),
    ('{"tactile_maps": {"taxels": [{"id": "a", "x": [0, 0]}]}}', "is not an integer"),
    ('{"tactile_maps": {"taxels": [{"id": 1, "x": [0]}]}}', "list of 2 numbers"),
    ('{"tactile_maps": {"taxels": [{"id": 1, "x": [0, 0]}, {"id": 1, "x": [1, 0]}]}}',
     "duplicate taxel ids"),
    ('{"skin": {"taxels": [{"id": 1, "x": [0, 0, 0]}]}, '
     '"tactile_maps": {"taxels": [{"id": 2, "x": [0, 0]}]}}', "missing from 'skin.taxels'"),
])
def test_bad_json(tmp_path, text, message):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        TaxelLayout.from_json(path)
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
