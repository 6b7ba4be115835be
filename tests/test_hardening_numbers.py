"""Every number a user gives is checked against its meaning before work starts, by one
shared check (tactbench.errors.check_number; cli.Number for CLI options), with bounds
that follow from the input where they do; budgets count the whole input."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from tactbench.cli import cli
from tactbench.errors import BudgetError, InputError, check_number


@settings(max_examples=200, deadline=None, database=None)
@given(value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(),
                       st.booleans(), st.text(max_size=5), st.none()),
       minimum=st.sampled_from([None, 0, 1]), integer=st.booleans())
def test_check_number_returns_only_finite_numbers_within_bounds(value, minimum, integer):
    try:
        got = check_number(value, "x", minimum=minimum, maximum=1e6, integer=integer)
    except InputError as exc:
        assert str(exc).startswith("x must be")
        return
    assert math.isfinite(got) and got <= 1e6 and (minimum is None or got >= minimum)
    assert not integer or float(got).is_integer()


@pytest.mark.parametrize("args", [
    ["can", "record", "--out", "x.blf", "--duration", "nan"],
    ["can", "record", "--out", "x.blf", "--idle-timeout", "nan"],
    ["can", "record", "--out", "x.blf", "--idle-timeout", "-1"],
    ["can", "record", "--out", "x.blf", "--max-messages", "-5"],
    ["can", "record", "--out", "x.blf", "--bitrate", "0"],
    ["can", "load", "--taxels", "10", "--bitrate", "0"],
    ["can", "load", "--taxels", "10", "--rate", "inf"],
    ["can", "simulate", "synthetic-forearm", "--speed", "-1"],
    ["can", "simulate", "synthetic-forearm", "--speed", "nan"],
    ["can", "simulate", "synthetic-forearm", "--gap", "-0.5"],
    ["live", "--model", __file__, "--max-sweeps", "-1"],
    ["live", "--model", __file__, "--threads", "nan"],
    ["live", "--model", __file__, "-L", "0"],
])
def test_cli_numbers_are_refused_before_any_work(args, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2, result.output
    assert "Invalid value" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "x.blf").exists()


def test_a_nan_idle_timeout_of_the_sensor_is_refused():
    from tactbench.plugins import load_registry

    with pytest.raises(InputError, match="idle_timeout must be a finite number"):
        load_registry().build("sensor", "cyskin-can:idle_timeout=nan,taxel_ids=0-10")


def test_a_window_larger_than_the_image_is_an_error_naming_both():
    from tactbench.plugins import load_registry

    registry = load_registry()
    seq = np.random.default_rng(0).random((3, 20, 16)).astype(np.float32)
    for spec, name in [("farneback:winsize=99999", "winsize"),
                       ("lucas-kanade:winsize=999", "winsize"),
                       ("dis:patch_size=999", "patch_size"), ("tvl1:median=999", "median")]:
        encoder = registry.build("encoder", spec)
        with pytest.raises(InputError, match=rf"{name} 999\d* is larger than the image "
                                             rf"\(20×16 px\)"):
            encoder.encode(seq)
    registry.build("encoder", "farneback:winsize=15").encode(seq[:, :4, :4])  # defaults fit
    with pytest.raises(InputError, match="iterations must be ≤"):
        registry.build("encoder", "farneback:iterations=1e9")


def test_planning_refuses_a_window_larger_than_the_image_before_encoding(tmp_path):
    from tactbench.runner import Scene
    from tactbench.runner.execution.planning import plan

    scene = Scene(dataset="synthetic-forearm:users=2,repetitions=1",
                  encoders=["farneback:winsize=99999"], classifiers=["logreg"], L=[2],
                  seeds=[0], test_per_class=1, pixel_mm=10.0, out=str(tmp_path / "out"))
    with pytest.raises(InputError, match="winsize 99999 is larger than the image"):
        plan(scene)


@pytest.mark.parametrize("pitch", [1e-300, 0, -1, float("nan"), 1e300])
def test_a_pitch_beyond_a_physical_length_is_one_line(tmp_path, pitch):
    from tactbench.datasets.folder import read_folder

    (tmp_path / "a").mkdir()
    np.save(tmp_path / "a" / "r.npy", np.ones((3, 4, 4)))
    with pytest.raises(InputError, match="pitch_mm"):
        read_folder(tmp_path, pitch_mm=pitch)


def test_the_memory_budget_counts_the_whole_folder(tmp_path, monkeypatch):
    from tactbench.datasets.folder import read_folder

    for cls in ("a", "b"):
        (tmp_path / cls).mkdir()
        for i in range(4):  # 4 × 2 files of 0.5 MiB: each under the budget, all above it
            np.save(tmp_path / cls / f"r{i}.npy", np.ones((64, 32, 32), np.float64))
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "2")
    with pytest.raises(BudgetError, match=r"reading the 8 recordings under .* would need"):
        read_folder(tmp_path)
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "20")
    assert len(read_folder(tmp_path)) == 8


def test_a_csv_is_read_within_a_few_times_its_size(tmp_path):
    from tactbench.datasets.folder import read_array_file

    rng = np.random.default_rng(0)
    path = tmp_path / "big.csv"
    rows = rng.integers(0, 9, (20_000, 100))
    path.write_text("\n".join(",".join(map(str, r)) for r in rows) + "\n")  # 4 MB
    size = path.stat().st_size
    tracemalloc.start()
    values, _ = read_array_file(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert values.shape == (20_000, 100)
    assert peak < 8 * size, f"peak {peak / size:.1f} × the file"  # was ~50 ×


def test_a_csv_field_over_the_csv_modules_limit_is_one_line(tmp_path):
    from tactbench.datasets.folder import read_array_file

    path = tmp_path / "r.csv"
    path.write_text('1,2\n3,"' + "4" * 200_000 + '"\n')
    with pytest.raises(InputError, match=r"r.csv, line 2: not a CSV row"):
        read_array_file(path)


def test_a_preview_at_a_fine_pixel_is_refused_under_the_budget(monkeypatch, tmp_path):
    from tactbench.cli import cli as app

    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "64")
    spec = "synthetic-forearm:users=1,repetitions=1,positions=1"
    result = CliRunner().invoke(app, ["data", "preview", spec, "--pixel-mm", "0.05",
                                      "--out", str(tmp_path / "p.png")])
    assert result.exit_code == 2 and "more than the memory budget" in result.output, \
        result.output
    assert not (tmp_path / "p.png").exists()
    result = CliRunner().invoke(app, ["data", "preview", spec, "--pixel-mm", "nan",
                                      "--out", str(tmp_path / "p.png")])
    assert result.exit_code == 2 and "Invalid value" in result.output


# ------------------------------------------------------- round three: numbers at the edge


def test_readings_near_the_float32_limit_are_normalised_without_nan(tmp_path):
    """Readings of ±3e38 (finite float32) span 6e38, beyond float32: the normalisation
    is computed in float64, so the images are not NaN (a run scoring chance)."""
    from tactbench.datasets.folder import read_folder

    root = tmp_path / "edge"
    rng = np.random.default_rng(0)
    for cls, sign in (("a", 1), ("b", -1)):
        (root / cls).mkdir(parents=True)
        for i in range(3):
            values = rng.uniform(-3e38, 3e38, (5, 3, 3))
            values[:, 0, 0] = sign * 3.3e38  # the class is in one taxel
            np.save(root / cls / f"r{i}.npy", values.astype(np.float32))
    ds = read_folder(root)
    vectors = ds.vectors()
    assert all(np.isfinite(v).all() and 0 <= v.min() and v.max() <= 1 for v in vectors)
    assert len({round(float(v[:, 0].mean()), 3) for v in vectors}) == 2  # classes differ
    for spec in ("baseline", "fixed:offset=-3.4e38,scale=6.8e38"):
        ds.normalisation = type(ds.normalisation).parse(spec)
        ds._norm_params = None
        with np.errstate(all="raise"):  # not even an overflow on the way
            out = ds.vectors()
        assert all(np.isfinite(v).all() and v.max() <= 1 for v in out), spec
        assert max(float(v.max()) for v in out) > 0.5, spec  # not all zeros


@pytest.mark.parametrize("body", ['{"pixel_mm": %s}' % ("1" * 400),
                                  '{"pixel_mm": -%s}' % ("9" * 400),
                                  '{"pixel_mm": %s.5}' % ("1" * 400),
                                  '{"seeds": [%s]}' % ("1" * 400),
                                  '{"threads": %s}' % ("1" * 400)])
def test_a_json_scene_number_of_400_digits_is_one_line(tmp_path, body):
    from tactbench.runner.execution.scene_files import load_scene_file

    path = tmp_path / "scene.json"
    path.write_text(body)
    with pytest.raises(InputError) as err:
        load_scene_file(path)
    assert "scene.json" in str(err.value) and "\n" not in str(err.value)
    result = CliRunner().invoke(cli, ["run", str(path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
