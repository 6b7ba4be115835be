"""Stiff and extreme inputs for every encoder: pass or fail, with the reason.

Every case runs on every encoder. A case either expects a result or expects
the shared input policy's ``ValueError`` (see :mod:`tactbench.encoders.base`:
NaN/Inf and values outside [0, 1] are rejected, never repaired). A case with a
result *passes* when the output

- has shape ``(T, C, H, W)`` and dtype float32,
- is finite and inside every channel's declared range,
- is bit-identical when encoded a second time (deterministic),
- meets the case's documented expectation (below), where it has one.

Documented expectations (flow encoders as :func:`tactbench.encoders.flow.is_flow_encoder`
defines them; ``pressure`` channels must equal the input):

================  ==============================================================
all-zero          every frame the same; pressure, magnitude, direction 0
constant / 1.0    frames after the first: no motion (magnitude, direction 0)
hot pixel         frames after the first: no motion (the pixel does not move)
checkerboard      only the generic conditions (aliased, no true flow exists)
huge motion       magnitude saturates at most at 1 (clipped, not wrapped)
sub-pixel         measured speed below 0.25 px/frame
tiny images       generic conditions; 1 × 1 has no motion
T = 1, T = 1000   generic conditions
dtypes            same output as the float32 values (uint scaled by its maximum)
NaN, Inf, far     ``ValueError`` naming the problem
================  ==============================================================
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from tactbench.contracts import ENCODER
from tactbench.encoders.flow import is_flow_encoder
from tactbench.encoders.evaluation.conformance import contact_sequence
from tactbench.errors import InputError

RANGE_ATOL = 1e-6


@dataclass(frozen=True)
class Case:
    """One input: ``make()`` builds it; ``expect_error`` or ``expect(encoder, seq, out)``."""

    name: str
    description: str
    make: Callable[[], Any]
    expect: Callable[[Any, Any, np.ndarray], str | None] | None = None
    expect_error: bool = False
    reference: Callable[[Any], np.ndarray] | None = None  # float32 input with the same meaning


@dataclass(frozen=True)
class Outcome:
    """One case × encoder."""

    case: str
    encoder: str
    passed: bool
    reason: str
    seconds: float

    def to_dict(self) -> dict[str, Any]:
        return {"case": self.case, "encoder": self.encoder, "passed": self.passed,
                "reason": self.reason, "seconds": round(self.seconds, 4)}


# ----------------------------------------------------------------------------- expectations


def _channel(encoder: Any, out: np.ndarray, name: str) -> np.ndarray:
    """Channel ``name`` of ``out`` ``(T, C, H, W)``: ``(T, H, W)``."""
    return out[:, list(encoder.channels).index(name)]


def _all_zero(encoder: Any, seq: Any, out: np.ndarray) -> str | None:
    spread = float(np.abs(out - out[:1]).max())
    if spread > 0:
        return f"every pair is (0, 0), yet frames differ by up to {spread:.3g}"
    if is_flow_encoder(encoder):
        for name in ("magnitude", "direction"):
            top = float(np.abs(_channel(encoder, out, name)).max())
            if top > 0:
                return f"expected {name} 0 for blank input, got up to {top:.3g}"
    return None


def _still_after_first(encoder: Any, seq: Any, out: np.ndarray) -> str | None:
    if not is_flow_encoder(encoder):
        return None
    mag = _channel(encoder, out, "magnitude")[1:]
    direction = _channel(encoder, out, "direction")[1:]
    scale = encoder.max_flow  # px/frame at magnitude 1
    if mag.size and mag.max() * scale > 0.02:
        return f"no motion expected after frame 0, magnitude reached {mag.max() * scale:.3g} px/frame"
    if direction.size and np.abs(direction).max() > 0:
        return "no motion expected after frame 0, but direction is non-zero"
    return None


def _saturates(encoder: Any, seq: Any, out: np.ndarray) -> str | None:
    if not is_flow_encoder(encoder):
        return None
    mag = _channel(encoder, out, "magnitude")
    return None if mag.max() <= 1.0 else f"magnitude {mag.max():.3g} above 1"


def _sub_pixel(encoder: Any, seq: Any, out: np.ndarray) -> str | None:
    if not is_flow_encoder(encoder):
        return None
    mag = _channel(encoder, out, "magnitude")[1:] * encoder.max_flow
    return None if mag.max() < 0.25 else (
        f"a 0.01 px/frame move was measured at up to {mag.max():.3g} px/frame")


def _one_pixel(encoder: Any, seq: Any, out: np.ndarray) -> str | None:
    if np.asarray(seq).shape[1:] != (1, 1) or not is_flow_encoder(encoder):
        return None
    mag = _channel(encoder, out, "magnitude")
    return None if mag.max() == 0 else "a 1 × 1 image cannot show motion, magnitude is not 0"


# ----------------------------------------------------------------------------- cases


def _checkerboard(shape=(32, 32), frames=4) -> np.ndarray:
    ys, xs = np.mgrid[0:shape[0], 0:shape[1]]
    board = ((ys + xs) % 2).astype(np.float32)
    return np.stack([board if k % 2 == 0 else 1.0 - board for k in range(frames)])


def _hot_pixel(shape=(32, 32), frames=4) -> np.ndarray:
    seq = np.zeros((frames, *shape), dtype=np.float32)
    seq[:, shape[0] // 2, shape[1] // 3] = 1.0
    return seq


def _with(value: float, at: tuple[int, int, int]) -> Callable[[], np.ndarray]:
    def make() -> np.ndarray:
        seq = contact_sequence((24, 24), 3, shift=1.0)
        seq[at] = value
        return seq
    return make


def _tiny(size: int) -> Callable[[], np.ndarray]:
    def make() -> np.ndarray:
        rng = np.random.default_rng(size)
        return rng.uniform(0, 1, size=(4, size, size)).astype(np.float32)
    return make


def _as_dtype(dtype) -> tuple[Callable[[], np.ndarray], Callable[[Any], np.ndarray]]:
    def make() -> np.ndarray:
        seq = contact_sequence((24, 24), 3, shift=1.0)
        if np.issubdtype(dtype, np.integer):
            return np.rint(seq * np.iinfo(dtype).max).astype(dtype)
        return seq.astype(dtype)

    def reference(arr: Any) -> np.ndarray:
        if np.issubdtype(arr.dtype, np.integer):
            return (arr.astype(np.float64) / np.iinfo(arr.dtype).max).astype(np.float32)
        return arr.astype(np.float32)
    return make, reference


def default_cases() -> list[Case]:
    """Every case of ``tactbench stability``, in order."""
    cases = [
        Case("all-zero", "5 blank 32×32 frames",
             lambda: np.zeros((5, 32, 32), np.float32), _all_zero),
        Case("constant", "5 frames of 0.5 everywhere",
             lambda: np.full((5, 32, 32), 0.5, np.float32), _still_after_first),
        Case("saturated", "5 frames of 1.0 everywhere",
             lambda: np.ones((5, 32, 32), np.float32), _still_after_first),
        Case("hot-pixel", "one pixel at 1.0 in 32×32 zeros, 4 frames",
             _hot_pixel, _still_after_first),
        Case("checkerboard", "1-px checkerboard inverting every frame", _checkerboard),
        Case("nan", "one NaN in a contact sequence", _with(math.nan, (1, 5, 5)),
             expect_error=True),
        Case("inf", "one +Inf in a contact sequence", _with(math.inf, (2, 7, 3)),
             expect_error=True),
        Case("huge-motion", "contacts moving 40 px/frame in 128×128",
             lambda: contact_sequence((128, 128), 3, shift=40.0, angle=0.3), _saturates),
        Case("sub-pixel", "contacts moving 0.01 px/frame",
             lambda: contact_sequence((32, 32), 4, shift=0.01, angle=1.0), _sub_pixel),
    ]
    for size in (1, 2, 3, 8):
        cases.append(Case(f"tiny-{size}x{size}", f"4 random {size}×{size} frames", _tiny(size),
                          _one_pixel))
    cases += [
        Case("t1", "a single 32×32 frame", lambda: contact_sequence((32, 32), 1)),
        Case("t1000", "1000 frames of 16×16, contacts moving 0.05 px/frame",
             lambda: contact_sequence((16, 16), 1000, shift=0.05, sigma=2.0)),
    ]
    for dtype in (np.uint8, np.uint16, np.float16, np.float64):
        make, reference = _as_dtype(dtype)
        cases.append(Case(f"dtype-{np.dtype(dtype).name}", f"{np.dtype(dtype).name} input",
                          make, reference=reference))
    cases += [
        Case("far-above", "values up to 255 (unnormalised float)",
             lambda: contact_sequence((24, 24), 3, shift=1.0) * 255.0, expect_error=True),
        Case("far-below", "values down to -3",
             lambda: contact_sequence((24, 24), 3, shift=1.0) * 4.0 - 3.0, expect_error=True),
    ]
    return cases


def select_cases(names: Sequence[str] = ()) -> list[Case]:
    """The cases called ``names``, in that order (all of :func:`default_cases` when empty);
    an unknown name is an :class:`~tactbench.errors.InputError` listing the known ones."""
    cases = default_cases()
    if not names:
        return cases
    known = {c.name: c for c in cases}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise InputError(f"unknown case(s) {', '.join(unknown)}; cases: {', '.join(known)}")
    return [known[n] for n in names]


# ----------------------------------------------------------------------------- running


def run_case(encoder: Any, case: Case, label: str = "") -> Outcome:
    """Run one case on one encoder; never raises for the encoder's failures."""
    label = label or ENCODER.get(encoder, "name") or type(encoder).__name__
    seq = case.make()
    t0 = time.perf_counter()
    try:
        out = encoder.encode(seq)
    except ValueError as exc:
        dt = time.perf_counter() - t0
        if case.expect_error:
            return Outcome(case.name, label, True, f"ValueError as documented: {exc}", dt)
        return Outcome(case.name, label, False, f"unexpected ValueError: {exc}", dt)
    except Exception as exc:  # any other crash is a failure, with its type
        return Outcome(case.name, label, False, f"{type(exc).__name__}: {exc}",
                       time.perf_counter() - t0)
    dt = time.perf_counter() - t0
    if case.expect_error:
        return Outcome(case.name, label, False, "accepted; the policy says ValueError", dt)
    problem = _generic_problem(encoder, seq, out)
    if problem is None:
        again = encoder.encode(seq)
        if not np.array_equal(out, again):
            problem = (f"not deterministic: a second run differs by up to "
                       f"{np.abs(out - again).max():.3g}")
    if problem is None and case.reference is not None:
        ref = encoder.encode(case.reference(seq))
        if not np.array_equal(out, ref):
            problem = (f"differs from the same values as float32 by up to "
                       f"{np.abs(out - ref).max():.3g}")
    if problem is None and case.expect is not None:
        problem = case.expect(encoder, seq, out)
    if problem is not None:
        return Outcome(case.name, label, False, problem, dt)
    what = "finite, in range, deterministic"
    if case.reference is not None:
        what += ", same as float32"
    elif case.expect is not None:
        what += ", as documented"
    return Outcome(case.name, label, True, what, dt)


