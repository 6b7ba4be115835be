"""Exceptions tactbench raises on purpose, and the shared checks that raise them.

A :class:`TactbenchError` is a mistake the user can fix (a bad option, file, shape or
name); the CLI prints it as one line and exits with status 2. Any other exception is a
bug and keeps its traceback. The user-error classes also subclass the built-in exception
a Python caller would expect (``ValueError``, ``FileNotFoundError``, ``LookupError``), so
``except ValueError`` keeps working.
"""

from __future__ import annotations

import difflib
import importlib
import math
import numbers
from typing import Any


class TactbenchError(Exception):
    """Base class: something the user can fix (bad input, bad name, broken plugin)."""


class InputError(TactbenchError, ValueError):
    """A value, option, shape or file content is not what tactbench accepts."""


class MissingFileError(TactbenchError, FileNotFoundError):
    """A file or folder the user named does not exist."""


class PluginError(TactbenchError):
    """A plugin failed to load or registered something invalid (fatal in strict mode)."""


class ContractError(PluginError, TypeError):
    """A built component does not satisfy the contract of its kind (see contracts.py)."""


class UnknownComponentError(TactbenchError, LookupError):
    """No component of that kind and name is registered."""

    def __str__(self) -> str:  # LookupError would quote the message
        return str(self.args[0]) if self.args else ""


class ComponentLoadError(TactbenchError):
    """A component's target did not import, or its requirements are missing."""


class WorkerError(TactbenchError):
    """Worker processes could not start here, or died while cells ran (the cause and
    the fix are in the message; finished cells are stored)."""


# ----------------------------------------------------------------------------- checks


def is_finite_number(value: Any) -> bool:
    """Whether ``value`` is a finite int or float (a bool is not a number here)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def check_positive_int(value: Any, name: str, *, minimum: int = 1,
                       maximum: int | None = None) -> int:
    """``value`` as an ``int`` in [``minimum``, ``maximum``]; bools, floats with a
    fraction, NaN, infinities and text refused."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if isinstance(value, numbers.Real) and not isinstance(value, bool) \
                and math.isfinite(float(value)) and float(value).is_integer():
            value = int(value)
        else:
            raise InputError(f"{name} must be an integer ≥ {minimum}, got {value!r}")
    if int(value) < minimum:
        raise InputError(f"{name} must be ≥ {minimum}, got {value}")
    if maximum is not None and int(value) > maximum:
        raise InputError(f"{name} must be ≤ {maximum}, got {_short(value)}")
    return int(value)


def check_positive_float(value: Any, name: str, *, allow_zero: bool = False,
                         maximum: float | None = None) -> float:
    """``value`` as a finite ``float`` > 0 (≥ 0 with ``allow_zero``), ≤ ``maximum``."""
    return check_number(value, name, minimum=0.0, exclusive_minimum=not allow_zero,
                        maximum=maximum)


