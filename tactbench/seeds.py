"""Seeds derived from a run's seed and a thing's identity, the same in every process.

Every random choice in tactbench (splits, window order, network initialisation,
simulated users) draws from a generator seeded by :func:`derive_seed` over the run's seed
and the identity of what is drawn, so a cell's result depends only on its identity and
seed, never on the order or the process it ran in.
"""

from __future__ import annotations

import hashlib
from typing import Any


def derive_seed(*parts: Any) -> int:
    """A seed in ``[0, 2**63)`` from ``parts`` (run seed, cell identity, ...), via SHA-256.

    Stable across processes and Python versions, unlike ``hash()`` (salted per process).
    """
    text = "\x1f".join(repr(p) for p in parts)
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "big") >> 1
