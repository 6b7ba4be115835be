"""Conformance suite for encoders: one set of checks for built-ins and plugins alike.

Run it on any encoder (an instance, a factory, or a registered spec such as
``"farneback:winsize=9"``)::

    from tactbench.testing import check_encoder
    check_encoder("my-encoder")          # raises AssertionError listing failures

or, in a plugin's test suite, one pytest test per check::

    import pytest
    from tactbench.testing import conformance_cases, run_check

    @pytest.mark.parametrize("encoder, check", conformance_cases(["my-encoder"]))
    def test_conformance(encoder, check):
        run_check(encoder, check)

The checks (see :data:`CHECKS`) follow the encoder contract
(:data:`tactbench.contracts.ENCODER`) and the input policy of
:mod:`tactbench.encoders.base`: float32 ``(T, H, W)`` in [0, 1] → float32
``(T, C, H, W)``, finite, each channel in its declared range, deterministic,
frame ``k`` computed from ``I_k`` and ``I_{k-1}`` only with ``I_{-1} = 0``, bad
input rejected with ``ValueError``. *Flow encoders*
(:func:`tactbench.encoders.flow.is_flow_encoder`) must also give zero flow
between identical frames and recover a known translation (direction within
0.05 of a turn, speed within 35 % through their ``max_flow`` scale). Checks that
do not apply are skipped, with the reason. Images are small (≤ 48 × 48) so the
whole suite takes seconds.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable

import numpy as np

from tactbench.boundary import encoder_output_problem
from tactbench.contracts import ENCODER
from tactbench.encoders.flow import is_flow_encoder
from tactbench.errors import InputError
from tactbench.plugins import load_registry

#: Tolerance for comparing outputs computed in different batches (float32 noise).
BATCH_ATOL = 1e-4
#: Tolerance on declared channel ranges.
RANGE_ATOL = 1e-6


#: Why the flow checks are skipped for an encoder that is not a flow encoder.
NOT_FLOW = ("not a flow encoder (tactbench.encoders.flow.is_flow_encoder: magnitude and "
            "direction channels, flow(prev, curr), max_flow and min_magnitude)")


class NotApplicable(Exception):
    """Raised by a check that does not apply to this encoder (reported as skipped)."""


@dataclass(frozen=True)
class CheckResult:
    """The outcome of one check on one encoder."""

    check: str
    status: str  # "passed", "failed" or "skipped"
    message: str = ""

    @property
    def passed(self) -> bool:
        return self.status != "failed"


# ----------------------------------------------------------------------------- inputs


def contact_sequence(shape: tuple[int, int] = (32, 32), frames: int = 4, *,
                     shift: float = 0.0, angle: float = 0.0, sigma: float = 3.5,
                     seed: int = 0) -> np.ndarray:
    """Float32 ``(frames, H, W)`` in [0, 1]: two Gaussian contacts moving together.

    Each frame moves them by ``shift`` px in direction ``angle`` (radians,
    image coordinates: 0 = +x, π/2 = +y down). ``seed`` places them.
    """
    h, w = shape
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    centres = [(h * rng.uniform(0.35, 0.45), w * rng.uniform(0.3, 0.4)),
               (h * rng.uniform(0.55, 0.65), w * rng.uniform(0.6, 0.7))]
    amps = rng.uniform(0.6, 0.9, size=2)
    out = np.empty((frames, h, w), dtype=np.float32)
    for k in range(frames):
        dy, dx = k * shift * math.sin(angle), k * shift * math.cos(angle)
        rest = np.ones((h, w))
        for (cy, cx), a in zip(centres, amps):
            rest *= 1 - a * np.exp(-((ys - cy - dy) ** 2 + (xs - cx - dx) ** 2) / (2 * sigma ** 2))
        out[k] = 1 - rest
    return out


# ----------------------------------------------------------------------------- checks


def _encode(encoder: Any, seq: np.ndarray) -> np.ndarray:
    out = encoder.encode(seq)
    assert isinstance(out, np.ndarray), f"encode returned {type(out).__name__}, not an ndarray"
    return out


def check_contract(encoder: Any) -> None:
    """The encoder contract (:data:`tactbench.contracts.ENCODER`) holds; declared ranges
    are finite, one per channel; ``options()`` is JSON; ``version`` is a string."""
    problems = ENCODER.problems(encoder)
    assert not problems, "breaks the encoder contract: " + "; ".join(problems)
    channels = encoder.channels
    ranges = ENCODER.get(encoder, "ranges")
    if ranges:
        assert len(ranges) == len(channels), \
            f"{len(ranges)} ranges for {len(channels)} channels"
        for name, rng in zip(channels, ranges):
            lo, hi = rng
            assert math.isfinite(lo) and math.isfinite(hi) and lo <= hi, \
                f"channel '{name}' has range {rng!r}"
    options = ENCODER.get(encoder, "options")
    if options is not None:
        try:
            json.dumps(options())
        except TypeError as exc:
            raise AssertionError(f"options() must be JSON-serialisable (cache keys): {exc}")
    version = ENCODER.get(encoder, "version")
    assert isinstance(version, str) and version, f"version must be a string, got {version!r}"


def check_shape_dtype(encoder: Any) -> None:
    """Output is float32 ``(T, C, H, W)`` for several T and odd image sizes."""
    c = len(encoder.channels)
    for t, shape in ((1, (32, 32)), (5, (32, 32)), (3, (17, 23))):
        seq = contact_sequence(shape, t, shift=1.0, angle=0.5)
        out = _encode(encoder, seq)
        # the rule the runner applies to every encoded sequence (tactbench.boundary)
        problem = encoder_output_problem(out, (t, c, *shape))
        assert problem is None, f"input {seq.shape}: {problem}"


def check_finite_in_range(encoder: Any) -> None:
    """Every value finite and inside its channel's declared range."""
    ranges = ENCODER.get(encoder, "ranges")
    for seed, shift in ((0, 0.7), (1, 3.0), (2, -2.0)):
        seq = contact_sequence((32, 32), 5, shift=shift, angle=1.0 + seed, seed=seed)
        out = _encode(encoder, seq)
        assert np.isfinite(out).all(), f"non-finite output for a moving contact (seed {seed})"
        if ranges:
            for i, (name, (lo, hi)) in enumerate(zip(encoder.channels, ranges)):
                v = out[:, i]
                assert v.min() >= lo - RANGE_ATOL and v.max() <= hi + RANGE_ATOL, \
                    f"channel '{name}' spans [{v.min():.6g}, {v.max():.6g}], declared [{lo}, {hi}]"
        problem = encoder_output_problem(out, out.shape, ranges, rtol=0.0)  # the runner's
        assert problem is None, f"a moving contact (seed {seed}): {problem}"


