"""Planning: the whole grid is checked before any work; what each classifier is fed."""

from __future__ import annotations

import pytest

from tactbench.errors import InputError, UnknownComponentError
from tactbench.runner import plan, run
from tactbench.runner.execution.planning import input_kind


@pytest.mark.parametrize("over, error, match", [
    ({"encoders": ["farnback"]}, UnknownComponentError, "did you mean 'farneback'"),
    ({"classifiers": ["small-cnn"]}, UnknownComponentError, "unknown classifier"),
    ({"L": [0, 5]}, InputError, "'L' must be ≥ 1, got \\[0\\]"),
    ({"encoders": ["raw:winsize=3"]}, InputError, "no option 'winsize'"),
    ({"split": "random"}, UnknownComponentError, "unknown split 'random'"),
    ({"split": "users:k=3"}, InputError, "split 'users' has no option 'k'"),
    ({"test_window": "votes"}, UnknownComponentError,
     "unknown test-window 'votes'; did you mean 'vote'"),
    ({"profile": "fast"}, InputError, "unknown profile 'fast'"),
    ({"executor": "slurm"}, InputError, "unknown executor"),
    ({"workers": 0}, InputError, "'workers' must be ≥ 1"),
    ({"threads": 0}, InputError, "'threads' must be ≥ 1"),
    ({"threads": -2}, InputError, "'threads' must be ≥ 1"),
    ({"pixel_mm": 0.0}, InputError, "'pixel_mm' must be a finite number > 0"),
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
    scene = tiny_scene(dataset=str(nolayout_dataset), encoders=["farneback"],
                       classifiers=["logreg"])
    with pytest.raises(InputError, match="encoder 'farneback' works on tactile images.*"
                                         "'logreg.*can take taxel vectors with --encoder raw"):
        plan(scene)


def test_a_vector_classifier_refuses_an_image_encoder(tiny_scene):
    with pytest.raises(InputError, match="encoder 'farneback' only encodes images; use an "
                                         "encoder of taxel vectors"):
        plan(tiny_scene(encoders=["farneback"], classifiers=["taxel-lstm"]))


def test_frame_diff_encodes_taxel_vectors_for_a_vector_classifier(tiny_scene, cache,
                                                                 nolayout_dataset):
    import numpy as np

    from tactbench.runner import run
    from tactbench.runner.execution.entries import load_encoding

    scene = tiny_scene(dataset=str(nolayout_dataset), encoders=["raw", "frame-diff"],
                       classifiers=["logreg"], L=[3], seeds=[0], test_per_class=2)
    result = run(scene, progress=False, cache=cache)
    assert [r["status"] for r in result.rows] == ["ok", "ok"]
    entries = {e["encoder"]: e for e in cache.entries() if e.get("encoder")}
    raw, _ = load_encoding(cache.path(entries["raw"]["key"]))
    diff, meta = load_encoding(cache.path(entries["frame-diff"]["key"]))
    n = raw[0].shape[1]
    assert diff[0].shape == (raw[0].shape[0], 2 * n)
    first, second = np.asarray(raw[0][:]), np.asarray(diff[0][:])
    np.testing.assert_allclose(second[:, :n], first)  # the pressures, then their change
    np.testing.assert_allclose(second[1:, n:], first[1:] - first[:-1], atol=1e-6)
    np.testing.assert_allclose(second[0, n:], first[0])


def test_logreg_takes_taxel_vectors_on_a_dataset_without_layout(tiny_scene, cache,
                                                               nolayout_dataset):
    # logreg declares frame_rank = None (either); it used to be refused here
    scene = tiny_scene(dataset=str(nolayout_dataset), encoders=["raw"],
                       classifiers=["logreg"], L=[3], seeds=[0], test_per_class=2)
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


@pytest.mark.slow("loads and trains on the real cyskin-fingers recordings (shared data)")
def test_logreg_on_the_real_fingers_set_without_layout(shared_data, tmp_path, cache):
    from tactbench.runner import Scene

    scene = Scene(dataset=str(shared_data / "cyskin-fingers"), encoders=["raw"],
                  classifiers=["logreg"], L=[3], seeds=[0], threads=1,
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


# ------------------------------------------------------------- hardening (issue 11)


def _nothing_done(tmp_path, cache, out=None):
    out = out or tmp_path / "out"
    assert not any(cache.root.iterdir())
    assert not (out / "cells").exists()


def test_an_out_folder_that_is_a_file_is_refused_before_any_work(tmp_path, cache, tiny_scene):
    out = tmp_path / "out"
    out.write_text("mine")
    with pytest.raises(InputError, match=f"out folder {out} is a file, not a folder"):
        run(tiny_scene(), progress=False, cache=cache)
    assert out.read_text() == "mine" and not any(cache.root.iterdir())


def test_an_out_folder_under_a_file_is_refused_before_any_work(tmp_path, cache, tiny_scene):
    (tmp_path / "file").write_text("mine")
    out = tmp_path / "file" / "sub" / "out"
    with pytest.raises(InputError, match=f"out folder {out} cannot be made: "
                                         f"{tmp_path / 'file'} is a file"):
        run(tiny_scene(out=str(out)), progress=False, cache=cache)
    assert not any(cache.root.iterdir())


def test_an_out_folder_that_cannot_be_written_is_refused_before_any_work(
        tmp_path, cache, tiny_scene, monkeypatch):
    """Permissions alone do not tell (root writes anywhere): the probe file does. Here the
    probe's creation fails as on a read-only mount, and the real check reports it."""
    import errno
    import tempfile

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(InputError, match=f"out folder {out} cannot be written: Read-only"):
        run(tiny_scene(), progress=False, cache=cache)
    _nothing_done(tmp_path, cache)


def test_the_writability_probe_leaves_nothing_behind(tmp_path):
    from tactbench.paths import check_output_folder
    from tactbench.runner.execution.results import is_run_output

    check_output_folder(tmp_path / "new" / "out", option="out folder", ours=is_run_output)
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "out").mkdir()
    check_output_folder(tmp_path / "out", option="out folder", ours=is_run_output)
    assert list((tmp_path / "out").iterdir()) == []


@pytest.mark.parametrize("names", [["notes.txt"], ["results.csv", "thesis.tex"],
                                   ["cells", "data"]])
def test_an_out_folder_holding_files_tactbench_did_not_write_is_not_overwritten(
        tmp_path, cache, tiny_scene, names):
    out = tmp_path / "out"
    out.mkdir()
    for name in names:
        (out / name).mkdir() if name in ("cells", "data") else (out / name).write_text("x")
    foreign = [n for n in names if n not in ("cells", "results.csv")][0]
    with pytest.raises(InputError, match=f"out folder {out} holds files tactbench did not "
                                         f"write \\('{foreign}'\\); give a new or empty"):
        run(tiny_scene(), progress=False, cache=cache)
    assert sorted(p.name for p in out.iterdir()) == sorted(names)
    assert not any(cache.root.iterdir())


def test_a_report_md_tactbench_did_not_write_is_not_overwritten(tmp_path, tiny_scene):
    from tactbench.paths import check_output_folder
    from tactbench.runner.execution.results import is_run_output

    out = tmp_path / "out"
    out.mkdir()
    (out / "report.md").write_text("# My thesis notes\n")
    with pytest.raises(InputError, match="holds files tactbench did not write \\('report.md'"):
        check_output_folder(out, option="out folder", ours=is_run_output)
    (out / "report.md").write_text("# tactbench report\n\n- dataset: x\n")
    check_output_folder(out, option="out folder", ours=is_run_output)  # an earlier run's


def test_an_out_folder_an_earlier_run_wrote_is_accepted(tmp_path, cache, tiny_scene):
    from tactbench.paths import check_output_folder
    from tactbench.runner.execution.results import is_run_output

    scene = tiny_scene(encoders=["raw"], classifiers=["logreg:max_iter=20"], seeds=[0])
    run(scene, progress=False, cache=cache)
    from tactbench.runner.orchestrate import write_reports

    out = tmp_path / "out"
    write_reports(out, [], plots=False)
    (out / "confusion_raw_logreg_L3.png").write_bytes(b"")
    (out / ".results.json.tmp-123-abcdef01-xyz").write_text("")  # an interrupted write
    (out / ".DS_Store").write_bytes(b"")  # a file manager's
    check_output_folder(out, option="out folder", ours=is_run_output)
    assert run(scene, progress=False, cache=cache).skipped == 1


def test_a_window_longer_than_every_sequence_is_refused_naming_the_longest(tiny_scene):
    p = plan(tiny_scene(encoders=["raw"]))
    lengths = p.dataset.lengths()
    longest, where = int(lengths.max()), int(lengths.argmax())
    with pytest.raises(InputError, match=f"window length L = {longest + 1}, 1000 is longer "
                                         f"than every sequence of dataset .*the longest "
                                         f"\\(sample {where}\\) has {longest} frames; "
                                         f"use L ≤ {longest}"):
        plan(tiny_scene(encoders=["raw"], L=[3, longest + 1, 1000]))
    assert plan(tiny_scene(encoders=["raw"], L=[longest])).cells  # the longest is fine


def test_a_tiny_pixel_size_is_refused_before_the_imaging_allocates(tiny_scene, tmp_path,
                                                                 cache, memory_cap,
                                                                 monkeypatch):
    from tactbench.errors import BudgetError

    plan(tiny_scene())  # the dataset made once, outside the cap
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "8192")
    with memory_cap(64):
        with pytest.raises(BudgetError, match=r"the imaging operator for tactile images at "
                                              r"0\.01 mm \(35700×33400 px\) would need about "
                                              r"[0-9.]+ GiB, more than the memory budget of "
                                              r"8\.0 GiB; set TACTBENCH_MEMORY_MIB"):
            plan(tiny_scene(pixel_mm=0.01))  # (the old plan passed; its run was OOM-killed)
    _nothing_done(tmp_path, cache)


def test_the_memory_budget_refuses_a_chunk_or_a_batch_that_would_not_fit(tiny_scene,
                                                                        monkeypatch):
    from tactbench.errors import BudgetError

    plan(tiny_scene())
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "40")
    # 1 mm: the operator fits (~32 MiB), a chunk of images and their encodings does not
    with pytest.raises(BudgetError, match="imaging and encoding tactile images at 1 mm "
                                          r"\(357×334 px\), chunks of"):
        plan(tiny_scene(pixel_mm=1.0))
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "16")  # the tiny dataset itself fits
    clf = "taxel-lstm:batch_size=100000"  # taxel vectors: no imaging
    with pytest.raises(BudgetError, match=r"a batch of 100000 windows of L=3 frames \(\d+,\) "
                                          r"\(raw × taxel-lstm\) would need about"):
        plan(tiny_scene(encoders=["raw"], classifiers=[clf]))
    plan(tiny_scene(encoders=["raw"], classifiers=["taxel-lstm:batch_size=8"]))


