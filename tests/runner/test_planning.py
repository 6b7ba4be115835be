"""Planning: the whole grid is checked before any work; what each classifier is fed."""

from __future__ import annotations

import pytest

from tactbench.errors import InputError, UnknownComponentError
from tactbench.runner import plan, run
from tactbench.runner.planning import input_kind


@pytest.mark.parametrize("over, error, match", [
    ({"encoders": ["farnback"]}, UnknownComponentError, "did you mean 'farneback'"),
    ({"classifiers": ["small-cnn"]}, UnknownComponentError, "unknown classifier"),
    ({"lengths": [0, 5]}, InputError, "L must be ≥ 1"),
    ({"encoders": ["raw:winsize=3"]}, InputError, "no option 'winsize'"),
    ({"split": "random"}, InputError, "unknown split"),
    ({"profile": "fast"}, InputError, "unknown profile 'fast'"),
    ({"executor": "slurm"}, InputError, "unknown executor"),
    ({"workers": 0}, InputError, "--workers must be ≥ 1"),
    ({"threads": 0}, InputError, "--threads must be ≥ 1"),
    ({"threads": -2}, InputError, "--threads must be ≥ 1"),
    ({"pixel_mm": 0.0}, InputError, "pixel size"),
])
def test_the_whole_grid_is_checked_before_any_work(tmp_path, cache, tiny_scene, over, error,
                                                   match):
    with pytest.raises(error, match=match):
        run(tiny_scene(**over), progress=False, cache=cache)
    assert not (tmp_path / "out").exists() and not any(cache.root.iterdir())


def test_input_kind_follows_the_frame_rank_and_the_layout():
    assert input_kind(3, has_layout=True) == "images"
    assert input_kind(1, has_layout=True) == "vectors"
    assert input_kind(None, has_layout=True) == "images"  # either: images where possible
    assert input_kind(None, has_layout=False) == "vectors"
    assert input_kind(1, has_layout=False) == "vectors"


def test_an_image_classifier_on_a_dataset_without_layout_is_refused(tiny_scene, cache,
                                                                   nolayout_dataset):
    scene = tiny_scene(dataset=str(nolayout_dataset), encoders=["raw"])
    with pytest.raises(InputError, match="works on tactile images.*has no taxel layout"):
        run(scene, progress=False, cache=cache)


def test_a_flow_encoder_without_layout_is_refused_for_an_either_classifier(
        tiny_scene, nolayout_dataset):
    scene = tiny_scene(dataset=str(nolayout_dataset), encoders=["frame-diff"],
                       classifiers=["logreg"])
    with pytest.raises(InputError, match="encoder 'frame-diff' works on tactile images.*"
                                         "'logreg.*can take taxel vectors with --encoder raw"):
        plan(scene)


def test_a_vector_classifier_refuses_an_image_encoder(tiny_scene):
    with pytest.raises(InputError, match="takes taxel vectors, which only the 'raw'"):
        plan(tiny_scene(encoders=["frame-diff"], classifiers=["taxel-lstm"]))


def test_logreg_takes_taxel_vectors_on_a_dataset_without_layout(tiny_scene, cache,
                                                               nolayout_dataset):
    # logreg declares frame_rank = None (either); it used to be refused here
    scene = tiny_scene(dataset=str(nolayout_dataset), encoders=["raw"],
                       classifiers=["logreg"], lengths=[3], seeds=[0], test_per_class=2)
    p = plan(scene)
    assert list(p.input_kind.values()) == ["vectors"]
    assert p.identities[p.cells[0].key]["imaging"] == {"kind": "vectors"}
    result = run(scene, progress=False, cache=cache)
    (row,) = result.rows
    assert row["status"] == "ok" and row["n_test"] == 4
    assert row["accuracy"] == 1.0  # one taxel per class: trivially separable


def test_logreg_still_takes_images_where_there_is_a_layout(tiny_scene):
    p = plan(tiny_scene(encoders=["raw"], classifiers=["logreg"]))
    assert list(p.input_kind.values()) == ["images"]


@pytest.mark.slow
def test_logreg_on_the_real_fingers_set_without_layout(shared_data, tmp_path, cache):
    from tactbench.runner import Scene

    scene = Scene(dataset=str(shared_data / "cyskin-fingers"), encoders=["raw"],
                  classifiers=["logreg"], lengths=[3], seeds=[0], threads=1,
                  out=str(tmp_path / "out"))
    p = plan(scene)
    assert p.dataset.layout is None and list(p.input_kind.values()) == ["vectors"]
    (row,) = run(scene, progress=False, cache=cache).rows
    assert row["status"] == "ok" and row["accuracy"] > 0.5  # 6 classes: chance is 1/6


@pytest.mark.parametrize("name, value", [("TACTBENCH_BANK_MIB", "abc"),
                                         ("TACTBENCH_LOADER_WORKERS", "-1")])
def test_bad_training_memory_settings_are_refused_before_any_work(tmp_path, cache, tiny_scene,
                                                                  monkeypatch, name, value):
    monkeypatch.setenv(name, value)
    with pytest.raises(InputError, match=name):
        run(tiny_scene(), progress=False, cache=cache)
    assert not (tmp_path / "out").exists() and not any(cache.root.iterdir())
