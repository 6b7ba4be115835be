"""A plugin is checked at the boundary at run time (tactbench.boundary): what an encoder
or a classifier returns is checked where the runner takes it; a violation is a failed
cell naming the plugin, the component and the rule, never a score, and never a row
dropped at report time. The conformance suites apply the same rules."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

from tactbench.boundary import (
    EncoderGuard,
    encoder_output_problem,
    labels_problem,
    proba_problem,
)
from tactbench.runner import FAILED, OK, EncodingCache, ResultStore, Scene, run

HERE = Path(__file__).resolve().parent / "hostile"
TINY = "synthetic-forearm:users=2,repetitions=1"


@pytest.fixture
def hostile(monkeypatch):
    """Built-ins plus tests/hostile/hostile_components.py, importable in workers."""
    import sys

    from tactbench.plugins import collect_registry, make_plugin_manager

    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])]))
    sys.modules.pop("hostile_components", None)
    import hostile_components

    return collect_registry(make_plugin_manager(entry_points=False,
                                                extra=[("hostile", hostile_components)]))


def _run(tmp_path, registry, *, encoders, classifiers, **over):
    scene = Scene(dataset=TINY, encoders=encoders, classifiers=classifiers, L=[3],
                  seeds=[0], test_per_class=1, pixel_mm=10.0, threads=1,
                  out=str(tmp_path / "out"), **over)
    return run(scene, registry=registry, progress=False,
               cache=EncodingCache(tmp_path / "cache"))


@pytest.mark.parametrize("encoder, rule", [
    ("nan-enc", "NaN or infinite"), ("huge-enc", "dtype float64, expected float32"),
    ("scaled-enc", "outside its declared range"), ("two-channel-enc", "shape")])
def test_an_encoders_broken_output_is_a_failed_cell_naming_plugin_and_rule(
        tmp_path, hostile, encoder, rule):
    result = _run(tmp_path, hostile, encoders=[encoder, "raw"], classifiers=["logreg"])
    by_encoder = {r["encoder"]: r for r in result.rows}
    assert len(result.rows) == 2  # the failed cell is reported, not dropped
    assert by_encoder["raw"]["status"] == OK  # the other encoder of the pass goes on
    bad = by_encoder[encoder]
    assert bad["status"] == FAILED and "accuracy" not in bad
    message = bad["error"]["message"]
    assert bad["error"]["type"] == "BoundaryError"
    assert f"encoder '{encoder}'" in message and "plugin 'hostile'" in message
    assert rule in message
    # the next run encodes it again (the plugin may have been fixed), and fails again
    again = _run(tmp_path, hostile, encoders=[encoder, "raw"], classifiers=["logreg"])
    assert {r["encoder"]: r["status"] for r in again.rows} == {encoder: FAILED, "raw": OK}


@pytest.mark.parametrize("classifier, rule, window", [
    ("nan-proba", "NaN or infinite", "vote"), ("few-columns", "expected (", "vote"),
    ("negative-proba", "negative probability", "vote"),
    ("unnormalised-proba", "sums to", "vote"), ("minus-one", "outside 0..", "first")])
def test_a_classifiers_broken_output_is_a_failed_cell_never_a_score(
        tmp_path, hostile, classifier, rule, window):
    result = _run(tmp_path, hostile, encoders=["raw"], classifiers=[classifier],
                  test_window=window)
    assert len(result.rows) == 1 and result.rows[0]["status"] == FAILED
    message = result.rows[0]["error"]["message"]
    assert f"classifier '{classifier}'" in message and "plugin 'hostile'" in message
    assert rule in message, message
    assert result.failed and not result.ok


def test_an_unsound_row_is_stored_as_a_failed_row_not_dropped_at_report_time(tmp_path):
    store = ResultStore(tmp_path)
    row = {"key": "k", "encoder": "raw", "classifier": "x", "L": 3, "seed": 0,
           "status": OK, "accuracy": 0.5, "classes": ["a", "b"],
           "confusion": [[1, 0], [1, 0]], "per_class_accuracy": {"a": 1.0, "b": 0.0},
           "test_predictions": {"indices": [0, 1], "labels": [0, 1], "predictions": [0, -1]}}
    stored = store.put(row)
    assert stored["status"] == FAILED and "test_predictions" in stored["error"]["message"]
    assert store.rows(["k"]) == [stored]  # read back: reported, exit 1


def test_the_rules_one_by_one():
    ok = np.zeros((4, 1, 3, 3), np.float32)
    assert encoder_output_problem(ok, (4, 1, 3, 3), ((0, 1),)) is None
    assert "not a numpy array" in encoder_output_problem(ok.tolist(), (4, 1, 3, 3))
    assert "inf" in encoder_output_problem(ok + np.inf, (4, 1, 3, 3))
    assert "(4, 2, 3, 3)" in encoder_output_problem(ok, (4, 2, 3, 3))
    assert "channel 0 spans" in encoder_output_problem(ok - 1, (4, 1, 3, 3), ((0, 1),))
    p = np.full((3, 2), 0.5)
    assert proba_problem(p, 3, 2) is None
    assert "expected (3, 3)" in proba_problem(p, 3, 3)
    assert "sums to" in proba_problem(p * 0.9, 3, 2)
    assert labels_problem(np.array([0, 1, 1]), 3, 2) is None
    assert "outside 0..1" in labels_problem(np.array([0, 2, 1]), 3, 2)
    assert "not class numbers" in labels_problem(np.array([0.5, 1, 1]), 3, 2)
    got = []
    guard = EncoderGuard(got.append, [2, 3], (1, 2, 2), ranges=((0, 1),),
                         component="e", plugin="p")
    guard(np.full((2, 1, 2, 2), np.nan, np.float32))
    guard(np.ones((3, 1, 2, 2), np.float32))
    assert "sample 0" in guard.violation and [g.shape for g in got] == [(2, 1, 2, 2),
                                                                         (3, 1, 2, 2)]
    assert not any(g.any() for g in got)  # zeros stand in; the entry is marked


def test_the_conformance_suites_apply_the_same_rules(hostile):
    from tactbench.testing import check_classifier, check_encoder

    import hostile_components as hc

    for cls, rule in ((hc.NaNEncoder, "NaN or infinite"), (hc.HugeEncoder, "float64"),
                      (hc.ScaledEncoder, "declared [0.0, 1.0]"),
                      (hc.TwoChannelEncoder, "expected (1, 1, 32, 32)")):
        with pytest.raises(AssertionError, match=re.escape(rule)):
            check_encoder(cls())
    for name in ("nan-proba", "negative-proba", "unnormalised-proba"):
        with pytest.raises(AssertionError, match="predict_proba"):
            check_classifier(name, registry=hostile)


def test_encode_never_writes_an_encoders_broken_output(tmp_path, plugin_dist):
    import subprocess
    import sys

    plugin_dist("tb-nan", "tb_nan", """
        import numpy as np
        from tactbench import hookimpl

        class NaN:
            channels = ("v",)

            def encode(self, seq):
                return np.full((len(seq), 1, *np.shape(seq)[1:]), np.nan, np.float32)

        @hookimpl
        def register_encoders(register):
            register("nan-cli", "tb_nan:NaN", summary="NaN everywhere")
        """)
    seq = tmp_path / "seq.npy"
    np.save(seq, np.random.default_rng(0).random((3, 6, 6)).astype(np.float32))
    done = subprocess.run([sys.executable, "-m", "tactbench", "encode", "-i", str(seq),
                           "-o", str(tmp_path / "out"), "-e", "nan-cli"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "NaN or infinite" in done.stderr, done.stderr
    assert "encoder 'nan-cli'" in done.stderr and not (tmp_path / "out.npy").exists()
