"""Executors: worker processes and dask give the local results, use the planned plugins,
and turn a failing cell into a failed row."""

from __future__ import annotations

import pytest

from tactbench.runner import run

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _by_cell(rows):
    return sorted(((r["classifier"].split(":")[0], r["L"], r["seed"]), r["status"],
                   r.get("confusion")) for r in rows)


def _extra_and_failing(tiny_scene, **over):
    # "added-logreg" and "failing" exist only in the fake registry (make_plugin_manager
    # extra=...): the workers must build them from the job, not from installed plugins
    return tiny_scene(encoders=["raw"], classifiers=["added-logreg:max_iter=20", "failing"],
                      seeds=[0], L=[2, 3], **over)


def test_worker_processes_use_the_planned_plugins_and_record_failures(
        tiny_scene, cache, fake_registry, monkeypatch):
    monkeypatch.setenv("TACTBENCH_TEST_FAIL", "1")
    result = run(_extra_and_failing(tiny_scene, workers=2), registry=fake_registry,
                 progress=False, cache=cache)
    assert result.computed == 4
    assert [(c, s) for c, s, _ in _by_cell(result.rows)] == [
        (("added-logreg", 2, 0), "ok"), (("added-logreg", 3, 0), "ok"),
        (("failing", 2, 0), "failed"), (("failing", 3, 0), "failed")]
    assert {r["error"]["type"] for r in result.failed} == {"RuntimeError"}


@pytest.mark.slow("starts a dask LocalCluster of two worker processes and trains the grid twice")
def test_dask_uses_the_planned_plugins_and_records_failures(tiny_scene, cache, fake_registry,
                                                            monkeypatch, tmp_path):
    pytest.importorskip("distributed")
    monkeypatch.setenv("TACTBENCH_TEST_FAIL", "1")
    local = run(_extra_and_failing(tiny_scene, out=str(tmp_path / "a")),
                registry=fake_registry, progress=False, cache=cache)
    dask = run(_extra_and_failing(tiny_scene, out=str(tmp_path / "b"), executor="dask",
                                  workers=2), registry=fake_registry, progress=False,
               cache=cache)
    assert dask.computed == 4 and len(dask.failed) == 2
    assert _by_cell(dask.rows) == _by_cell(local.rows)  # same cells, same confusions


@pytest.mark.slow("starts a dask LocalCluster of two worker processes and trains the grid twice")
def test_dask_local_cluster_gives_the_same_results_as_local(tmp_path, tiny_scene, cache):
    pytest.importorskip("distributed")
    local = run(tiny_scene(out=str(tmp_path / "a")), progress=False, cache=cache)
    dask = run(tiny_scene(out=str(tmp_path / "b"), executor="dask", workers=2),
               progress=False, cache=cache)
    assert dask.computed == 4
    key = lambda r: (r["encoder"], r["L"], r["seed"])  # noqa: E731
    assert [(key(r), r["confusion"]) for r in sorted(local.rows, key=key)] == \
           [(key(r), r["confusion"]) for r in sorted(dask.rows, key=key)]


def test_serial_cells_name_the_run_step_that_set_their_peak(monkeypatch):
    from types import SimpleNamespace

    from tactbench.runner.execution import executors
    from tactbench.runner.execution.system import BEFORE, MemoryTracker
    from tactbench.ui import Progress

    rows = iter([{"peak_step": BEFORE}, {"peak_step": "fit"}])
    monkeypatch.setattr(executors, "run_cell", lambda job, progress=None: next(rows))
    cell = SimpleNamespace(classifier="logreg",
                           label=lambda labels=None: "raw × logreg L=5 seed=0")
    job = SimpleNamespace(cell=cell)
    # the run so far: its encoding pass set a peak far above anything a cell reaches
    memory = MemoryTracker(steps=[(BEFORE, 10.0, 10.0), ("encode", 10.0, 1e9)])
    got = []
    with Progress(enabled=False) as bars:
        executors.run_serial([job, job], got.append, bars, memory)
    assert [r["peak_step"] for r in got] == ["encode (earlier in this run)", "fit"]
