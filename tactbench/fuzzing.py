"""Hypothesis strategies that mutate the documents a reader is handed (JSON headers,
manifests, calibration files): for tactbench's own fuzz suites and for plugin authors
fuzzing their readers.

>>> from hypothesis import given, strategies as st                       # doctest: +SKIP
>>> @given(st.data())                                                     # doctest: +SKIP
... def test_my_reader(data):
...     doc = data.draw(json_mutation(my_manifest(), values=json_values()))
...     ...  # write it, read it back: only tactbench's errors may escape

hypothesis is imported when a strategy is made (it is a test dependency, not a runtime
one).
"""

from __future__ import annotations

import copy
from typing import Any, Iterator, Sequence


def json_values(extra: Sequence[Any] = ()) -> Any:
    """JSON values a hostile or careless edit could leave in a field: null, booleans,
    integers far beyond 64 bits, NaN and infinities, short text, small lists and dicts, a
    nested empty list, and ``extra`` (values that mean something to the reader at hand)."""
    from hypothesis import strategies as st

    return st.one_of(
        st.none(), st.booleans(), st.integers(-2 ** 70, 2 ** 70),
        st.sampled_from([0, -1, 1, 2, 3, 2 ** 63, 10 ** 30, 20_000_000_000, *extra]),
        st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
        st.lists(st.one_of(st.integers(-3, 2 ** 40), st.floats(), st.text(max_size=2)),
                 max_size=4),
        st.builds(lambda: [[[]]]),
        st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


def json_paths(doc: Any, prefix: tuple = ()) -> Iterator[tuple]:
    """The path to every node of a JSON document (the first 3 items of each list)."""
    yield prefix
    if isinstance(doc, dict):
        for key, value in doc.items():
            yield from json_paths(value, prefix + (key,))
    elif isinstance(doc, list):
        for i, value in enumerate(doc[:3]):
            yield from json_paths(value, prefix + (i,))


def json_mutation(doc: Any, *, values: Any = None, at_most: int = 1) -> Any:
    """A strategy for ``doc`` (deep-copied) with 1 to ``at_most`` nodes each replaced by one
    of ``values`` (default :func:`json_values`) or removed."""
    from hypothesis import strategies as st

    values = json_values() if values is None else values

    @st.composite
    def mutate(draw):
        out = copy.deepcopy(doc)
        for _ in range(draw(st.integers(1, max(1, at_most)))):
            paths = list(json_paths(out))[1:]
            if not paths:
                break
            path = draw(st.sampled_from(paths))
            parent = out
            for key in path[:-1]:
                parent = parent[key]
            if draw(st.booleans()):
                parent[path[-1]] = draw(values)
            else:
                del parent[path[-1]]
        return out

    return mutate()