def test_a_grid_too_large_to_run_is_refused_before_it_is_expanded(tiny_scene, memory_cap):
    with memory_cap(5):
        with pytest.raises(InputError, match="the grid has 40000 cells .*at most 10000"):
            plan(tiny_scene(dataset="no-such-dataset", seeds=list(range(1000)),
                            L=list(range(1, 21))))


def test_a_seed_listed_twice_is_one_cell(tiny_scene):
    p = plan(tiny_scene(encoders=["raw"], seeds=[0, 1, 0]))
    assert [c.seed for c in p.cells] == [0, 1]


@pytest.mark.parametrize("device, match", [("gpu", "unknown device 'gpu'"),
                                           ("cuda:99", "cuda:99")])
def test_a_device_this_machine_lacks_is_refused_before_any_work(tmp_path, cache, tiny_scene,
                                                                device, match):
    with pytest.raises(InputError, match=match):
        run(tiny_scene(device=device), progress=False, cache=cache)
    _nothing_done(tmp_path, cache)


# ------------------------------------------------ statistics options: inputs, seeds, contrasts


def test_input_kind_is_in_the_identity_only_when_asked_for_and_the_classifier_takes_either(
        tiny_scene):
    plain = plan(tiny_scene(encoders=["raw"], classifiers=["logreg", "taxel-lstm"]))
    asked = plan(tiny_scene(encoders=["raw"], classifiers=["logreg", "taxel-lstm"],
                            input="vectors"))
    logreg = [k for k in plain.input_kind if k.startswith("logreg")][0]
    assert plain.input_kind[logreg] == "images" and asked.input_kind[logreg] == "vectors"
    by_clf = lambda p: {(c.classifier.split(":")[0], c.seed): c.key for c in p.cells}  # noqa: E731
    a, b = by_clf(plain), by_clf(asked)
    assert all(a["taxel-lstm", s] == b["taxel-lstm", s] for s in (0, 1))  # unchanged
    assert all(a["logreg", s] != b["logreg", s] for s in (0, 1))
    assert all("input" not in i for i in plain.identities.values())
    assert {i.get("input") for i in asked.identities.values()} == {None, "vectors"}


