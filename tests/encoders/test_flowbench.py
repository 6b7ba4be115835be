"""Flowbench: scenes carry their true motion; errors, Pareto front and outputs are right."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.encoders.evaluation import flowbench as fb


def warp_back(curr: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """``curr(x + flow(x))``: equals ``prev`` where the ground truth is right."""
    import cv2

    h, w = curr.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    return cv2.remap(curr, xs + flow[..., 0], ys + flow[..., 1], cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REPLICATE)


@pytest.mark.parametrize("motion", ["translate", "twist", "push", "pull"])
@pytest.mark.parametrize("speed", [0.5, 4.0])
def test_true_flow_maps_each_frame_onto_the_previous(motion, speed):
    scene = fb.tactile_scene(motion, speed, "large", (64, 64), pairs=2)
    for k in range(2):
        back = warp_back(scene.curr[k], scene.flow[k])
        # where something moves, warping with the truth undoes most of the change
        # (not all: contacts blend where they overlap, and resampling smooths)
        mask = scene.mask[k] & (np.abs(scene.flow[k]).sum(-1) > 0)
        assert np.abs(back - scene.prev[k])[mask].mean() < \
            0.25 * np.abs(scene.curr[k] - scene.prev[k])[mask].mean()


def test_speeds_are_what_the_scene_says():
    for motion in ("translate", "pull"):
        scene = fb.tactile_scene(motion, 2.0, "small", (64, 64))
        speeds = np.hypot(*np.moveaxis(scene.flow[scene.mask], -1, 0))
        assert speeds.max() == pytest.approx(2.0, rel=1e-5)
    push = fb.tactile_scene("push", 2.0, "small", (64, 64))
    assert push.flow[push.mask].max() > 0


def test_pressure_change_has_zero_true_flow_but_changes_the_image():
    scene = fb.tactile_scene("pressure", 0.0, "small", (48, 48))
    assert not scene.flow.any()
    assert np.abs(scene.curr - scene.prev).max() > 0.05


def test_natural_scene_is_a_consistent_warp():
    scene = fb.natural_scene((64, 64))
    back = warp_back(scene.curr[0], scene.flow[0])
    mask = scene.mask[0]
    assert np.abs(back - scene.prev[0])[mask].mean() < 0.01
    assert not scene.tactile and np.abs(scene.flow).max() <= 2.0


def test_scene_inputs_are_checked():
    with pytest.raises(ValueError, match="motion"):
        fb.tactile_scene("wiggle", 1.0, "small", (32, 32))
    with pytest.raises(ValueError, match="size"):
        fb.tactile_scene("translate", 1.0, "huge", (32, 32))


def test_errors():
    truth = np.zeros((1, 1, 2), np.float32)
    est = np.array([[[3.0, 4.0]]], np.float32)
    assert fb.endpoint_error(est, truth)[0, 0] == pytest.approx(5.0)
    assert fb.angular_error(truth, truth)[0, 0] == pytest.approx(0.0, abs=1e-5)
    # (1, 0, 1) against (0, 0, 1): 45 degrees
    assert fb.angular_error(np.array([[[1.0, 0.0]]]), truth)[0, 0] == pytest.approx(45.0)


def test_pareto_front_of_time_against_error():
    """(time, error), both lower better: the front as the benchmark asks it, error negated."""
    from tactbench.pareto import pareto_front

    points = [(1.0, 5.0), (2.0, 1.0), (3.0, 3.0), (1.0, 6.0), (10.0, 0.5)]
    assert pareto_front([(t, -e) for t, e in points]) == [0, 1, 4]


def test_run_ranks_a_real_method_above_a_blind_one(tmp_path):
    from tactbench.encoders.flow import FlowEncoder
    from tactbench.plugins import load_registry

    class Blind(FlowEncoder):
        name = "blind"

        def _flow(self, prev, curr):
            return np.zeros((*prev.shape, 2), np.float32)

    encoders = [("dis", load_registry().build("encoder", "dis")), ("blind", Blind())]
    results = fb.run_flowbench(encoders, [(32, 32)], repeats=1)
    by = {r.encoder: r for r in results}
    assert by["dis"].epe < by["blind"].epe
    assert by["blind"].per_motion["pressure"] == 0.0      # never wrong about no motion
    assert set(by["dis"].per_motion) == set(fb.MOTIONS)
    assert all(r.ms_per_pair > 0 for r in results)
    paths = fb.write_outputs(results, tmp_path, {"test": True})
    doc = json.loads(paths["json"].read_text())
    assert {r["encoder"] for r in doc["results"]} == {"dis", "blind"}
    assert paths["csv"].read_text().count("\n") == len(doc["scenes"]) + 1
    assert paths["png"].stat().st_size > 1000
    assert sorted(f.name for f in tmp_path.iterdir()) == sorted(p.name for p in paths.values())


def test_outputs_are_written_whole_or_not_at_all(tmp_path, monkeypatch):
    """A plot that fails half-way leaves the old plot whole and no temporary behind."""
    from matplotlib.figure import Figure

    def half_then_fail(self, fname, **kwargs):
        if hasattr(fname, "write"):
            fname.write(b"half a png")
        else:
            Path(fname).write_bytes(b"half a png")
        raise OSError("disk full")

    (tmp_path / "flow_error_vs_time.png").write_bytes(b"old plot")
    monkeypatch.setattr(Figure, "savefig", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        fb.write_outputs([fb.EncoderResult("dis", "8x8", 0.5, 3.0, 0.1, 0.4, pareto=True)],
                         tmp_path, {"test": True})
    assert json.loads((tmp_path / "flowbench.json").read_text())["meta"] == {"test": True}
    assert (tmp_path / "flow_error_vs_time.png").read_bytes() == b"old plot"
    assert sorted(f.name for f in tmp_path.iterdir()) == [
        "flow_error_vs_time.png", "flowbench.csv", "flowbench.json"]


def test_command_prints_one_json_document_and_writes_files(tmp_path):
    result = CliRunner().invoke(cli, ["flowbench", "-e", "dis:preset=ultrafast", "--size",
                                      "24x24", "--repeats", "1", "--out", str(tmp_path),
                                      "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["results"][0]["encoder"] == "dis:preset=ultrafast"
    assert doc["results"][0]["pareto"] is True
    assert (tmp_path / "flow_error_vs_time.png").is_file()


def test_command_refuses_encoders_without_flow_and_bad_sizes():
    runner = CliRunner()
    result = runner.invoke(cli, ["flowbench", "-e", "raw", "--size", "24x24"])
    assert result.exit_code != 0 and "flow" in result.output
    result = runner.invoke(cli, ["flowbench", "--size", "big"])
    assert result.exit_code != 0 and "HxW" in result.output


def test_a_size_beyond_the_memory_budget_is_refused_before_any_scene(monkeypatch):
    """flowbench --size 4000x4000 under a 128 MiB budget: one line, exit 2, nothing made
    (it once peaked at 6.8 GB; the estimate, 15 GiB, is on the safe side)."""
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "128")
    monkeypatch.setattr(fb, "tactile_scene", lambda *a, **k: pytest.fail("a scene was made"))
    result = CliRunner().invoke(cli, ["flowbench", "--size", "4000x4000", "--encoder", "dis"])
    assert result.exit_code == 2
    assert "flowbench at 4000x4000 would need about" in result.output
    # the estimate grows with the images and stays under the default budget at the defaults
    assert fb.memory_estimate([(4000, 4000)]) > 100 * fb.memory_estimate([fb.DEFAULT_SHAPE])
    assert fb.memory_estimate([fb.DEFAULT_SHAPE, fb.FULL_SHAPE]) < 512 * 2 ** 20
