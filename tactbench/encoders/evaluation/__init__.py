"""Tools that evaluate encoders, kept apart from the encoders themselves.

:mod:`~tactbench.encoders.evaluation.conformance` (the conformance suite every encoder
passes; its public face is :mod:`tactbench.testing`),
:mod:`~tactbench.encoders.evaluation.stability` (extreme inputs) and
:mod:`~tactbench.encoders.evaluation.flowbench` (flow error against run time).
"""