def check_deterministic(encoder: Any) -> None:
    """The same input gives bit-identical output, twice and from a copy of the encoder."""
    seq = contact_sequence((32, 32), 5, shift=1.5, angle=2.0)
    first = _encode(encoder, seq)
    again = _encode(encoder, seq.copy())
    assert np.array_equal(first, again), \
        f"two runs differ by up to {np.abs(first - again).max():.3g}"
    twin = copy.deepcopy(encoder)
    other = _encode(twin, seq)
    assert np.array_equal(first, other), \
        f"a copy of the encoder differs by up to {np.abs(first - other).max():.3g}"


def check_zero_previous_frame(encoder: Any) -> None:
    """Frame 0 is computed against an all-zero ``I_{-1}``; an all-zero input is uniform."""
    seq = contact_sequence((32, 32), 3, shift=1.0)
    out = _encode(encoder, seq)
    padded = _encode(encoder, np.concatenate([np.zeros_like(seq[:1]), seq]))
    diff = np.abs(out[0] - padded[1]).max()
    assert diff <= BATCH_ATOL, \
        f"frame 0 differs by {diff:.3g} from the same frame encoded after an explicit zero frame"
    zeros = _encode(encoder, np.zeros((3, 24, 24), dtype=np.float32))
    assert np.isfinite(zeros).all(), "non-finite output for an all-zero sequence"
    spread = np.abs(zeros - zeros[:1]).max()
    assert spread <= BATCH_ATOL, \
        f"an all-zero sequence gave frames differing by {spread:.3g} (every pair is (0, 0))"
    if is_flow_encoder(encoder):
        ch = list(encoder.channels)
        for name in ("magnitude", "direction"):
            top = np.abs(zeros[:, ch.index(name)]).max()
            assert top <= RANGE_ATOL, f"all-zero input gave {name} up to {top:.3g}, expected 0"


