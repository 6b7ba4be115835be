"""Errors have types: a user's mistake is one line and exit status 2, a bug keeps its
traceback and says how to report it; the shared checks accept and refuse by name."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from tactbench.errors import (
    ContractError,
    InputError,
    MissingFileError,
    PluginError,
    TactbenchError,
    UnknownComponentError,
    check_choice,
    check_positive_float,
    check_positive_int,
    check_shape,
)

BUGGY_PLUGIN = """
    import numpy as np
    from tactbench import hookimpl

    class Divide:
        channels = ("pressure",)

        def encode(self, seq):
            scale = 1 / 0  # the bug
            return np.asarray(seq, np.float32)[:, None] * scale

    @hookimpl
    def register_encoders(register):
        register("divide", "buggyplug:Divide", summary="divides by zero")
"""


def tactbench(*args, env=None):
    return subprocess.run([sys.executable, "-m", "tactbench", *args], capture_output=True,
                          text=True, env={**os.environ, **(env or {})}, timeout=120)


@pytest.fixture
def sequence(tmp_path):
    path = tmp_path / "seq.npy"
    np.save(path, np.zeros((3, 8, 8), np.float32))
    return path


# ----------------------------------------------------------------------------- the CLI


def test_a_bug_inside_a_component_shows_its_traceback(plugin_dist, sequence, tmp_path):
    plugin_dist("buggy-dist", "buggyplug", BUGGY_PLUGIN)
    result = tactbench("encode", "--encoder", "divide", "--input", str(sequence),
                       "--out", str(tmp_path / "out.npy"))
    assert result.returncode == 1
    assert "Traceback (most recent call last)" in result.stderr
    assert "ZeroDivisionError" in result.stderr and "buggyplug.py" in result.stderr
    assert "this is a bug" in result.stderr and "please report it" in result.stderr


def test_a_bad_option_is_one_line_and_exit_status_2(sequence, tmp_path):
    result = tactbench("encode", "--encoder", "farneback:winsize=-1", "--input",
                       str(sequence), "--out", str(tmp_path / "out.npy"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert lines == ["Error: encoder 'farneback': winsize must be ≥ 1, got -1"]
    assert not (tmp_path / "out.npy").exists()


def test_bad_file_content_is_a_user_error(tmp_path):
    path = tmp_path / "loud.npy"
    np.save(path, np.full((2, 4, 4), 3.0, np.float32))
    result = tactbench("encode", "--encoder", "raw", "--input", str(path),
                       "--out", str(tmp_path / "out.npy"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "values must lie in [0, 1]" in result.stderr


def test_debug_shows_the_traceback_of_a_user_error(sequence, tmp_path):
    result = tactbench("encode", "--encoder", "farneback:winsize=-1", "--input",
                       str(sequence), "--out", str(tmp_path / "out.npy"),
                       env={"TACTBENCH_DEBUG": "1"})
    assert result.returncode != 0
    assert "Traceback (most recent call last)" in result.stderr
    assert "InputError: encoder 'farneback': winsize must be ≥ 1" in result.stderr


# ----------------------------------------------------------------------------- the types


def test_user_errors_are_also_the_builtin_types_callers_expect():
    assert issubclass(InputError, ValueError) and issubclass(InputError, TactbenchError)
    assert issubclass(MissingFileError, FileNotFoundError)
    assert issubclass(UnknownComponentError, LookupError)
    assert issubclass(ContractError, PluginError) and issubclass(ContractError, TypeError)
    assert str(UnknownComponentError("unknown encoder 'x'")) == "unknown encoder 'x'"


# ----------------------------------------------------------------------------- the checks


@pytest.mark.parametrize("value, minimum, expected", [(3, 1, 3), (np.int64(5), 1, 5),
                                                      (0, 0, 0), (4.0, 1, 4)])
def test_check_positive_int_accepts(value, minimum, expected):
    got = check_positive_int(value, "levels", minimum=minimum)
    assert got == expected and type(got) is int


@pytest.mark.parametrize("value, minimum, message", [
    (0, 1, "levels must be ≥ 1, got 0"), (-2, 0, "levels must be ≥ 0, got -2"),
    (2.5, 1, "levels must be an integer ≥ 1, got 2.5"), (True, 1, "levels must be an integer"),
    ("3", 1, "levels must be an integer ≥ 1, got '3'"), (None, 1, "levels must be an integer"),
])
def test_check_positive_int_refuses_naming_the_argument(value, minimum, message):
    with pytest.raises(InputError, match=message):
        check_positive_int(value, "levels", minimum=minimum)


@pytest.mark.parametrize("value, allow_zero", [(0.5, False), (3, False), (0, True),
                                               (np.float32(2.0), False)])
def test_check_positive_float_accepts(value, allow_zero):
    got = check_positive_float(value, "max_flow", allow_zero=allow_zero)
    assert got == float(value) and type(got) is float


@pytest.mark.parametrize("value, allow_zero, message", [
    (0, False, "max_flow must be > 0, got 0"), (-1.0, True, "max_flow must be ≥ 0, got -1.0"),
    (float("nan"), False, "max_flow must be a finite number, got nan"),
    (float("inf"), True, "max_flow must be a finite number"), (False, False, "finite number"),
    ("8", False, "max_flow must be a finite number, got '8'"),
])
def test_check_positive_float_refuses_naming_the_argument(value, allow_zero, message):
    with pytest.raises(InputError, match=message):
        check_positive_float(value, "max_flow", allow_zero=allow_zero)


def test_check_choice_accepts_a_choice_and_suggests_the_closest():
    assert check_choice("fast", "preset", ("ultrafast", "fast", "medium")) == "fast"
    with pytest.raises(InputError, match="unknown preset 'mediun'; did you mean 'medium'\\? "
                                         "Choices: ultrafast, fast, medium"):
        check_choice("mediun", "preset", ("ultrafast", "fast", "medium"))
    with pytest.raises(InputError, match="unknown preset 'zzz'. Choices: fast"):
        check_choice("zzz", "preset", ("fast",))


def test_check_shape_accepts_rank_sizes_and_kind():
    check_shape(np.zeros((5, 3, 8, 8), np.float32), "T C H W", "encoded", C=3,
                dtype_kind="f")


@pytest.mark.parametrize("arr, message", [
    (np.zeros((5, 2, 8, 8)), r"encoded must be \(T, C=3, H, W\), got \(5, 2, 8, 8\)"),
    (np.zeros((5, 8, 8)), r"encoded must be \(T, C=3, H, W\), got \(5, 8, 8\)"),
    ([[1.0]], r"encoded must be an array \(T, C=3, H, W\), got list"),
    (np.zeros((1, 3, 2, 2), dtype="U1"), "encoded must hold numbers, got dtype <U1"),
])
def test_check_shape_refuses_saying_expected_and_actual(arr, message):
    with pytest.raises(InputError, match=message):
        check_shape(arr, "T C H W", "encoded", C=3, dtype_kind="fiu")


def test_corrupt_artefact_error_survives_pickling():
    import pickle

    from tactbench.errors import CorruptArtefactError

    err = pickle.loads(pickle.dumps(CorruptArtefactError("/c/x.npy", "checksum differs")))
    assert (err.artefact, err.problem, str(err)) == ("/c/x.npy", "checksum differs",
                                                     "/c/x.npy: checksum differs")
