"""A plugin's output checked at the boundary, at run time: what it returns, not only
what it has.

:mod:`tactbench.contracts` checks a component's members when it is built; this module
checks what its methods *return*, each time the runner takes it, cheaply (one pass over
the array: shape, dtype, ``isfinite``, min and max):

- an encoder's output of one sequence: an ndarray of the expected shape
  (``(T, C, H, W)`` images, ``(T, C·N)`` taxel vectors) and dtype float32, finite, and
  inside each channel's declared ``ranges`` (within :data:`RANGE_ATOL`);
- a classifier's ``predict_proba``: an ``(n, K)`` array, finite, non-negative, each row
  summing to 1 within :data:`PROBA_ATOL`; its ``predict``: ``n`` whole numbers in
  ``0 .. K-1``.

A violation is a :class:`BoundaryError` naming the plugin, the component and the rule;
the runner turns it into a *failed cell* (never a score). The conformance suites of
:mod:`tactbench.testing` check the same rules with the same functions, so a plugin
author meets them before users do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Sequence

from tactbench.errors import PluginError

if TYPE_CHECKING:
    import numpy as np

#: How far outside its declared range an encoder's value may lie: float rounding, and at
#: run time (on data the conformance inputs do not cover) a thousandth of the range.
RANGE_ATOL, RANGE_RTOL = 1e-6, 1e-3
#: How far from 1 a row of probabilities may sum.
PROBA_ATOL = 1e-3


class BoundaryError(PluginError):
    """A plugin's component returned something its contract rules out (at run time).
    Made by :meth:`of`; its text names the kind, component, plugin and rule."""

    @classmethod
    def of(cls, kind: str, component: str, plugin: str, rule: str) -> "BoundaryError":
        where = f" (plugin '{plugin}')" if plugin else ""
        return cls(f"{kind} '{component}'{where} broke the {kind} contract at run time: "
                   f"{rule}; no score is given for it")


#: The ``meta.json`` field of a cache entry whose encoder's output broke its contract
#: (the :class:`BoundaryError`'s text): its cells fail naming it, and the next run
#: encodes it again.
VIOLATION_FIELD = "boundary_violation"


def _shape(shape: Sequence[int]) -> str:
    return "(" + ", ".join(str(int(n)) for n in shape) + ("," if len(shape) == 1 else "") + ")"


def encoder_output_problem(out: Any, shape: Sequence[int],
                           ranges: Sequence[Sequence[float]] = (), *,
                           rtol: float = RANGE_RTOL) -> str | None:
    """What is wrong with ``out`` as an encoder's output of expected ``shape``, or None.

    ``ranges``: the encoder's declared ``(low, high)`` per channel (axis 1 of ``shape``);
    for taxel vectors ``(T, C·N)`` give one pair spanning every channel, or none."""
    import numpy as np

    if not isinstance(out, np.ndarray):
        return f"its output is a {type(out).__name__}, not a numpy array"
    if tuple(out.shape) != tuple(shape):
        return f"its output has shape {_shape(out.shape)}, expected {_shape(shape)}"
    if out.dtype != np.float32:
        return f"its output has dtype {out.dtype}, expected float32"
    if out.size == 0:
        return None
    finite = np.isfinite(out)
    if not finite.all():
        bad = int(out.size - np.count_nonzero(finite))
        return f"its output holds {bad} NaN or infinite values of {out.size}"
    if not ranges:
        return None
    per_channel = out.reshape(out.shape[0], -1) if len(ranges) == 1 or out.ndim < 3 \
        else None
    for c, (low, high) in enumerate(ranges):
        values = per_channel if per_channel is not None else out[:, c]
        lo, hi = float(values.min()), float(values.max())
        slack = RANGE_ATOL + rtol * (float(high) - float(low))
        if lo < low - slack or hi > high + slack:
            return (f"channel {c} spans [{lo:.6g}, {hi:.6g}], outside its declared range "
                    f"[{low:g}, {high:g}]")
        if per_channel is not None:
            break
    return None


def proba_problem(proba: Any, n: int, k: int) -> str | None:
    """What is wrong with ``proba`` as ``predict_proba`` of ``n`` windows and ``k``
    classes, or None: shape ``(n, k)``, finite, non-negative, rows summing to 1."""
    import numpy as np

    arr = np.asarray(proba) if isinstance(proba, np.ndarray) or hasattr(proba, "__array__") \
        else None
    if arr is None:
        return f"predict_proba returned a {type(proba).__name__}, not an array"
    if arr.shape != (n, k):
        return f"predict_proba gave shape {_shape(arr.shape)}, expected ({n}, {k})"
    if arr.dtype.kind not in "fiu":
        return f"predict_proba gave dtype {arr.dtype}, not numbers"
    if arr.size == 0:
        return None
    arr = arr.astype(np.float64, copy=False)
    if not np.isfinite(arr).all():
        return "predict_proba gave NaN or infinite probabilities"
    if float(arr.min()) < 0.0:
        return f"predict_proba gave a negative probability ({float(arr.min()):.3g})"
    sums = arr.sum(axis=1)
    worst = int(np.argmax(np.abs(sums - 1.0)))
    if abs(float(sums[worst]) - 1.0) > PROBA_ATOL:
        return f"predict_proba's row {worst} sums to {float(sums[worst]):.6g}, not 1"
    return None


def labels_problem(labels: Any, n: int, k: int) -> str | None:
    """What is wrong with ``labels`` as ``predict`` of ``n`` windows and ``k`` classes,
    or None: ``n`` whole numbers in ``0 .. k-1``."""
    import numpy as np

    arr = np.asarray(labels)
    if arr.shape != (n,):
        return f"predict gave shape {_shape(arr.shape)}, expected ({n},)"
    if arr.size == 0:
        return None
    if arr.dtype.kind not in "iu":
        if arr.dtype.kind != "f" or not np.isfinite(arr).all() \
                or not np.array_equal(arr, np.round(arr)):
            return f"predict gave {arr.dtype} values that are not class numbers"
    lo, hi = int(arr.min()), int(arr.max())
    if lo < 0 or hi >= k:
        return f"predict gave class {lo if lo < 0 else hi}, outside 0..{k - 1}"
    return None


def check_proba(proba: Any, n: int, k: int, *, component: str, plugin: str) -> "np.ndarray":
    """``proba`` as float64 ``(n, k)`` when :func:`proba_problem` finds nothing, else
    :class:`BoundaryError`."""
    import numpy as np

    problem = proba_problem(proba, n, k)
    if problem is not None:
        raise BoundaryError.of("classifier", component, plugin, problem)
    return np.asarray(proba, dtype=np.float64)


def check_labels(labels: Any, n: int, k: int, *, component: str, plugin: str
                 ) -> "np.ndarray":
    """``labels`` as int64 ``(n,)`` when :func:`labels_problem` finds nothing, else
    :class:`BoundaryError`."""
    import numpy as np

    problem = labels_problem(labels, n, k)
    if problem is not None:
        raise BoundaryError.of("classifier", component, plugin, problem)
    return np.asarray(labels).astype(np.int64)


class EncoderGuard:
    """A sink of the encoding pass that checks each encoded sequence first.

    The first sequence that breaks :func:`encoder_output_problem` records
    :attr:`violation` (the :class:`BoundaryError`'s text); it and every later one go to
    ``sink`` as zeros of the expected shape, so the entry is completed and marked (the
    runner records the violation in its metadata; its cells fail naming it, and the
    entry is encoded again next run) while the other encoders of the pass go on.
    """

    def __init__(self, sink: Callable[["np.ndarray"], None], lengths: Sequence[int],
                 frame_shape: Sequence[int], *, ranges: Sequence[Sequence[float]] = (),
                 component: str, plugin: str) -> None:
        self.sink, self.lengths, self.frame_shape = sink, list(lengths), tuple(frame_shape)
        self.ranges, self.component, self.plugin = tuple(ranges), component, plugin
        self.done = 0
        self.violation: str | None = None

    def __call__(self, seq: Any) -> None:
        import numpy as np

        index, self.done = self.done, self.done + 1
        shape = (self.lengths[index], *self.frame_shape)
        if self.violation is None:
            problem = encoder_output_problem(seq, shape, self.ranges)
            if problem is not None:
                self.violation = str(BoundaryError.of("encoder", self.component, self.plugin,
                                                   f"on sample {index}, {problem}"))
        self.sink(np.zeros(shape, np.float32) if self.violation is not None else seq)
