"""One cell: built from the planned component; a raising cell is a failed row."""

from __future__ import annotations

import pickle
from pathlib import Path

import pytest

from tactbench.runner import ensure_encodings, make_jobs, plan, run_cell
from tactbench.runner.execution.cell import TRACEBACK_FRAMES

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture
def jobs(tiny_scene, cache, fake_registry):
    """``jobs(classifier)``: the jobs of a one-cell grid of ``classifier`` (raw, L=3)."""

    def make(classifier: str):
        p = plan(tiny_scene(encoders=["raw"], classifiers=[classifier], seeds=[0]),
                 fake_registry)
        return make_jobs(p, p.cells, ensure_encodings(p, cache, p.cells))

    return make


def test_a_job_carries_the_planned_component_and_pickles(jobs):
    (job,) = jobs("added-logreg")
    assert job.classifier.target == "fake_components:AddedLogReg"
    assert pickle.loads(pickle.dumps(job)) == job


def test_a_cell_builds_its_classifier_from_the_job_not_the_installed_plugins(jobs):
    # "added-logreg" exists only in the plan's registry; load_registry() does not know it
    from tactbench.plugins import load_registry

    assert "added-logreg" not in load_registry().names("classifier")
    (job,) = jobs("added-logreg")
    row = run_cell(job)
    assert row["status"] == "ok" and row["classifier"].startswith("added-logreg")
    assert 0.0 <= row["accuracy"] <= 1.0 and row["fit"]["classifier"] == "added-logreg"


def test_a_cell_that_raises_returns_a_failed_row(jobs, monkeypatch):
    monkeypatch.setenv("TACTBENCH_TEST_FAIL", "1")
    (job,) = jobs("failing")
    row = run_cell(job)
    assert row["status"] == "failed" and row["key"] == job.cell.key
    assert row["error"]["type"] == "RuntimeError"
    assert row["error"]["message"] == "deliberate failure in fit"
    trace = row["error"]["traceback"]
    assert "fake_components.py" in trace and "deliberate failure in fit" in trace
    assert trace.count('  File "') <= TRACEBACK_FRAMES
    assert row["classifier"] == job.identity["classifier"] and "accuracy" not in row


def test_ctrl_c_in_a_cell_is_not_a_failure(jobs):
    (job,) = jobs("interrupted")
    with pytest.raises(KeyboardInterrupt):
        run_cell(job)


def test_a_row_says_which_step_set_the_peak_memory(jobs):
    (job,) = jobs("added-logreg")
    row = run_cell(job)
    steps = list(row["memory"])
    assert steps == ["before this cell", "load encoding", "windows", "fit", "predict"]
    assert row["peak_step"] in steps
    peaks = [row["memory"][s]["peak_mb"] for s in steps]
    assert peaks == sorted(peaks)  # a peak only grows
    assert row["peak_rss_mb"] == max(peaks) > 0
    first = next(s for s in steps if row["memory"][s]["peak_mb"] == max(peaks))
    assert row["peak_step"] == first
    assert row["rss_before_fit_mb"] == row["memory"]["windows"]["peak_mb"]


def test_a_failed_row_keeps_the_memory_of_the_steps_it_got_through(jobs, monkeypatch):
    monkeypatch.setenv("TACTBENCH_TEST_FAIL", "1")
    (job,) = jobs("failing")
    row = run_cell(job)
    assert row["status"] == "failed"
    assert list(row["memory"])[-1] == "fit"  # the step that raised is recorded too
    assert row["peak_step"] in row["memory"] and row["peak_rss_mb"] > 0


def test_the_memory_tracker_names_the_step_that_set_the_peak():
    import numpy as np

    from tactbench.machine import memory_mb
    from tactbench.runner.execution.system import BEFORE, MemoryTracker

    current, peak = memory_mb()
    assert 0 < current <= peak
    mem = MemoryTracker()
    mem.step("small")
    assert mem.peak_step == BEFORE  # nothing new: the peak predates the tracker
    block = np.ones(int((peak + 64) * 2 ** 20 / 8))  # raise the peak by ≥ 64 MiB
    mem.step("big")
    del block
    mem.step("after")
    assert mem.peak_step == "big" and mem.peak_mb >= peak + 64
    assert mem.as_dict()["after"]["rss_mb"] < mem.as_dict()["big"]["rss_mb"]


