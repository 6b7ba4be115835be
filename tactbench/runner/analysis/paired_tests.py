"""Paired tests: the test a comparison's verdict rests on, a registered component.

A paired test (kind ``paired-test``, hook ``register_paired_tests``, contract
:data:`tactbench.contracts.PAIRED_TEST`) turns a pair's per-run differences B − A into
an interval and a p: ``test(d, *, ratio, confidence)`` → ``{"low", "high", "p", "df"}``
(``df`` None where the test has no degrees of freedom). It declares the designs it is
valid for (``designs``: the split designs of :data:`~tactbench.contracts.SPLIT_DESIGNS`,
and :data:`SEQUENTIAL` for the looks of a run ``--until answered``), and is refused for
any other in one line (:func:`check_paired_test`) — by ``tactbench run`` before any
training, by a report before any file.

The built-ins (:mod:`~tactbench.runner.analysis.paired_builtins`, registered by
:mod:`tactbench.paired`):
:class:`CorrectedT` (``corrected-t``, the default: every design, and the looks, whose
boundaries are placed for its statistic), defined here since every comparison made
without a choice uses it, and ``wilcoxon`` (runs of one fixed split, or independent
runs). Holm, the verdict rules
and the minimum of evidence are the same whichever test gives the p
(:mod:`tactbench.runner.analysis.comparisons`); the TOST, the runs for power and the
Bayesian correlated t beside a verdict stay the corrected t's.
"""

from __future__ import annotations

from typing import Any, Collection, Iterable, NamedTuple

import numpy as np

from tactbench.contracts import PAIRED_TEST, SEQUENTIAL
from tactbench.errors import InputError
from tactbench.plugins import load_registry
from tactbench.runner.analysis.statistics import corrected_t

#: The paired test a comparison uses when none is chosen (every stored report's).
DEFAULT_PAIRED_TEST = "corrected-t"


class CorrectedT:
    """The corrected resampled t of Nadeau & Bengio (2003), for K folds Bouckaert &
    Frank's (2004); ``ratio`` 0 (fixed split, independent runs) is the plain paired t.
    Valid for every design, and for the sequential looks (its null distribution at
    each look is Student's t on J − 1 degrees of freedom, which the boundaries use)."""

    label = "corrected t"
    designs = frozenset({"resampled", "kfold", "fixed", "independent", SEQUENTIAL})

    def test(self, d: np.ndarray, *, ratio: float, confidence: float) -> dict[str, Any]:
        t = corrected_t(d, ratio, confidence=confidence)
        return {"low": float(t["low"]), "high": float(t["high"]), "p": float(t["p"]),
                "df": int(t["df"])}


def check_paired_test(test: Any, name: str, design: str | None, *, sequential: bool = False
                      ) -> None:
    """Refuse paired test ``test`` (registered as ``name``) for runs of ``design``, or
    for the looks of a run ``--until answered`` (``sequential``), where it does not
    declare them: one :class:`InputError` line naming what it is valid for."""
    valid: Collection[str] = PAIRED_TEST.get(test, "designs")
    wanted = [w for w in (design, SEQUENTIAL if sequential else None) if w is not None]
    for what in wanted:
        if what not in valid:
            said = ("the looks of --until (they need a test with a known null "
                    "distribution at each look)" if what == SEQUENTIAL
                    else f"runs of a {what} design")
            raise InputError(f"paired test '{name}' is not valid for {said}; it is valid "
                             f"for {', '.join(sorted(valid))} (--paired-test "
                             f"{DEFAULT_PAIRED_TEST} is valid for all)")


class PairedTestChoice(NamedTuple):
    """A paired test as a run chose it: its registered ``name`` (what results.json and
    report.md record) and the built ``test``."""

    name: str
    test: Any

    def check(self, design: str | None, *, sequential: bool = False) -> None:
        """:func:`check_paired_test` of this test."""
        check_paired_test(self.test, self.name, design, sequential=sequential)


#: The default choice: the corrected t.
DEFAULT_CHOICE = PairedTestChoice(DEFAULT_PAIRED_TEST, CorrectedT())


def choose_paired_test(name: str | None, registry: Any = None) -> PairedTestChoice:
    """The paired test registered as ``name`` (None: :data:`DEFAULT_PAIRED_TEST`), built
    by ``registry`` (default: every installed plugin's) and checked against its
    contract; an unknown name is one line naming the known ones."""
    if name is None or name == DEFAULT_PAIRED_TEST and registry is None:
        return DEFAULT_CHOICE
    registry = load_registry() if registry is None else registry
    return PairedTestChoice(name, registry.build("paired-test", name))


#: How report.md names a test chosen with ``--paired-test`` above its comparisons (the
#: names in the ``{}``; every stored report, made with the default, says the t's text).
PAIRED_TEST_TEXT = ("the paired test chosen with --paired-test (`{}`: each comparison's "
                    "`method` in results.json says which; docs/statistics.md), over runs,")


def chosen_tests(comps: Iterable[Any]) -> str:
    """The paired tests other than the default that ``comps`` (comparison records) were
    tested with, their names joined by ", "; "" where all used the default."""
    return ", ".join(sorted({c.paired_test for c in comps} - {DEFAULT_PAIRED_TEST}))