def check_number(value: Any, name: str, *, minimum: float | None = None,
                 maximum: float | None = None, exclusive_minimum: bool = False,
                 integer: bool = False) -> float:
    """The one check of a number a user gives (an option, a CLI value, a file field),
    against its meaning, before any work: a real number (not a bool or text), finite
    (NaN never compares, so an unchecked NaN timeout never ends), within
    [``minimum``, ``maximum``] (``exclusive_minimum``: above ``minimum``), and with
    ``integer`` a whole number. Returns it as a ``float`` (an ``int`` with ``integer``).
    Bounds that follow from the data (a window no larger than the image) are checked
    where the data is known, with :func:`check_at_most`.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{name} must be a finite number, got {str(value)[:40]!r}")
    if isinstance(value, numbers.Integral):
        number = float(value) if abs(int(value)) < 2 ** 1023 else math.copysign(math.inf,
                                                                                   int(value))
    else:
        number = float(value)
    if not math.isfinite(number):
        raise InputError(f"{name} must be a finite number, got {_short(value)}")
    if integer and not number.is_integer():
        raise InputError(f"{name} must be a whole number, got {value!r}")
    if minimum is not None and (number < minimum or exclusive_minimum and number == minimum):
        raise InputError(f"{name} must be {'>' if exclusive_minimum else '≥'} {minimum:g}, "
                         f"got {_short(value)}")
    if maximum is not None and number > maximum:
        raise InputError(f"{name} must be ≤ {maximum:g}, got {_short(value)}")
    return int(number) if integer else number


def check_at_most(value: float, limit: float, name: str, what: str) -> None:
    """Refuse ``value`` above a bound that follows from the input, naming both:
    ``winsize 99999 is larger than the image (32×28 px)``."""
    if value > limit:
        raise InputError(f"{name} {_short(value)} is larger than {what}")


def _short(value: Any) -> str:
    """A number as a user wrote it, shortened (a 5000-digit integer is not echoed)."""
    text = repr(value)
    if len(text) > 30:
        text = f"{float(value):.6g}" if abs(float(value)) < 1e308 else text[:12] + "…"
    return text


def check_choice(value: Any, name: str, choices: "tuple[str, ...] | list[str]") -> str:
    """``value`` if it is one of ``choices``; else an error listing them (closest first)."""
    if value in choices:
        return value

    close = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1)
    hint = f"; did you mean '{close[0]}'?" if close else "."
    raise InputError(f"unknown {name} {value!r}{hint} Choices: {', '.join(map(str, choices))}")


def check_shape(arr: Any, dims: str, name: str = "array", *, dtype_kind: str | None = None,
                **sizes: int) -> None:
    """Check an array's rank (and named sizes) against a shape written as ``"T H W"``.

    ``check_shape(x, "T C H W", "encoded", C=3)`` raises :class:`InputError` saying
    what was expected and what came: ``encoded must be (T, C=3, H, W), got (5, 2, 8, 8)``.
    ``dtype_kind`` (numpy kind letters, e.g. ``"fiu"``) also checks the element type.
    """
    names = dims.split()
    shape = getattr(arr, "shape", None)
    want = "(" + ", ".join(f"{d}={sizes[d]}" if d in sizes else d for d in names) + ")"
    if shape is None:
        raise InputError(f"{name} must be an array {want}, got {type(arr).__name__}")
    if len(shape) != len(names) or any(shape[names.index(d)] != n for d, n in sizes.items()):
        raise InputError(f"{name} must be {want}, got {tuple(shape)}")
    if dtype_kind is not None and arr.dtype.kind not in dtype_kind:
        raise InputError(f"{name} must hold numbers, got dtype {arr.dtype}")


class CorruptArtefactError(TactbenchError):
    """Something tactbench stored (cache entry, cell row, model, dataset folder) failed
    its verification when read back: its checksum, identity or shapes do not match.

    ``artefact`` names what was read (a path); ``problem`` says what is wrong. Readers of
    artefacts tactbench can rebuild catch it and rebuild; the others let it reach the
    user as one line.
    """

    def __init__(self, artefact: Any, problem: str) -> None:
        self.artefact = str(artefact)
        self.problem = problem
        super().__init__(f"{self.artefact}: {problem}")

    def __reduce__(self):  # rebuilt from (artefact, problem) in a worker's parent process
        return (type(self), (self.artefact, self.problem))


class StorageError(TactbenchError, OSError):
    """The disk refused a write tactbench had to make (full, over quota, read-only): one
    line naming the file; nothing half-written is left under the final name."""


#: errno values that mean "the disk will not take it", whoever asked.
STORAGE_ERRNOS = (28, 122, 30)  # ENOSPC, EDQUOT, EROFS


def storage_error(exc: OSError, path: Any) -> StorageError | None:
    """A :class:`StorageError` for ``exc`` when it is the disk's refusal, else None."""
    if getattr(exc, "errno", None) in STORAGE_ERRNOS:
        return StorageError(f"cannot write {path}: {exc.strerror or exc}; free space "
                            f"(or choose another folder) and run again")
    return None


class BudgetError(InputError):
    """A step would need more memory than the budget allows (see tactbench.integrity)."""


class MissingExtraError(TactbenchError, ImportError):
    """A library of an optional extra is not installed (pandas for a data frame): one line
    naming it and the ``pip install`` that brings it."""


def require(module: str, extra: str) -> Any:
    """The module ``module``, imported; :class:`MissingExtraError` naming the extra
    ``tactbench[extra]`` (or the plugin) that installs it when it is missing."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        what = extra if " " in extra or "/" in extra else f'"tactbench[{extra}]"'
        raise MissingExtraError(f"{module} is not installed ({exc}); pip install "
                                f"{what}") from None