def check_pairwise(encoder: Any) -> None:
    """Frame ``k`` depends on ``I_{k-1}`` and ``I_k`` only (same result as a 2-frame input)."""
    seq = contact_sequence((32, 32), 5, shift=1.2, angle=0.3)
    out = _encode(encoder, seq)
    for k in (1, 3):
        pair = _encode(encoder, seq[k - 1:k + 1])[1]
        diff = np.abs(pair - out[k]).max()
        assert diff <= BATCH_ATOL, \
            f"frame {k} differs by {diff:.3g} from encoding (I_{k - 1}, I_{k}) alone"


def check_identical_frames(encoder: Any) -> None:
    """Repeated frames give repeated outputs; for flow encoders, no motion."""
    frame = contact_sequence((32, 32), 1, seed=3)
    out = _encode(encoder, np.repeat(frame, 3, axis=0))
    diff = np.abs(out[1] - out[2]).max()
    assert diff <= BATCH_ATOL, f"two identical frame pairs gave outputs {diff:.3g} apart"
    if is_flow_encoder(encoder):
        ch = list(encoder.channels)
        mag = out[1:, ch.index("magnitude")].max()
        direction = np.abs(out[1:, ch.index("direction")]).max()
        limit = 0.02 / encoder.max_flow  # 0.02 px/frame
        assert mag <= limit, f"identical frames gave magnitude up to {mag:.3g} (limit {limit:.3g})"
        assert direction == 0.0, f"identical frames gave a direction of up to {direction:.3g}"


def check_translation(encoder: Any) -> None:
    """A contact moving 2 px/frame is seen moving that way, about that fast."""
    if not is_flow_encoder(encoder):
        raise NotApplicable(NOT_FLOW)
    ch = list(encoder.channels)
    speed = 2.0
    for angle in (0.0, 0.5 * math.pi, 1.25 * math.pi):
        seq = contact_sequence((48, 48), 3, shift=speed, angle=angle, sigma=4.0)
        out = _encode(encoder, seq)
        mask = np.minimum(seq[1], seq[2]) > 0.3
        direction = out[2, ch.index("direction")][mask]
        expected = angle / (2 * math.pi)
        turn = np.abs((direction - expected + 0.5) % 1.0 - 0.5)  # circular distance
        err = float(np.median(turn))
        assert err <= 0.05, (f"a move at {expected:.3f} turn was seen at a median distance "
                             f"of {err:.3f} turn")
        seen = float(np.median(out[2, ch.index("magnitude")][mask])) * encoder.max_flow
        assert abs(seen - speed) <= 0.35 * speed, \
            f"a {speed} px/frame move was measured at {seen:.2f} px/frame (median)"


def check_bad_input(encoder: Any) -> None:
    """NaN, Inf, wrong rank, empty, out-of-range and signed-integer input → ``ValueError``."""
    good = contact_sequence((16, 16), 3)
    nan = good.copy()
    nan[1, 3, 4] = np.nan
    inf = good.copy()
    inf[2, 0, 0] = np.inf
    cases = {
        "NaN": nan, "+Inf": inf, "-Inf": -inf, "rank 2": good[0], "rank 4": good[None],
        "T = 0": good[:0], "W = 0": good[:, :, :0], "value 2.0": good * 2.0,
        "negative values": good - 0.5, "signed integers": (good * 100).astype(np.int32),
    }
    for label, bad in cases.items():
        try:
            encoder.encode(bad)
        except ValueError:
            continue
        except Exception as exc:  # a crash is not a clear message
            raise AssertionError(f"{label}: raised {type(exc).__name__}: {exc} "
                                 f"instead of ValueError") from exc
        raise AssertionError(f"{label}: accepted; expected ValueError")


def check_input_dtypes(encoder: Any) -> None:
    """uint8/uint16 are scaled by their maximum; float16/float64 are the same values."""
    seq = contact_sequence((24, 24), 3, shift=1.0)
    for dtype in (np.uint8, np.uint16):
        top = np.iinfo(dtype).max
        ints = np.rint(seq * top).astype(dtype)
        got = _encode(encoder, ints)
        want = _encode(encoder, (ints.astype(np.float64) / top).astype(np.float32))
        assert np.array_equal(got, want), f"{np.dtype(dtype).name} input not read as value/{top}"
    for dtype in (np.float16, np.float64):
        cast = seq.astype(dtype)
        got = _encode(encoder, cast)
        want = _encode(encoder, cast.astype(np.float32))
        assert np.array_equal(got, want), f"{np.dtype(dtype).name} input differs from float32"


