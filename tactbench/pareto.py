"""The Pareto front of ``(cost, quality)`` points: the one definition the runner's
cost-against-accuracy figure and the encoder benchmark's time-against-error table use."""

from __future__ import annotations

import math
from typing import Sequence


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the ``(cost, quality)`` points no other point beats on both (lower
    cost, higher quality; give ``-error`` as the quality where lower is better).

    A point is beaten when another costs no more *and* scores no less, and is better in
    one of the two. Equal points are all on the front; points with a NaN are never on
    it. Ordered by cost, then index.
    """
    finite = [i for i, (c, q) in enumerate(points)
              if not (math.isnan(float(c)) or math.isnan(float(q)))]
    front = []
    for i in finite:
        ci, qi = points[i]
        beaten = any(points[j][0] <= ci and points[j][1] >= qi
                     and (points[j][0] < ci or points[j][1] > qi) for j in finite)
        if not beaten:
            front.append(i)
    return sorted(front, key=lambda i: (points[i][0], i))
