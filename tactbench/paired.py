"""The built-in paired tests, registered by name the way plugins register theirs
(hook ``register_paired_tests``; the tests themselves are
:mod:`tactbench.runner.analysis.paired_builtins`, imported only when one is built)."""

from __future__ import annotations

from tactbench import hookimpl


@hookimpl
def register_paired_tests(register):
    register("corrected-t", "tactbench.runner.analysis.paired_builtins:CorrectedT",
             summary="corrected resampled t (Nadeau–Bengio; K folds: Bouckaert–Frank), "
                     "plain paired t for fixed splits and independent runs; every design "
                     "and --until (the default)")
    register("wilcoxon", "tactbench.runner.analysis.paired_builtins:WilcoxonSignedRank",
             summary="Wilcoxon signed-rank over runs with the Hodges–Lehmann interval; "
                     "fixed splits and independent runs only")
