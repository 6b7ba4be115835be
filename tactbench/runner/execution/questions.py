"""The names of a run's cells and the questions asked of them.

A component spec is long (``small-cnn-lstm:batch_size=64,epochs=4,...``); the reports and
the terminal name it by its short name, or by the options that tell it apart from the
other specs of the same run (:func:`spec_labels`). A *contrast* (``--contrast``,
``--primary``) names two cells of a run by the factors they differ in
(``encoder=raw..encoder=farneback``; :func:`parse_contrast`), and the cells it pairs are
found by :func:`contrast_pairs`. Both are read when a run is planned (a question that
names no two cells is refused before any work, :func:`check_contrasts`) and again by the
analysis and the reports, so they live here, with the run. A spec's short name and label
are names, not decoration: a contrast is written with them, a comparison and a look's
decision are keyed by them, and summaries are ordered by them, so execution and analysis
need them; how a table or a figure lays them out is presentation's.
"""

from __future__ import annotations

from collections import Counter
from functools import lru_cache
from typing import Any, Iterable, Mapping, Sequence

from tactbench.errors import InputError

#: The factors a paired comparison may differ in (the rest of a cell's group is shared).
FACTORS = ("encoder", "classifier", "L")
#: How a contrast is written, for the errors that refuse one.
_EXAMPLE = "e.g. encoder=raw,L=6..encoder=farneback,L=3"


def short_name(spec: str) -> str:
    """``small-cnn-lstm:epochs=4,...`` → ``small-cnn-lstm``; a component's ``estimator``
    stays in the name (``sklearn:C=10,estimator=SVC`` → ``sklearn:SVC``), as it says what
    the component is."""
    name, _, rest = spec.partition(":")
    for item in rest.split(","):
        key, _, value = item.partition("=")
        if key.strip() == "estimator" and value.strip():
            return f"{name}:{value.strip()}"
    return name


def spec_labels(specs: Iterable[str]) -> dict[str, str]:
    """Spec → the name the reports show for it, among ``specs`` (those of one run).

    A spec whose :func:`short_name` no other spec shares is shown by it, as always. Specs
    that share one are told apart by the options that differ among them, by key:
    ``small-cnn-lstm (width=16)`` and ``small-cnn-lstm (width=8)``, several joined by
    ``"; "`` (a label holds no comma: contrast labels join factors with commas); an option
    one of them lacks shows as ``key=default``. Specs still shown alike (the same options
    spelled in another order) are shown whole.
    """
    groups: dict[str, list[str]] = {}
    for spec in dict.fromkeys(str(s) for s in specs):
        groups.setdefault(short_name(spec), []).append(spec)
    labels: dict[str, str] = {}
    for short, members in groups.items():
        if len(members) == 1:
            labels[members[0]] = short
            continue
        options = {spec: _options_text(spec) for spec in members}
        keys = sorted({k for o in options.values() for k in o})
        differ = [k for k in keys if len({o.get(k) for o in options.values()}) > 1]
        for spec in members:
            shown = "; ".join(f"{k}={options[spec].get(k, 'default')}" for k in differ)
            labels[spec] = f"{short} ({shown})"
    count = Counter(labels.values())
    return {spec: spec if count[label] > 1 else label for spec, label in labels.items()}


def spec_label(spec: Any, labels: Mapping[str, str] | None = None) -> str:
    """``spec``'s label in ``labels`` (:func:`spec_labels`); its short name where
    ``labels`` does not name it."""
    return (labels or {}).get(str(spec)) or short_name(str(spec))


def _options_text(spec: str) -> dict[str, str]:
    """A spec's options as written (``key`` → value text; a bare first value under
    ``_``), for labels: no typing, so a value shows as the spec spells it."""
    options = {}
    for item in spec.partition(":")[2].split(","):
        key, eq, value = item.partition("=")
        if key.strip():
            options[key.strip() if eq else "_"] = value.strip() if eq else key.strip()
    return options