def test_an_entry_damaged_after_the_run_checked_it_fails_its_cell_and_is_rebuilt_next(
        tiny_scene, cache, fake_registry):
    """A cell reads only a verified entry: one cut short after the run's check fails the
    cell with the one-line reason (not a crash, not garbage); the next run rebuilds it."""
    p = plan(tiny_scene(encoders=["raw"], classifiers=["added-logreg"], seeds=[0]),
             fake_registry)
    folders = ensure_encodings(p, cache, p.cells)
    (job,) = make_jobs(p, p.cells, folders)
    frames = Path(job.encoding_dir) / "frames.npy"
    with open(frames, "r+b") as fh:
        fh.truncate(frames.stat().st_size - 1)
    row = run_cell(job)
    assert row["status"] == "failed" and row["error"]["type"] == "CorruptArtefactError"
    assert row["error"]["message"].startswith(job.encoding_dir)
    assert "truncated" in row["error"]["message"]
    ensure_encodings(p, cache, p.cells)  # the next run
    assert run_cell(job)["status"] == "ok"


def test_a_k_fold_users_cell_tests_every_sample_once(tiny_scene, cache):
    from tactbench.runner import run

    result = run(tiny_scene(encoders=["raw"], seeds=[0], split="users:folds=2",
                            classifiers=["logreg"]), progress=False, cache=cache)
    [row] = result.rows
    assert row["status"] == "ok", row.get("error")
    assert (row["split"], row["folds"]) == ("users:folds=2", 2)
    n = len(row["test_predictions"]["indices"])
    assert sorted(row["test_predictions"]["indices"]) == list(range(n))
    assert row["n_test"] == n and len(row["test_users"]) == len(set(row["test_users"])) == 2
    from tactbench.errors import InputError

    with pytest.raises(InputError, match="trains one per fold"):
        run(tiny_scene(split="users:folds=2", save_models=True), progress=False, cache=cache)


@pytest.fixture
def three_by_three(tmp_path):
    """A saved dataset of taxel vectors: 3 users × 3 positions × 2 classes × 2
    repetitions, each class a different taxel pressed."""
    import numpy as np

    from tactbench.data.dataset import Dataset
    from tactbench.data.recording import Recording, Sample

    rng = np.random.default_rng(1)
    samples = []
    for i in range(36):
        label, user, position, rep = i % 2, (i // 2) % 3, (i // 6) % 3, 1 + i // 18
        values = rng.uniform(0.0, 0.1, (6, 4)).astype(np.float32)
        values[:, label] += 0.8
        samples.append(Sample(Recording(values, np.arange(6) * 0.1, np.arange(4)),
                              label=label, user=f"u{user}", position=f"p{position}",
                              repetition=rep, source="test"))
    path = tmp_path / "three"
    Dataset(name="three", samples=samples, classes=("a", "b"), layout=None).save(path)
    return path


@pytest.mark.parametrize("split, key", [("users:folds=3", "user"),
                                        ("group:position:folds=3", "position")])
def test_a_k_fold_row_stores_the_fold_and_group_each_recording_was_tested_in(
        tiny_scene, cache, three_by_three, split, key):
    """The fold ids of a row are the folds its models were trained on: drawn again here,
    fold k's test recordings are those the row says fold k tested."""
    import numpy as np

    from tactbench.data.dataset import Dataset
    from tactbench.data.splits import dataset_groups, make_splits
    from tactbench.runner import run

    scene = tiny_scene(dataset=str(three_by_three), encoders=["raw"],
                       classifiers=["logreg"], seeds=[4], split=split)
    [row] = run(scene, progress=False, cache=cache).rows
    assert row["status"] == "ok", row.get("error")
    tp = row["test_predictions"]
    assert set(tp) == {"indices", "labels", "predictions", "folds", "groups"}
    assert len(tp["folds"]) == len(tp["groups"]) == len(tp["indices"]) == row["n_test"]
    ds = Dataset.load(three_by_three)
    folds = make_splits(split, labels=ds.labels, users=ds.users, seed=4,
                        groups=dataset_groups(ds))
    indices, fold_of = np.asarray(tp["indices"]), np.asarray(tp["folds"])
    assert sorted(set(fold_of.tolist())) == [0, 1, 2] and row["folds"] == 3
    for f in folds:
        assert sorted(indices[fold_of == f.fold].tolist()) == f.test.tolist()
    values = dict(dataset_groups(ds))[key]
    assert tp["groups"] == [values[i] for i in tp["indices"]]
    # a group is tested in one fold only: what the fold left out
    assert all(len({k for k, g in zip(tp["folds"], tp["groups"]) if g == v}) == 1
               for v in set(tp["groups"]))


def test_a_one_split_row_stores_fold_0_and_each_recordings_own_group(tiny_scene, cache):
    from tactbench.runner import run

    [row] = run(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0]),
                progress=False, cache=cache).rows
    tp = row["test_predictions"]
    assert set(tp["folds"]) == {0} and "folds" not in row
    assert tp["groups"] == [str(i) for i in tp["indices"]]  # paper: each its own group


