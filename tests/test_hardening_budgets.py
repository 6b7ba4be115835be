"""Budgets before work for every size a user can give: the simulator's users and
repetitions are estimated from the request (synthetic_forearm.memory_estimate, as
flowbench --size does) and refused by the memory budget in one line before anything is
simulated; grid cells and seeds are bounded before they are expanded."""

from __future__ import annotations

import time
import tracemalloc

import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.errors import BudgetError, InputError


@pytest.mark.parametrize("option", ["--users", "--repetitions"])
def test_data_synth_with_a_billion_users_or_repetitions_is_refused_before_work(tmp_path,
                                                                                option):
    start = time.perf_counter()
    result = CliRunner().invoke(cli, ["data", "synth", "--out", str(tmp_path / "o"),
                                      option, "1000000000"])
    assert result.exit_code == 2 and "memory budget" in result.output, result.output
    assert "1000000000" in result.output and time.perf_counter() - start < 20
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("spec", ["synthetic-forearm:users=1000000000",
                                  "synthetic-forearm:repetitions=1000000000"])
def test_a_simulator_option_of_a_billion_is_refused_before_simulating(spec):
    from tactbench.plugins import load_registry

    tracemalloc.start()
    try:
        with pytest.raises(BudgetError, match="simulating"):
            load_registry().build("dataset", spec + ",cache=false").load()
        assert tracemalloc.get_traced_memory()[1] < 64 << 20
    finally:
        tracemalloc.stop()


def test_the_estimate_follows_the_request_and_the_budget(monkeypatch):
    from tactbench.datasets.synthetic_forearm import generate, memory_estimate

    small = memory_estimate({"users": 1, "positions": 1, "repetitions": 1})
    assert memory_estimate({"users": 10, "positions": 2, "repetitions": 3}) == 60 * small
    monkeypatch.setenv("TACTBENCH_MEMORY_MIB", "64")
    assert len(generate(users=1, positions=1, repetitions=1, workers=1)) == 5
    with pytest.raises(BudgetError):
        generate(users=1000, positions=2, repetitions=5, workers=1)


def test_grid_cells_seeds_and_lengths_are_bounded_before_they_are_expanded():
    from tactbench.runner import Scene, plan
    from tactbench.runner.execution.scene import parse_lengths, parse_seeds

    with pytest.raises(InputError, match="too many seeds"):
        parse_seeds(["0-99999999999"])
    with pytest.raises(InputError, match="too many window lengths"):
        parse_lengths(["1-3000000000000"])
    with pytest.raises(InputError, match="cells"):
        plan(Scene(dataset="no-such-dataset", seeds=list(range(1000)),
                   L=list(range(1, 21))))


def test_a_dataset_of_more_classes_than_a_row_can_hold_is_refused_at_planning():
    from types import SimpleNamespace

    from tactbench.runner import Scene
    from tactbench.runner.execution.planning import _check_memory

    many = SimpleNamespace(name="many", classes=[f"c{i}" for i in range(3000)])
    with pytest.raises(BudgetError, match="3000 classes.*at most 2896 classes"):
        _check_memory(Scene(dataset="x"), many, {}, {}, {})