#: Every check, by name, in the order they run.
CHECKS: dict[str, Callable[[Any], None]] = {
    "contract": check_contract,
    "shape-dtype": check_shape_dtype,
    "finite-in-range": check_finite_in_range,
    "deterministic": check_deterministic,
    "zero-previous-frame": check_zero_previous_frame,
    "pairwise": check_pairwise,
    "identical-frames": check_identical_frames,
    "translation": check_translation,
    "bad-input": check_bad_input,
    "input-dtypes": check_input_dtypes,
}


# ----------------------------------------------------------------------------- running


def build_encoder(encoder: Any) -> Any:
    """An encoder from an instance, a zero-argument factory/class, or a registry spec."""
    if isinstance(encoder, str):
        return load_registry().build("encoder", encoder)
    if isinstance(encoder, type) or (callable(encoder) and not hasattr(encoder, "encode")):
        return encoder()
    return encoder


def run_check(encoder: Any, check: str) -> None:
    """Run one check; raises ``AssertionError`` on failure, ``pytest.skip`` when not applicable."""
    if check not in CHECKS:
        raise InputError(f"unknown check '{check}'; checks: {', '.join(CHECKS)}")
    enc = build_encoder(encoder)
    try:
        CHECKS[check](enc)
    except NotApplicable as exc:
        import pytest

        pytest.skip(f"{check}: {exc}")


def run_checks(encoder: Any, *, skip: Iterable[str] = ()) -> list[CheckResult]:
    """Run every check (but those in ``skip``) and return one result per check."""
    enc = build_encoder(encoder)
    skip = set(skip)
    unknown = skip - set(CHECKS)
    if unknown:
        raise InputError(f"unknown checks to skip: {', '.join(sorted(unknown))}")
    results = []
    for name, fn in CHECKS.items():
        if name in skip:
            results.append(CheckResult(name, "skipped", "skipped on request"))
            continue
        try:
            fn(enc)
        except NotApplicable as exc:
            results.append(CheckResult(name, "skipped", str(exc)))
        except AssertionError as exc:
            results.append(CheckResult(name, "failed", str(exc) or "assertion failed"))
        except Exception as exc:  # a crash inside a check is a failure, with its type
            results.append(CheckResult(name, "failed", f"{type(exc).__name__}: {exc}"))
        else:
            results.append(CheckResult(name, "passed"))
    return results


def check_encoder(encoder: Any, *, skip: Iterable[str] = ()) -> list[CheckResult]:
    """Run the whole suite; raise ``AssertionError`` naming every failed check."""
    results = run_checks(encoder, skip=skip)
    failed = [r for r in results if r.status == "failed"]
    if failed:
        label = encoder if isinstance(encoder, str) else type(build_encoder(encoder)).__name__
        lines = "\n".join(f"  {r.check}: {r.message}" for r in failed)
        raise AssertionError(f"encoder {label} failed {len(failed)} conformance "
                             f"check(s):\n{lines}")
    return results


def conformance_cases(encoders: Iterable[Any], checks: Iterable[str] | None = None) -> list:
    """``pytest.param(encoder, check)`` for every encoder × check, with readable ids.

    Use with ``@pytest.mark.parametrize("encoder, check", conformance_cases([...]))``
    and :func:`run_check` in the test body.
    """
    import pytest

    names = list(CHECKS) if checks is None else list(checks)
    params = []
    for enc in encoders:
        label = enc if isinstance(enc, str) else ENCODER.get(enc, "name") or _class_name(enc)
        for name in names:
            params.append(pytest.param(enc, name, id=f"{label}-{name}"))
    return params


def _class_name(encoder: Any) -> str:
    """A label for an encoder instance (its class), class or factory (its name)."""
    if isinstance(encoder, type) or not hasattr(encoder, "encode"):
        return getattr(encoder, "__name__", type(encoder).__name__)
    return type(encoder).__name__
