"""Stability suite: extreme cases pass or fail per encoder, with reasons and exit status."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.encoders.evaluation import stability as st
from tactbench.encoders.base import Encoder
from tactbench.encoders.simple import Raw

CASES = {c.name: c for c in st.default_cases()}


def test_every_case_the_issue_lists_is_there():
    expected = {"all-zero", "constant", "saturated", "hot-pixel", "checkerboard", "nan", "inf",
                "huge-motion", "sub-pixel", "tiny-1x1", "tiny-2x2", "tiny-3x3", "tiny-8x8",
                "t1", "t1000", "dtype-uint8", "dtype-uint16", "dtype-float16",
                "dtype-float64", "far-above", "far-below"}
    assert expected <= set(CASES)
    assert {n for n, c in CASES.items() if c.expect_error} == {"nan", "inf", "far-above",
                                                               "far-below"}


@pytest.mark.parametrize("spec", ["raw", "frame-diff", "farneback", "dis", "lucas-kanade"])
def test_builtins_pass_every_case(spec):
    from tactbench.plugins import load_registry

    enc = load_registry().build("encoder", spec)
    cases = [c for c in CASES.values() if c.name != "t1000" or spec in ("raw", "frame-diff")]
    failed = [o for o in st.run_stability([(spec, enc)], cases) if not o.passed]
    assert not failed, "\n".join(f"{o.case}: {o.reason}" for o in failed)


def test_a_silent_repair_fails_the_nan_case():
    class Repairing(Raw):
        def encode(self, seq):
            return super().encode(np.nan_to_num(np.asarray(seq, np.float32), nan=0.0,
                                                posinf=1.0))

    outcome = st.run_case(Repairing(), CASES["nan"])
    assert not outcome.passed and "ValueError" in outcome.reason


def test_non_finite_output_fails_with_the_channel_and_frame():
    class Exploding(Encoder):
        name = "exploding"
        channels = ("pressure", "ratio")
        ranges = ((0.0, 1.0), (0.0, 1.0))

        def _encode(self, seq):
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.stack([seq, seq / seq.max(axis=(1, 2), keepdims=True)], axis=1)

    outcome = st.run_case(Exploding(), CASES["all-zero"])
    assert not outcome.passed
    assert "non-finite" in outcome.reason and "'ratio'" in outcome.reason


def test_a_crash_is_a_failure_not_an_exception():
    class Fragile(Raw):
        def _encode(self, seq):
            if seq.shape[1] < 2:
                raise IndexError("too small")
            return super()._encode(seq)

    outcome = st.run_case(Fragile(), CASES["tiny-1x1"])
    assert not outcome.passed and outcome.reason.startswith("IndexError")


def test_command_exit_status_and_json(tmp_path):
    runner = CliRunner()
    ok = runner.invoke(cli, ["stability", "-e", "raw", "-e", "farneback", "--case", "nan",
                             "--case", "tiny-1x1", "--json"])
    assert ok.exit_code == 0, ok.output
    doc = json.loads(ok.stdout)
    assert doc["passed"] is True and doc["total"] == 4
    assert {r["encoder"] for r in doc["results"]} == {"raw", "farneback"}
    # OpenCV's Farnebäck without the border margin, on an 8×8 grid: motion where there is
    # (almost) none — the problem the margin fixes, so the suite must fail it.
    bad = runner.invoke(cli, ["stability", "-e", "farneback:margin=0,downscale=4",
                              "--case", "sub-pixel"])
    assert bad.exit_code == 1
    assert "FAILED sub-pixel × farneback:margin=0,downscale=4" in bad.output


def test_command_rejects_unknown_cases():
    result = CliRunner().invoke(cli, ["stability", "--case", "sideways"])
    assert result.exit_code != 0 and "unknown case" in result.output
