"""Nothing silently wrong: a CSV's first frame is never taken for a header, a folder named
like a registered dataset never replaces it, degenerate data and options that train
nothing are refused, a bound the user gave is never replaced, a recording is listed once,
a scene file's paths are its own."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tactbench.datasets.folder import read_array_file, read_folder
from tactbench.datasets.loading import check_informative, is_path_spec, load_dataset
from tactbench.errors import InputError


def _folder(root: Path, values=None) -> Path:
    rng = np.random.default_rng(0)
    for cls in ("a", "b"):
        (root / cls).mkdir(parents=True)
        for i in range(2):
            arr = rng.random((5, 3, 3)) if values is None else np.full((5, 3, 3), values)
            np.save(root / cls / f"u{i}_r.npy", arr.astype(np.float32))
    return root


@pytest.mark.parametrize("first", ["1,,3", "1,-,3", "1,NA,3", "1,2,3,"])
def test_a_csv_first_row_with_a_missing_reading_is_refused_like_any_row(tmp_path, first):
    path = tmp_path / "r.csv"
    path.write_text(f"{first}\n4,5,6\n7,8,9\n")
    with pytest.raises(InputError, match=r"r.csv, line 1"):
        read_array_file(path)


def test_a_header_of_names_is_still_a_header_and_a_trailing_comma_on_every_line_is_ok(
        tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("t,1,2\n0,5,6\n1,8,9\n")  # numeric column names
    assert read_array_file(path)[0].shape == (2, 3)
    path.write_text("1,2,3,\n4,5,6,\n")
    assert read_array_file(path)[0].tolist() == [[1, 2, 3], [4, 5, 6]]


def test_a_name_is_a_name_and_a_path_says_it_is_one(tmp_path, monkeypatch):
    assert not is_path_spec("synthetic-forearm") and not is_path_spec("folder:path=a/b")
    for text in ("./synthetic-forearm", "data/x", "~/x", "a.csv", "/abs:x"):
        assert is_path_spec(text), text
    _folder(tmp_path / "synthetic-forearm")
    _folder(tmp_path / "mine")
    monkeypatch.chdir(tmp_path)
    simulated = load_dataset("synthetic-forearm:users=1,repetitions=1,positions=1")
    assert simulated.name == "synthetic-forearm" and len(simulated) > 4
    local = load_dataset("./synthetic-forearm")
    assert len(local) == 4  # the folder, when asked for as a path
    assert len(load_dataset("mine")) == 4  # a bare word naming no dataset: the folder


@pytest.mark.parametrize("value, message", [(np.nan, "every reading is missing"),
                                            (3.0, "every reading is 3")])
def test_an_all_nan_or_constant_dataset_is_refused(tmp_path, value, message):
    ds = read_folder(_folder(tmp_path / "d", values=value))
    with pytest.raises(InputError, match=message):
        check_informative(ds)
    check_informative(read_folder(_folder(tmp_path / "ok")))


def test_planning_refuses_a_constant_dataset_before_any_work(tmp_path):
    from tactbench.runner import Scene
    from tactbench.runner.execution.planning import plan

    scene = Scene(dataset=str(_folder(tmp_path / "d", values=0.0)), encoders=["raw"],
                  classifiers=["taxel-lstm:epochs=1"], L=[2], seeds=[0],
                  test_per_class=1, out=str(tmp_path / "out"))
    with pytest.raises(InputError, match="every reading is 0"):
        plan(scene)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("spec, message", [
    ("taxel-lstm:epochs=0", "epochs must be ≥ 1"),
    ("taxel-lstm:epochs=1e9", "epochs must be ≤ 100000"),
    ("small-cnn-lstm:epochs=nan", "epochs must be an integer"),
])
def test_training_options_that_train_nothing_or_forever_are_refused(spec, message):
    from tactbench.plugins import load_registry

    with pytest.raises(InputError, match=message):
        load_registry().build("classifier", spec)


def test_a_bound_the_user_gave_is_never_replaced(tmp_path):
    root = _folder(tmp_path / "d")
    with pytest.raises(InputError, match=r"vmax \(-1\) must be greater than the smallest"):
        read_folder(root, vmax=-1)
    with pytest.raises(InputError, match=r"vmin \(5\) must be less than the largest"):
        read_folder(root, vmin=5)
    assert read_folder(root, vmax=2).normalisation.spec == "fixed:offset=0,scale=2"


def test_a_recording_listed_twice_with_different_users_is_refused(tmp_path):
    root = _folder(tmp_path / "d")
    (root / "users.csv").write_text("recording,user\na/u0_r,P1\nb/u0_r,P1\na/u1_r,P2\n"
                                    "b/u1_r,P2\na/u0_r,P3\n")
    with pytest.raises(InputError, match=r"users.csv, line 6: recording 'a/u0_r' is listed "
                                         r"again \(first on line 2\) with another user"):
        read_folder(root)
    (root / "users.csv").write_text("recording,user\na/u0_r,P1\nb/u0_r,P1\na/u1_r,P2\n"
                                    "b/u1_r,P2\nu0_r.npy,P9\n")
    with pytest.raises(InputError, match="listed twice with different users"):
        read_folder(root)


def test_a_scene_files_paths_are_taken_from_its_folder_and_expand_the_home(tmp_path,
                                                                          monkeypatch):
    from tactbench.runner.execution.scene_files import load_scene_file

    (tmp_path / "study").mkdir()
    scene = tmp_path / "study" / "scene.toml"
    scene.write_text('dataset = "data/rec"\nout = "results"\n')
    monkeypatch.chdir(tmp_path)
    fields = load_scene_file(scene)
    assert fields["dataset"] == str(tmp_path / "study" / "data" / "rec")
    assert fields["out"] == str(tmp_path / "study" / "results")
    scene.write_text('dataset = "synthetic-forearm:users=2"\nout = "~/x"\n')
    fields = load_scene_file(scene)
    assert fields["dataset"] == "synthetic-forearm:users=2"
    assert fields["out"] == os.path.join(os.path.expanduser("~"), "x")


def test_a_class_with_one_recording_is_refused_by_its_name(tmp_path):
    """Degenerate input: a class with one recording can be trained on or tested on, never
    both, so a score over it is no finding. Refused at planning, naming the class."""
    root = _folder(tmp_path / "d")
    (root / "lonely").mkdir()
    np.save(root / "lonely" / "u0_r.npy", np.random.default_rng(1).random((5, 3, 3),
                                                                           dtype=np.float32))
    with pytest.raises(InputError, match="class 'lonely' has 1 recording; a benchmark "
                                         "needs ≥ 2 per class"):
        check_informative(read_folder(root))


def test_a_one_line_csv_ending_in_a_comma_is_refused_not_guessed(tmp_path):
    """'12,' alone: a trailing comma, or a missing second reading? (found by the fuzz
    suite: it was read as one column)."""
    path = tmp_path / "r.csv"
    path.write_text("12,\n")
    with pytest.raises(InputError, match=r"r.csv, line 1: its one row ends in ','"):
        read_array_file(path)
    path.write_text("12,\n13,\n")  # every line of several: a trailing comma
    assert read_array_file(path)[0].tolist() == [[12.0], [13.0]]


# ----------------------------------------------------------------------- round three


def test_an_npz_with_two_members_of_one_name_in_different_folders_is_refused(tmp_path):
    import zipfile

    path = tmp_path / "rec.npz"
    with zipfile.ZipFile(path, "w") as zf:
        for folder, value in (("a", 1.0), ("b", 2.0)):
            with zf.open(f"{folder}/values.npy", "w") as fh:
                np.lib.format.write_array(fh, np.full((3, 2, 2), value, np.float32))
    with pytest.raises(InputError, match="'a/values.npy' and 'b/values.npy' have one name"):
        read_array_file(path)


@pytest.mark.parametrize("name", ["a|b", "a*b*", "`x`", "[l](u)", "<b>", "a\\|b", "x~y~"])
def test_a_class_name_with_markdown_specials_is_escaped_by_the_markdown_writers(name):
    import re

    from tactbench.runner.presentation.tables import failed_cells_markdown, md, per_class_markdown

    summary = {"encoder": "raw", "classifier": "logreg", "L": 3,
               "classes": [name, "plain"], "per_class_accuracy": {name: 0.5, "plain": 1.0}}
    table = per_class_markdown([summary], {"logreg": "logreg"})
    header, rule, row = table.splitlines()
    cells = lambda line: re.split(r"(?<!\\)\|", line)[1:-1]  # noqa: E731 — GFM's split
    assert len(cells(header)) == len(cells(rule)) == len(cells(row)) == 5
    assert md(name) in header
    unescaped = re.sub(r"\\(.)", r"\1", md(name))
    assert unescaped == name  # every escape is a backslash before the character itself
    failed = failed_cells_markdown([{"key": "k", "encoder": "raw", "classifier": "x",
                                     "L": 3, "seed": 0, "status": "failed",
                                     "error": {"type": "E", "message": f"class {name}\nbad"}}])
    assert len(cells(failed.splitlines()[-1])) == 6