def test_a_plugins_split_and_test_window_registered_through_the_hooks_run(
        tiny_scene, cache, fake_registry):
    from tactbench.runner import run

    scene = tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0], split="parity",
                       test_window="last")
    result = run(scene, registry=fake_registry, progress=False, cache=cache)
    [row] = result.rows
    assert row["status"] == "ok", row.get("error")
    assert (row["split"], row["folds"], row["test_window"]) == ("parity", 2, "last")
    assert row["test_users"] == ["even", "odd"]
    tp = row["test_predictions"]
    assert all(i % 2 == k and g == ("even", "odd")[k]
               for i, k, g in zip(tp["indices"], tp["folds"], tp["groups"]))
    from tactbench.runner import plan

    identity = plan(scene, fake_registry).identities[row["key"]]
    assert (identity["split"], identity["test_window"]) == ("parity", "last")


def test_rows_with_and_without_fold_and_group_lists_read_back(tiny_scene, cache):
    """Rows made before folds and groups were stored still verify; lists that do not
    match, or are not fold numbers and text, are refused."""
    from tactbench.runner import run
    from tactbench.runner.execution.results import check_row

    [row] = run(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0]),
                progress=False, cache=cache).rows
    row = {k: v for k, v in row.items() if k != "checksum"}
    tp = row["test_predictions"]
    assert check_row(row, row["key"]) is None
    old = {**row, "test_predictions": {k: tp[k] for k in ("indices", "labels",
                                                          "predictions")}}
    assert check_row(old, row["key"]) is None
    for bad, problem in [({"folds": tp["folds"][:-1]}, "lists of one length"),
                         ({"folds": [-1] * len(tp["folds"])}, "fold numbers"),
                         ({"groups": [1] * len(tp["groups"])}, "groups that are not text"),
                         ({"fold": tp["folds"]}, "not {indices, labels, predictions")]:
        damaged = {**row, "test_predictions": {**tp, **bad}}
        assert problem in (check_row(damaged, row["key"]) or ""), bad


def test_a_kfold_cell_tests_every_recording_once_by_the_fold_it_was_dealt_to(tiny_scene,
                                                                             cache):
    from tactbench.runner import run

    [row] = run(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[1],
                           split="kfold"), progress=False, cache=cache).rows
    assert row["status"] == "ok", row.get("error")
    assert (row["split"], row["folds"], row["test_users"]) == ("kfold:folds=5", 5, [])
    tp = row["test_predictions"]
    assert sorted(tp["indices"]) == list(range(row["n_test"]))  # each recording once
    assert sorted(set(tp["folds"])) == list(range(5))
    assert tp["groups"] == [str(i) for i in tp["indices"]]
    assert len(row["fit"]) == 5  # one model per fold