def parse_contrast(text: str) -> tuple[dict[str, str], dict[str, str]]:
    """``"encoder=raw,L=6..encoder=farneback,L=3"`` → the factors of cell A and cell B.

    Each side names the factors (of :data:`FACTORS`) it sets, ``factor=value`` joined by
    commas; both sides name the same factors; the factors neither names are shared, so
    the contrast is made once for each of their combinations in the run. An encoder or
    classifier spec keeps its own commas (``encoder=farneback:levels=3,winsize=9,L=3``):
    a comma starts a new factor only where a factor's name and ``=`` follow it. The
    difference is B − A. Raises :class:`InputError` naming the mistake.
    """
    if not isinstance(text, str) or text.count("..") != 1:
        raise InputError(f"contrast {text!r} must be two cells joined by '..' ({_EXAMPLE})")
    a, b = _parsed(text)  # each text parsed once (a look asks the same questions again)
    return dict(a), dict(b)


@lru_cache(maxsize=1024)
def _parsed(text: str) -> tuple[tuple, tuple]:
    """:func:`parse_contrast`'s work, kept per text: each side's ``(factor, value)``."""
    sides = []
    for part in text.split(".."):
        side: dict[str, str] = {}
        for item in _contrast_items(part):
            factor, eq, value = item.partition("=")
            factor, value = factor.strip(), value.strip()
            if not eq or not factor or not value:
                raise InputError(f"contrast {text!r}: {item.strip()!r} is not factor=value "
                                 f"({_EXAMPLE})")
            if factor not in FACTORS:
                raise InputError(f"contrast {text!r}: unknown factor {factor!r} (factors: "
                                 f"{', '.join(FACTORS)})")
            if factor in side:
                raise InputError(f"contrast {text!r}: factor {factor!r} is given twice")
            if factor == "L":
                try:
                    int(value)
                except ValueError:
                    raise InputError(f"contrast {text!r}: L must be a whole number, got "
                                     f"{value!r}") from None
            side[factor] = value
        sides.append(side)
    a, b = sides
    if set(a) != set(b):
        raise InputError(f"contrast {text!r}: both sides must set the same factors "
                         f"({', '.join(sorted(a))} against {', '.join(sorted(b))})")
    if a == b:
        raise InputError(f"contrast {text!r} compares a cell with itself")
    return tuple(a.items()), tuple(b.items())


def _contrast_items(side: str) -> list[str]:
    """One side of a contrast split into its ``factor=value`` items: a comma-separated
    piece that does not start with a factor's name and ``=`` continues the spec before
    it (an option of an encoder or classifier spec, ``farneback:levels=3,winsize=9``)."""
    items: list[str] = []
    for piece in side.split(","):
        starts_factor = piece.partition("=")[0].strip() in FACTORS
        if items and not starts_factor and ":" in items[-1]:
            items[-1] += "," + piece
        else:
            items.append(piece)
    return items


def _matches(cell: dict[str, Any], side: dict[str, str], labels: Mapping[str, str]) -> bool:
    for factor, value in side.items():
        got = cell[factor]
        if factor == "L":
            if int(got) != int(value):
                return False
        elif factor == "classifier":
            if value not in (str(got), short_name(str(got)), str(got).split(":")[0],
                             spec_label(got, labels)):
                return False
        elif str(got) != value:
            return False
    return True


def contrast_pairs(contrast: str, cells: Sequence[dict[str, Any]]) -> list[tuple[int, int]]:
    """The pairs (index of A, index of B) of ``cells`` (dicts of :data:`FACTORS`) that
    ``contrast`` (:func:`parse_contrast`) names: A and B match their sides and agree on
    every factor the contrast does not set. A side names a classifier by its full spec,
    its name, its short name or its label among the cells' (:func:`spec_labels`)."""
    a_side, b_side = parse_contrast(contrast)
    rest = [f for f in FACTORS if f not in a_side]
    labels = spec_labels(c["classifier"] for c in cells)
    return [(i, j) for i, ci in enumerate(cells) for j, cj in enumerate(cells)
            if i != j and _matches(ci, a_side, labels) and _matches(cj, b_side, labels)
            and all(ci[f] == cj[f] for f in rest)]


def check_contrasts(contrasts: Sequence[str], cells: Sequence[dict[str, Any]]) -> None:
    """Refuse a contrast that names no pair of ``cells`` (before any work)."""
    for text in contrasts:
        if not contrast_pairs(text, cells):
            raise InputError(f"contrast {text!r} names no two cells of this run (cells "
                             f"that match each side and share every other factor)")
