"""The run configuration: window lengths, scene files, profile-derived settings."""

from __future__ import annotations

import re

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
    assert load_scene_file(path) == {"dataset": "x", "encoders": ["raw"], "L": [1, 2, 3],
                                     "seeds": [4]}
    path.write_text('encoderz = ["raw"]\n')
    with pytest.raises(InputError, match="unknown field 'encoderz'; did you mean 'encoders'"):
        load_scene_file(path)
    path.write_text('dataset = \n')
    with pytest.raises(InputError, match="not valid TOML"):
        load_scene_file(path)
    with pytest.raises(MissingFileError, match="scene file not found"):
        load_scene_file(tmp_path / "absent.toml")


def test_the_window_length_is_L_and_the_old_field_name_is_refused_naming_it(tmp_path):
    """One spelling: -L, the scene's field L, cell identities' "L", model metadata's "L"."""
    assert Scene(L=[2, 3]).L == [2, 3]
    for name, body in [("scene.toml", 'lengths = [5]\n'), ("scene.json", '{"lengths": [5]}')]:
        path = tmp_path / name
        path.write_text(body)
        with pytest.raises(InputError, match=r"^.*scene\.(toml|json): field 'lengths' is "
                                             r"now 'L'$"):
            load_scene_file(path)


def test_pixel_size_comes_from_the_profile_unless_given():
    assert Scene().resolved_pixel_mm() == 5.0
    assert Scene(profile="paper").resolved_pixel_mm() == 1.0
    assert Scene(profile="paper", pixel_mm=2.5).resolved_pixel_mm() == 2.5


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
                classifiers=["logreg"], L=[3], seeds=[0], test_per_class=1,
                pixel_mm=10.0)
    plans = {p: plan(Scene(**tiny, precision=p)) for p in ("float32", "float16", "uint8")}
    identities = {p: pl.identities[pl.cells[0].key] for p, pl in plans.items()}
    assert "precision" not in identities["float32"]
    for p in ("float16", "uint8"):
        assert identities[p] == {**identities["float32"], "precision": p}
    assert len({pl.cells[0].key for pl in plans.values()}) == 3
    assert plans["float32"].cells[0].key == plan(Scene(**tiny)).cells[0].key


# ------------------------------------------------------------- hardening (issue 11)


@pytest.mark.parametrize("body, match", [
    ("seeds = [1.5]", r"field 'seeds' must be whole numbers or ranges .*, got 1\.5"),
    ("seeds = [true]", "field 'seeds' must be whole numbers or ranges .*, got True"),
    ("seed = 1.0", "field 'seeds' must be whole numbers"),
    ("encoders = [1]", "field 'encoders' entry 1 must be text, got int 1"),
    ("encoders = [\"raw\", [\"x\"]]", "field 'encoders' entry 2 must be text, got list"),
    ("classifiers = {name = \"logreg\"}", "field 'classifiers' must be a list, got dict"),
    ("encoders = []", "field 'encoders' is empty"),
    ("dataset = 3", "field 'dataset' must be text, got int 3"),
    ("dataset = \"\"", "field 'dataset' is empty"),
    ("out = [\"a\"]", "field 'out' must be text"),
    ("threads = 0", "field 'threads' must be ≥ 1, got 0"),
    ("threads = -3", "field 'threads' must be ≥ 1, got -3"),
    ("threads = \"4\"", "field 'threads' must be a whole number, got str"),
    ("workers = 100000000", "field 'workers' must be at most 1024"),
    ("test_per_class = 2.5", "field 'test_per_class' must be a whole number"),
    ("pixel_mm = \"5\"", "field 'pixel_mm' must be a number, got str"),
    ("pixel_mm = nan", "field 'pixel_mm' must be a finite number > 0, got nan"),
    ("pixel_mm = -inf", "field 'pixel_mm' must be a finite number > 0"),
    ("rerun = 1", "field 'rerun' must be true or false, got int 1"),
    ("save_models = \"yes\"", "field 'save_models' must be true or false"),
    ("L = [1.5]", "field 'L' must be whole numbers or ranges"),
    ("L = true", "field 'L' must be whole numbers or ranges"),
    ("L = \"1-3000000\"", "field 'L': too many window lengths: '1-3000000' is "
                          "3000000 of them; a run takes at most 1000"),
    ("seeds = [9223372036854775807, -9223372036854775808]", "is not a 64-bit integer"),
    ("seed = 1\nseeds = [2]", "field 'seeds' is given twice \\(as 'seed' and 'seeds'\\)"),
    ("[dataset]\nname = \"x\"", "field 'dataset' must be text, got dict"),
])
def test_every_scene_file_field_has_its_type_checked(tmp_path, body, match):
    path = tmp_path / "scene.toml"
    path.write_text(body + "\n")
    with pytest.raises(InputError, match=match) as info:
        load_scene_file(path)
    assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)


