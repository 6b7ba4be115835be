"""The run configuration: window lengths, scene files, profile-derived settings."""

from __future__ import annotations

import pytest

from tactbench.errors import InputError, MissingFileError
from tactbench.runner import Scene, load_scene_file, parse_lengths


def test_parse_lengths():
    assert parse_lengths(["5"]) == [5]
    assert parse_lengths(["1-3", "6", "2"]) == [1, 2, 3, 6]
    for bad in ("x", "4-2", "1-"):
        with pytest.raises(InputError, match="bad window length"):
            parse_lengths([bad])


def test_scene_file_fields_and_typos(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('dataset = "x"\nencoder = "raw"\nL = ["1-3"]\nseeds = [4]\n')
    assert load_scene_file(path) == {"dataset": "x", "encoders": ["raw"], "lengths": [1, 2, 3],
                                     "seeds": [4]}
    path.write_text('encoderz = ["raw"]\n')
    with pytest.raises(InputError, match="unknown field 'encoderz'; did you mean 'encoders'"):
        load_scene_file(path)
    path.write_text('dataset = \n')
    with pytest.raises(InputError, match="not valid TOML"):
        load_scene_file(path)
    with pytest.raises(MissingFileError, match="scene file not found"):
        load_scene_file(tmp_path / "absent.toml")


def test_pixel_size_comes_from_the_profile_unless_given():
    assert Scene().resolved_pixel_mm() == 5.0
    assert Scene(profile="paper").resolved_pixel_mm() == 1.0
    assert Scene(profile="paper", pixel_mm=2.5).resolved_pixel_mm() == 2.5


def test_threads_share_the_cores_between_workers(monkeypatch):
    import os

    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    assert Scene(workers=2).resolved_threads() == 4
    assert Scene(workers=16).resolved_threads() == 1
    assert Scene(threads=3, workers=2).resolved_threads() == 3


def test_precision_comes_from_the_profile_unless_given(tmp_path):
    assert Scene().resolved_precision() == "float32"
    assert Scene(profile="paper").resolved_precision() == "uint8"
    assert Scene(profile="paper", precision="float16").resolved_precision() == "float16"
    path = tmp_path / "scene.toml"
    path.write_text('precision = "uint8"\n')
    assert Scene(**load_scene_file(path)).resolved_precision() == "uint8"


def test_an_unknown_precision_is_refused_before_any_work():
    from tactbench.runner import plan

    with pytest.raises(InputError, match="precision"):
        plan(Scene(dataset="no-such-dataset", precision="int4"))


def test_the_precision_is_in_the_cell_identity_except_float32():
    """float32 cells keep the identity (and key) they had before precisions existed."""
    from tactbench.runner import plan

    tiny = dict(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
                classifiers=["logreg"], lengths=[3], seeds=[0], test_per_class=1,
                pixel_mm=10.0)
    plans = {p: plan(Scene(**tiny, precision=p)) for p in ("float32", "float16", "uint8")}
    identities = {p: pl.identities[pl.cells[0].key] for p, pl in plans.items()}
    assert "precision" not in identities["float32"]
    for p in ("float16", "uint8"):
        assert identities[p] == {**identities["float32"], "precision": p}
    assert len({pl.cells[0].key for pl in plans.values()}) == 3
    assert plans["float32"].cells[0].key == plan(Scene(**tiny)).cells[0].key
