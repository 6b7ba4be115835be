"""Moved to :mod:`tactbench.encoders.parallel` (this alias goes in tactbench 0.3)."""

from tactbench._compat import moved

moved(__name__)
