"""Conformance suites for plugin authors, in one place.

``check_encoder("name")`` and ``check_classifier("name")`` run the checks that the
built-in components pass; ``conformance_cases`` and ``run_check`` parametrise the
encoder checks in pytest. The suites live beside what they check
(:mod:`tactbench.encoders.evaluation.conformance`,
:mod:`tactbench.classifiers.conformance`); this module is their public face: plugin
authors import from here.
"""

from __future__ import annotations

from tactbench.classifiers.conformance import check_classifier, tiny_windows
from tactbench.encoders.evaluation.conformance import (
                                        CHECKS,
                                        CheckResult,
                                        NotApplicable,
                                        check_encoder,
                                        conformance_cases,
                                        contact_sequence,
                                        run_check,
                                        run_checks,
)

__all__ = ["CHECKS", "CheckResult", "NotApplicable", "check_classifier", "check_encoder",
           "conformance_cases", "contact_sequence", "run_check", "run_checks", "tiny_windows"]