def _generic_problem(encoder: Any, seq: Any, out: Any) -> str | None:
    arr = np.asarray(seq)
    channels = list(encoder.channels)
    expected = (arr.shape[0], len(channels), *arr.shape[1:])
    if not isinstance(out, np.ndarray) or out.shape != expected:
        return f"output shape {getattr(out, 'shape', None)}, expected {expected}"
    if out.dtype != np.float32:
        return f"output dtype {out.dtype}, expected float32"
    if not np.isfinite(out).all():
        bad = np.argwhere(~np.isfinite(out))[0]
        return (f"{int((~np.isfinite(out)).sum())} non-finite output value(s), first in "
                f"channel '{channels[bad[1]]}' at frame {bad[0]}")
    for i, (name, (lo, hi)) in enumerate(zip(channels, ENCODER.get(encoder, "ranges"))):
        v = out[:, i]
        if v.min() < lo - RANGE_ATOL or v.max() > hi + RANGE_ATOL:
            return f"channel '{name}' spans [{v.min():.6g}, {v.max():.6g}], declared [{lo}, {hi}]"
    if "pressure" in channels and np.issubdtype(arr.dtype, np.floating):
        diff = np.abs(out[:, channels.index("pressure")] - arr.astype(np.float32)).max()
        if diff > RANGE_ATOL:
            return f"pressure channel differs from the input by {diff:.3g}"
    return None


def run_stability(encoders: Sequence[tuple[str, Any]], cases: Sequence[Case] | None = None, *,
                  progress: Callable[..., None] | None = None) -> list[Outcome]:
    """Every case on every ``(label, encoder)``; one :class:`Outcome` each.

    ``progress(done, total, item=...)`` is called before each case (``item`` names the
    encoder and case) and once at the end.
    """
    cases = list(default_cases() if cases is None else cases)
    total = len(cases) * len(encoders)
    outcomes = []
    for j, (label, enc) in enumerate(encoders):
        for i, case in enumerate(cases):
            if progress:
                progress(j * len(cases) + i, total, item=f"{label}: {case.name}")
            outcomes.append(run_case(enc, case, label))
    if progress:
        progress(total, total, item="done")
    return outcomes
