"""Hardening, round four (issue 40): a plugin's split and test window checked as a
classifier's output is, questions counted as the user asked them, strict durations,
a resumed run's budget, float16 that would overflow."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.data.splits import Split, SplitData, draw_splits
from tactbench.data.windows import Windows, check_windows
from tactbench.encoders.encoding import Storage
from tactbench.errors import ContractError, InputError
from tactbench.runner.orchestrate import next_batch_seconds
from tactbench.runner.execution.scene import Scene, parse_duration, show_duration

DATA = SplitData(np.array([0, 1, 0, 1, 0, 1]), {"user": tuple("aabbcc")})


class _Split:
    """A plugin split returning whatever ``make(data, seed)`` says."""

    def __init__(self, make):
        self.make = make

    def split(self, data, *, seed):
        return self.make(data, seed)


def _one(train, test):
    return [Split(np.asarray(train), np.asarray(test), tuple("g" * len(test)))]


@pytest.mark.parametrize("train, test, match", [
    ([-1, 0, 1], [4, 5], "must be ≥ 0"),  # -1 is the last recording: a test one
    (np.array([2 ** 64 - 1, 0], dtype=np.uint64), [4], "must be ≥ 0"),  # wraps to -1
    ([0, 1, 2, 3, 9], [4], "beyond the dataset's 6"),
])
def test_split_indices_that_wrap_or_leave_the_data_are_refused(train, test, match):
    with pytest.raises(ContractError, match=match):
        draw_splits(_Split(lambda d, s: _one(train, test)), DATA, 0, "split 'bad'")


def test_a_split_that_changes_its_data_or_its_draw_is_refused():
    def relabel(data, seed):
        data.labels[:] = 0  # what it was given: every cell would score against class 0
        return _one([0, 1, 2, 3], [4, 5])

    data = SplitData(DATA.labels.copy(), DATA.groups)
    with pytest.raises(ContractError, match="changed the labels"):
        draw_splits(_Split(relabel), data, 0, "split 'relabel'")
    draws = iter([[4, 5], [3, 5]])
    with pytest.raises(ContractError, match="other recordings when drawn twice with seed 3"):
        draw_splits(_Split(lambda d, s: _one([0, 1, 2], next(draws))), DATA, 3,
                    "split 'drifting'")
    assert draw_splits(_Split(lambda d, s: _one([0, 1, 2, 3], [4, 5])), DATA, 0, "ok")


def _windows(starts, seq_index, lengths=(4, 6)):
    seqs = [np.zeros((n, 2), np.float32) for n in lengths]
    return Windows(seqs, np.asarray(seq_index), np.asarray(starts),
                   np.zeros(len(starts), np.int64), 2)


def test_a_test_window_past_the_end_or_leaving_a_recording_out_is_refused():
    check_windows(_windows([0, 5], [0, 1]), "ok", every=True)
    with pytest.raises(ContractError, match="starts a window at frame 4 of a recording of 4"):
        check_windows(_windows([4, 0], [0, 1]), "test window 'late'")
    with pytest.raises(ContractError, match="starts a window at frame -1"):
        check_windows(_windows([-1], [1]), "test window 'neg'")
    with pytest.raises(ContractError, match="gives 1 of its 2 test recordings no window"):
        check_windows(_windows([0, 1], [1, 1]), "test window 'sparse'", every=True)


@pytest.mark.parametrize("primary", [
    ["encoder=raw..encoder=farneback", "encoder=raw..encoder=farneback"],
    ["encoder=raw..encoder=farneback", "encoder=farneback..encoder=raw"],
    ["encoder=raw,L=6..encoder=farneback,L=3", "L=3, encoder=farneback..L=6,encoder=raw"],
])
def test_one_question_named_twice_in_the_primary_family_is_refused(primary):
    with pytest.raises(InputError, match="names one question twice"):
        Scene(primary=primary)
    assert Scene(primary=primary[:1]).primary == primary[:1]


@pytest.mark.parametrize("text", ["1h30", "2h5", "1m30", "h", "90 m", "1.5.0h"])
def test_durations_are_parsed_strictly(text):
    with pytest.raises(InputError, match="bad duration"):
        parse_duration(text)


def test_durations_read_as_written_and_echoed():
    assert parse_duration("1h30m") == 5400 and parse_duration("90") == 90
    assert parse_duration("1m30s") == 90
    assert show_duration(5400) == "1 h 30 min" and show_duration(90) == "1 min 30 s"


@pytest.mark.parametrize("option", [["--budget", "1h"], ["--max-runs", "8"],
                                    ["--look-every", "2"]])
def test_options_that_need_until_are_refused_without_it(option, tmp_path):
    res = CliRunner().invoke(cli, ["run", *option, "--out", str(tmp_path / "o")])
    # the scene's own rule, said with the option's name (Scene.of)
    assert res.exit_code == 2 and f"{option[0]} only means something with --until " \
        "answered" in res.output
    assert not (tmp_path / "o").exists()


def test_a_resumed_look_of_stored_cells_does_not_make_the_next_batch_free():
    rows = [{"encoder": e, "classifier": "c", "L": 5, "train_s": 60.0,
             "inference_ms_per_sequence": 10.0, "n_test": 100} for e in ("raw", "flow")
            for _ in range(5)]
    # 5 more runs of 2 cells of 61 s on 2 workers: 5 rounds of 61 s
    assert next_batch_seconds(rows, 5, 2) == pytest.approx(5 * 61.0)
    assert next_batch_seconds([], 5, 2) == 0.0


def test_float16_storage_refuses_values_it_would_store_as_infinite():
    store = Storage.for_channels("float16", 1)
    assert store.encode(np.array([[1.0, 6e4]])).dtype == np.float16
    with pytest.raises(InputError, match="beyond float16's 65504"):
        store.encode(np.array([[1.0, 7e4]]))
    assert np.isnan(store.encode(np.array([[np.nan]]))).all()  # NaN is no overflow