def test_images_asked_of_a_dataset_without_layout_is_one_clear_error(tiny_scene,
                                                                     nolayout_dataset):
    scene = tiny_scene(dataset=str(nolayout_dataset), encoders=["raw"],
                       classifiers=["logreg"], input="images")
    with pytest.raises(InputError, match="--input images: dataset 'nolayout' has no taxel "
                                         "layout"):
        plan(scene)
    with pytest.raises(InputError, match="unknown --input 'pixels'|--input"):
        plan(tiny_scene(input="pixels"))


def test_init_seeds_multiply_the_cells_and_keep_other_keys(tiny_scene):
    plain = plan(tiny_scene())
    varied = plan(tiny_scene(init_seeds=[0, 1, 2]))
    assert len(varied.cells) == 3 * len(plain.cells)
    assert {c.init_seed for c in varied.cells} == {0, 1, 2}
    assert {c.init_seed for c in plain.cells} == {None}
    assert not {c.key for c in plain.cells} & {c.key for c in varied.cells}
    assert all("init_seed" not in i for i in plain.identities.values())


def test_margin_and_contrasts_are_checked_before_any_work(tiny_scene):
    with pytest.raises(InputError, match="'margin' must be a finite number > 0, got -1.0"):
        plan(tiny_scene(margin=-1.0))
    with pytest.raises(InputError, match="'..'"):
        plan(tiny_scene(contrasts=["raw"]))
    with pytest.raises(InputError, match="names no two cells"):
        plan(tiny_scene(contrasts=["encoder=raw,L=3..encoder=frame-diff,L=9"]))
    p = plan(tiny_scene(contrasts=["encoder=raw..encoder=frame-diff"], margin=2.0))
    assert len(p.cells) == 4