def test_a_json_scene_file_is_read_and_checked_like_toml(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text('{"dataset": "x", "encoder": "raw", "L": ["1-3"], "seeds": [4], '
                    '"pixel_mm": 2.5, "workers": null, "rerun": true}')
    assert load_scene_file(path) == {"dataset": "x", "encoders": ["raw"], "L": [1, 2, 3],
                                     "seeds": [4], "pixel_mm": 2.5, "workers": None,
                                     "rerun": True}
    for body, match in [('{"seeds": [1], "seeds": [2]}', "key 'seeds' is given twice"),
                        ('[1, 2]', "holds a table of fields, got list"),
                        ('{"seeds": [1.5]}', "field 'seeds' must be whole numbers"),
                        ('{"seeds": [' + "9" * 5000 + ']}', "not valid JSON"),
                        ("[" * 100_000, "not valid JSON"),
                        ('{"threads": 1e400}', "field 'threads' must be a whole number"),
                        ('{"encoders": [null]}', "entry 1 must be text, got NoneType")]:
        path.write_text(body)
        with pytest.raises(InputError, match=match):
            load_scene_file(path)


def test_a_scene_file_that_is_no_text_or_too_large_is_refused_before_it_is_read(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_bytes(b"\xff\xfe\x00junk")
    with pytest.raises(InputError, match="not a text file"):
        load_scene_file(path)
    path.write_text("# comment\n" * 200_000)
    with pytest.raises(InputError, match="scene files are a few lines"):
        load_scene_file(path)
    with pytest.raises(InputError, match="cannot read the scene file"):
        load_scene_file(tmp_path)  # a folder


def test_a_range_of_lengths_is_refused_before_it_is_expanded(memory_cap):
    with memory_cap(1):
        with pytest.raises(InputError, match="too many window lengths: '1-3000000000000'"):
            parse_lengths(["1-3000000000000"])
    assert parse_lengths(["1-1000"]) == list(range(1, 1001))
    with pytest.raises(InputError, match="too many window lengths"):
        parse_lengths(["1-1000", "2000"])
    for bad in (1.5, True, None, [3]):
        with pytest.raises(InputError, match="bad window length"):
            parse_lengths([bad])


def test_scene_fields_given_in_python_are_checked_when_the_scene_is_made():
    for over, match in [({"seeds": [1.5]}, "scene field 'seeds' must be whole numbers"),
                        ({"encoders": [1]}, "scene field 'encoders' entry 1 must be text"),
                        ({"L": [True]}, "scene field 'L' must be whole numbers"),
                        ({"rerun": "no"}, "scene field 'rerun' must be true or false"),
                        ({"seeds": [10 ** 5000]}, "an integer of 16610 bits is not a 64-bit"),
                        ({"workers": 10 ** 5000}, "'workers' must be at most 1024, got an "
                                                  "integer of")]:
        with pytest.raises(InputError, match=match):
            Scene(dataset="no-such-dataset", **over)


@pytest.mark.parametrize("parse, what", [(parse_lengths, "window length"),
                                         ("seeds", "seed")])
def test_window_lengths_and_seeds_are_read_by_one_rule(parse, what):
    """-L and --seed (and a scene file's L and seeds) share one "N or A-B" reader: the same
    ranges, bounds and messages; only the order differs (lengths sorted, seeds as given)."""
    from tactbench.runner.execution.scene import parse_numbers, parse_seeds

    parse = parse_seeds if parse == "seeds" else parse
    assert parse([7, " 2 - 4 ", "3", 2]) == (sorted if what != "seed" else list)([7, 2, 3, 4])
    assert parse(["-3--2"]) == [-3, -2]
    for bad, message in [("4-2", f"bad {what} range '4-2': the end is below the start"),
                         ("1-", f"bad {what} '1-': use a whole number or a range such as"),
                         ("x", f"bad {what} 'x'"), (1.5, f"bad {what} 1.5"),
                         (True, f"bad {what} True"), ("9" * 5000, f"bad {what} '999"),
                         ("99999999999999999999", f"{what} '99999999999999999999' is not a "
                                                  f"64-bit integer"),
                         (2 ** 63, f"{what} 9223372036854775808 is not a 64-bit integer"),
                         ("0-99999999999", f"too many {what}s: '0-99999999999' is "
                                           f"100000000000 of them; a run takes at most 1000")]:
        with pytest.raises(InputError, match=f"^{re.escape(message)}"):
            parse([bad])
    with pytest.raises(InputError, match=f"too many {what}s"):
        parse(["1-1000", "2000"])
    assert parse_numbers(["1-3", 2, "0"], what, "1-6") == [1, 2, 3, 0]


def test_seeds_take_ranges_in_files_and_on_the_command_line(tmp_path):
    from tactbench.runner.execution.scene import parse_seeds

    assert parse_seeds(["0-3"]) == [0, 1, 2, 3]
    assert parse_seeds([5, "0-2", 1]) == [5, 0, 1, 2]  # the order given, each once
    assert parse_seeds(["-3"]) == [-3]
    for bad, message in [("3-1", "the end is below the start"), ("x", "bad seed"),
                         ("0-99999999999", "too many seeds"), (1.5, "bad seed"),
                         ("9" * 5000, "bad seed"), ("99999999999999999999", "not a 64-bit")]:
        with pytest.raises(InputError, match=message):
            parse_seeds([bad])
    scene = tmp_path / "s.toml"
    scene.write_text('seeds = ["0-4"]\ntest_window = "onset"\nsplit = "users:folds=2"\n')
    fields = load_scene_file(scene)
    assert fields["seeds"] == [0, 1, 2, 3, 4] and fields["test_window"] == "onset"
    scene.write_text('seeds = [true]\n')
    with pytest.raises(InputError, match="field 'seeds' must be whole numbers or ranges"):
        load_scene_file(scene)


def test_a_scene_is_frozen_checked_once_when_made_and_trusted_by_planning(tmp_path,
                                                                        monkeypatch):
    import dataclasses

    from tactbench.runner import plan
    from tactbench.runner.execution import scene as scene_module

    scene = Scene(L=["1-2"], seeds=3, encoders="raw", out=str(tmp_path / "out"))
    assert (scene.L, scene.seeds, scene.encoders) == ([1, 2], [3], ["raw"])  # normalised
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.split = "users"  # type: ignore[misc]
    for over, match in [({"profile": "fast"}, "unknown profile 'fast'"),
                        ({"precision": "int4"}, "unknown precision 'int4'"),
                        ({"input": "pixels"}, "unknown --input 'pixels'"),
                        ({"executor": "slurm"}, "unknown executor 'slurm'"),
                        ({"scheduler": "nowhere"}, "not a dask scheduler address"),
                        ({"split": "users:folds=3,k"}, "bad option 'k'"),
                        ({"seeds": "0-99", "L": "1-99", "encoders": ["a", "b"]},
                         "the grid has 19800 cells"),
                        ({"L": [0]}, "scene field 'L' must be ≥ 1, got \\[0\\]")]:
        with pytest.raises(InputError, match=match):
            Scene(**over)
        with pytest.raises(InputError, match=match):  # replace() makes a Scene too
            dataclasses.replace(scene, **over)
    calls = []
    real = scene_module.check_fields
    monkeypatch.setattr(scene_module, "check_fields",
                        lambda values: calls.append(1) or real(values))
    made = Scene(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
                 classifiers=["logreg"], L=[3], seeds=[0], pixel_mm=10.0,
                 out=str(tmp_path / "out"))
    plan(made)
    assert len(calls) == 1  # when the scene was made; planning trusts it


def test_a_refused_field_is_named_as_its_source_names_it(tmp_path):
    with pytest.raises(InputError, match="^--threads must be ≥ 1, got 0$"):
        Scene.of({"threads": 0}, labels={"threads": "--threads"})
    with pytest.raises(InputError, match="^scene field 'workers' must be ≥ 1, got 0$"):
        Scene.of({"workers": 0}, labels={"threads": "--threads"})
    path = tmp_path / "scene.toml"
    path.write_text("workers = 0\n")
    with pytest.raises(InputError, match=f"^{re.escape(str(path))}: field 'workers' must be"):
        load_scene_file(path)


def test_the_run_defaults_are_written_once_in_the_scene():
    """One default for the split, one for the test window: the Scene's; the test window a
    row or identity leaves out is the study's ('first'), for keys made before windows."""
    import dataclasses

    from tactbench.data.windows import UNNAMED_TEST_WINDOW
    from tactbench.runner.execution.results import IDENTITY_DEFAULTS

    defaults = {f.name: f.default for f in dataclasses.fields(Scene)}
    assert (defaults["split"], defaults["test_window"]) == ("paper", "vote")
    assert IDENTITY_DEFAULTS["test_window"] == UNNAMED_TEST_WINDOW == "first"
