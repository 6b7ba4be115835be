"""The conformance suite passes good encoders and names what is wrong with bad ones."""

from __future__ import annotations

import numpy as np
import pytest

from tactbench.encoders.base import Encoder, previous_frames
from tactbench.encoders.flow import FlowEncoder
from tactbench.encoders.evaluation.conformance import (
    CHECKS,
    check_encoder,
    conformance_cases,
    run_check,
    run_checks,
)


class Diff(Encoder):
    """A correct two-channel encoder (like frame-diff)."""

    name = "diff"
    channels = ("pressure", "diff")
    ranges = ((0.0, 1.0), (-1.0, 1.0))

    def _encode(self, seq):
        return np.stack([seq, seq - previous_frames(seq)], axis=1)


class Shift(FlowEncoder):
    """A flow encoder that reports a constant flow (u, v) wherever there is pressure."""

    name = "shift"

    def __init__(self, *, u: float = 0.0, v: float = 0.0, max_flow: float = 8.0) -> None:
        super().__init__(max_flow=max_flow)
        self.u, self.v = u, v

    def _flow(self, prev, curr):
        changed = (np.abs(curr - prev) > 1e-6)[..., None]
        return np.where(changed, np.array([self.u, self.v], np.float32), 0.0).astype(np.float32)


def failures(encoder):
    return {r.check: r.message for r in run_checks(encoder) if r.status == "failed"}


def test_a_correct_encoder_passes_and_flow_checks_are_skipped():
    results = check_encoder(Diff())
    assert [r.check for r in results] == list(CHECKS)
    skipped = [r for r in results if r.status == "skipped"]
    assert [r.check for r in skipped] == ["translation"] and "not a flow" in skipped[0].message


def test_non_finite_output_fails_with_the_channel():
    class Nan(Diff):
        def _encode(self, seq):
            out = super()._encode(seq)
            out[-1, 1, 0, 0] = np.nan
            return out

    assert "non-finite" in failures(Nan())["finite-in-range"]


def test_out_of_range_output_names_the_channel():
    class Loud(Diff):
        def _encode(self, seq):
            out = super()._encode(seq)
            out[:, 1] *= 3
            return out

    assert "channel 'diff'" in failures(Loud())["finite-in-range"]


def test_nondeterminism_is_caught():
    class Noisy(Diff):
        def _encode(self, seq):
            noise = np.random.default_rng().uniform(0, 1e-3, seq.shape).astype(np.float32)
            return np.stack([seq, np.clip(seq - previous_frames(seq) + noise, -1, 1)], axis=1)

    assert "differ" in failures(Noisy())["deterministic"]


def test_an_encoder_using_more_than_two_frames_fails_pairwise():
    class Cumulative(Diff):
        channels = ("pressure", "sum")
        ranges = ((0.0, 1.0), (0.0, 1.0))

        def _encode(self, seq):
            total = np.cumsum(seq, axis=0) / seq.shape[0]
            return np.stack([seq, total], axis=1).astype(np.float32)

    failed = failures(Cumulative())
    assert "pairwise" in failed and "frame" in failed["pairwise"]


def test_an_encoder_that_repairs_nan_fails_bad_input():
    class Lenient(Diff):
        def encode(self, seq):
            return super().encode(np.nan_to_num(np.asarray(seq, np.float32)).clip(0, 1))

    assert "NaN: accepted" in failures(Lenient())["bad-input"]


def test_flow_encoders_must_see_motion_in_the_right_direction_and_size():
    # Shift claims every change is a move of (u, v): right for one of the three
    # test directions at most, and only when the size is right.
    assert "turn" in failures(Shift(u=-2.0))["translation"]
    assert "turn" in failures(Shift(u=2.0))["translation"]       # right, but not down
    too_slow = failures(Shift(u=0.0, v=0.2))
    assert "translation" in too_slow
    assert "identical-frames" not in too_slow                    # still frames are still


def test_check_encoder_lists_every_failure():
    class Loud(Diff):
        def _encode(self, seq):
            return super()._encode(seq) * 3

    with pytest.raises(AssertionError, match="finite-in-range"):
        check_encoder(Loud())


def test_specs_classes_and_instances_are_accepted():
    assert all(r.passed for r in run_checks("raw"))
    assert all(r.passed for r in run_checks(Diff))
    with pytest.raises(ValueError, match="unknown check"):
        run_check(Diff(), "nonsense")


def test_conformance_cases_make_readable_ids():
    params = conformance_cases(["raw", Diff()], checks=["contract", "pairwise"])
    assert [p.id for p in params] == ["raw-contract", "raw-pairwise", "diff-contract",
                                      "diff-pairwise"]


@pytest.mark.parametrize("encoder, check", conformance_cases(["dis"]))
def test_the_pytest_helper_runs_each_check(encoder, check):
    run_check(encoder, check)
