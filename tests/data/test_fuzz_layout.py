"""Fuzz: mutated layout files (CySkin calibration JSON with 3-D skin and a flat map, the
CSV tactbench writes) only ever raise tactbench's own error, stay under a memory cap,
and are never changed by the failed read."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.data.layout_io import load_layout, write_layout_csv
from tactbench.errors import TactbenchError
from tactbench.fuzzing import json_mutation as _json_mutation
from tactbench.fuzzing import json_values
from tactbench.integrity import hash_file

FUZZ = settings(max_examples=80, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
CAP_MIB = 200

JSON_VALUES = json_values([10 ** 400])


def json_mutation(doc):
    return _json_mutation(doc, values=JSON_VALUES, at_most=3)


def _calibration() -> dict:
    """A CySkin calibration document (metres) of a small forearm patch: 3-D skin with
    normals and a flat map, as the cyskin-layouts files have."""
    from tactbench.datasets.forearm import cyskin_forearm

    lay = cyskin_forearm(12, circumference_mm=60, length_mm=30)
    skin = [{"id": int(i), "x": (p / 1000).tolist(), "n": n.tolist(), "type": "pressure"}
            for i, p, n in zip(lay.ids, lay.positions_3d, lay.normals)]
    flat = [{"id": int(i), "x": (p / 1000).tolist()} for i, p in zip(lay.ids, lay.positions)]
    return {"info": {"file_version": "2"}, "skin": {"n_taxels": 12, "taxels": skin},
            "tactile_maps": {"name": "flat", "taxels": flat}}


@pytest.fixture(scope="module")
def originals(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzz-layout")
    doc = _calibration()
    (folder / "cal.json").write_text(json.dumps(doc, indent=1))
    skin_only = {"skin": doc["skin"]}
    (folder / "skin.json").write_text(json.dumps(skin_only))
    write_layout_csv(load_layout(folder / "cal.json"), folder / "lay.csv")
    return folder


def _check_read(path: Path, memory_cap) -> None:
    before = hash_file(path)
    with memory_cap(CAP_MIB):
        try:
            layout = load_layout(path)
        except TactbenchError as exc:
            assert "\n" not in str(exc) and str(exc).startswith(str(path)), str(exc)
        else:  # what loads is a usable layout
            assert np.all(np.isfinite(layout.positions)) and layout.n_taxels >= 1
            x0, y0, x1, y1 = layout.bounds
            assert x1 > x0 and y1 > y0
    assert hash_file(path) == before


@FUZZ
@given(data=st.data(), which=st.sampled_from(["cal.json", "skin.json"]))
def test_mutated_calibration_json(originals, memory_cap, data, which):
    doc = json.loads((originals / which).read_text())
    mutated = data.draw(json_mutation(doc))
    with tempfile.TemporaryDirectory() as root:
        path = Path(root) / which
        path.write_text(json.dumps(mutated))
        _check_read(path, memory_cap)


@FUZZ
@given(which=st.sampled_from(["cal.json", "skin.json", "lay.csv"]),
       flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                      max_size=6),
       inserts=st.lists(st.tuples(st.floats(0, 1), st.sampled_from(
           [b",", b"\n", b"9" * 25, b"1e999", b"nan", b"-", b"#", b"[", b"{", b'"', b"\xff"])),
           max_size=3),
       cut=st.one_of(st.none(), st.floats(0, 1, exclude_max=True)))
def test_layout_bytes_flipped_inserted_or_truncated(originals, memory_cap, which, flips,
                                                    inserts, cut):
    data = bytearray((originals / which).read_bytes())
    for where, mask in flips:
        data[int(where * len(data))] ^= mask
    for where, text in inserts:
        at = int(where * len(data))
        data[at:at] = text
    if cut is not None:
        data = data[:int(cut * len(data))]
    with tempfile.TemporaryDirectory() as root:
        path = Path(root) / which
        path.write_bytes(bytes(data))
        _check_read(path, memory_cap)


def test_the_fuzzed_files_themselves_load(originals):
    """The fuzz starts from valid files."""
    assert load_layout(originals / "cal.json").n_taxels == 12
    assert load_layout(originals / "skin.json").positions_3d is not None
    assert load_layout(originals / "lay.csv").n_taxels == 12
