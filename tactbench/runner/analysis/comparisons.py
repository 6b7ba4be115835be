"""Paired comparisons of cells over runs: the :class:`Comparison` record and how rows make it.

Two cells that differ in one factor (or that a contrast names,
:func:`tactbench.runner.execution.questions.parse_contrast`) are compared run by run on the test
recordings both predicted: :func:`comparisons` pairs them, :func:`compare_cells` computes
one record, and the family step (Holm, verdicts) closes the run. The tests themselves are
pure functions of :mod:`tactbench.runner.analysis.statistics`; :func:`run_level_tests` is the one
place they are called over a pair's differences, and a :class:`Comparison` holds what
they give. results.json stores each record as :meth:`Comparison.to_dict` (flat JSON, the
field names of the reports made before the record), read back by
:meth:`Comparison.from_dict`, which verifies it.

Folds are read from the rows: a K-fold row's ``test_predictions`` carries ``folds``, the
fold id of each test recording, beside ``indices``; no fold is drawn again here.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from tactbench.data.splits import DESIGN_FIELD
from tactbench.errors import CorruptArtefactError, InputError
from tactbench.errors import is_finite_number
from tactbench.runner.execution.results import INDEPENDENT_RUNS
from tactbench.runner.analysis.pairing import (
    ClassGain,
    UserGains,
    aligned,
    difference_components,
    distinct_splits,
    fold_differences,
    per_class_gains,
    per_user_gains,
    recordings,
    repeats_note,
    sampling_share,
)
from tactbench.runner.analysis.paired_tests import (DEFAULT_CHOICE, DEFAULT_PAIRED_TEST,
                                                    PairedTestChoice)
from tactbench.runner.analysis.power import (
    bayes_correlated_t,
    detectable_effect,
    runs_for_power,
    seed_mean_ratio,
)
from tactbench.runner.execution.learning import cell_learning, describe_cell
from tactbench.runner.analysis.statistics import (
    NOT_LEARNED,
    TARGET_HALF_WIDTH,
    corrected_t,
    holm,
    pairs_differing_in_one_factor,
    runs_needed,
    sign_flip_p,
    tost_p,
    verdict,
)
from tactbench.runner.analysis.summaries import CONFIDENCE, cell_groups
from tactbench.runner.execution.questions import (FACTORS, contrast_pairs, parse_contrast,
                                                  spec_label, spec_labels)
from tactbench.runner.analysis.family import (parse_contrast_factors, pair_where,
                                              primary_family, side_label)
from tactbench.runner.analysis.variance import COMPONENTS, TEST_SAMPLING

#: The one rule for the p a verdict rests on, as report.md and docs/statistics.md state
#: it: the corrected t's (``p``), Holm-adjusted within its family (``p_holm``). The
#: sign-flip test over runs (``permutation_p``) is reported for reference only: it
#: assumes independent runs, which runs of one data set are not, so it is no check on
#: the correction (tests/runner/analysis/test_power.py shows it exceeding α).
P_RULE = ("p is the corrected t's; Holm adjusts it within its family (primary or "
          "exploratory), and the verdict rests on the adjusted p")

#: The margin (points) of the Bayesian correlated t's region of practical equivalence
#: when the run gives none (1 point, as Benavoli et al. 2017 use for accuracies).
BAYES_DEFAULT_MARGIN = 1.0
#: The two families a comparison belongs to.
FAMILIES = ("primary", "exploratory")


@dataclass(frozen=True)
class Comparison:
    """Two cells A and B compared run by run; differences are B − A, accuracy fractions.

    - which: ``dataset``, ``split``, ``factor`` (one of :data:`FACTORS`, or
      ``"contrast"``), ``a``, ``b`` (their values; a contrast's sides as
      ``encoder=raw,L=6``) and ``where`` (the factors both share: factor → value);
    - the run-level tests (:func:`run_level_tests`): ``difference`` (mean over runs),
      ``low``/``high`` (the interval at ``confidence``, by ``method`` with ``ratio`` =
      n_test/n_train or 1/(K − 1); ``df`` None below 2 runs), ``t_p``,
      ``permutation_p`` (exact sign-flip over runs), ``p`` (the one the verdict rests
      on), ``equivalence_margin`` (points) and ``equivalence_p`` (TOST), ``runs_needed``
      for an interval of ±``runs_needed_half_width`` points;
    - the runs: ``runs``, ``per_run`` (split seed → difference), ``b_better_runs``,
      ``a_better_runs``, ``tied_runs``, ``p_b_better`` (share of runs where B is higher),
      ``accuracy_a``/``accuracy_b``;
    - the recordings: ``a_only``/``b_only`` (rows only A / only B got right),
      ``discordant_recordings``, ``test_recordings``, ``mcnemar_per_seed`` (seed → p;
      about those trained models only), ``per_class`` (class → :class:`ClassGain`),
      ``per_user`` (:class:`UserGains`, with the users known);
    - the family (``family``: ``primary``, the comparisons the run names with
      ``--primary``, or ``exploratory``, all the others; each is Holm-adjusted apart):
      ``p_holm``, ``equivalence_p_holm``, ``family_size``, ``verdict`` and ``note``
      (:func:`tactbench.runner.analysis.statistics.verdict`; ``not learned``, with the cells and
      runs named in the note, where a run of either did not learn or did not transfer,
      :mod:`tactbench.runner.execution.learning`); ``ceiling`` when both cells are
      right on every paired recording of every run (a ceiling, not a precise zero);
    - for a reader (:mod:`tactbench.runner.analysis.power`): the Bayesian correlated t's
      ``bayes_a_better``/``bayes_equivalent``/``bayes_b_better`` within ±``bayes_margin``
      points; ``runs_for_power`` (runs for 80 % power at the observed difference, at the
      family's Bonferroni level; None when no number of runs of these data reaches it),
      ``detectable_effect`` (points found with 80 % power at the runs made) and
      ``test_sampling_share`` (the share of the per-run variance of the difference that
      test sampling, ``(π − δ²)/n``, accounts for); ``run_ratio``: the correction of
      a mean over per-run differences (``ratio``, or ``K/(K − 1)`` for seed means of K
      folds, :func:`tactbench.runner.analysis.power.seed_mean_ratio`);
    - ``variance_components``: where the runs vary the initialisation too (at least 2
      init seeds in each of at least 2 split seeds), the variance of the per-run
      difference split into split, initialisation and test sampling
      (:func:`tactbench.runner.analysis.variance.paired_variance_components`: ``*_var`` in
      points², ``*_sd`` in points, ``*_share``); None otherwise.
    """

    dataset: str
    split: str
    factor: str
    a: Any
    b: Any
    where: dict[str, Any]
    difference: float
    low: float
    high: float
    confidence: float
    method: str
    ratio: float
    df: int | None
    runs: int
    per_run: dict[str, float]
    b_better_runs: int
    a_better_runs: int
    tied_runs: int
    p_b_better: float
    t_p: float | None
    permutation_p: float
    p: float | None
    accuracy_a: float
    accuracy_b: float
    equivalence_margin: float | None
    equivalence_p: float | None
    runs_needed: int | None
    runs_needed_half_width: float
    a_only: int
    b_only: int
    discordant_recordings: int
    test_recordings: int
    mcnemar_per_seed: dict[str, float]
    per_class: dict[str, ClassGain]
    per_user: UserGains | None
    p_holm: float | None = None
    equivalence_p_holm: float | None = None
    family_size: int = 0
    verdict: str = ""
    note: str = ""
    family: str = "exploratory"
    bayes_margin: float | None = None
    bayes_a_better: float | None = None
    bayes_equivalent: float | None = None
    bayes_b_better: float | None = None
    runs_for_power: int | None = None
    detectable_effect: float | None = None
    test_sampling_share: float | None = None
    ceiling: bool = False
    run_ratio: float = 0.0
    variance_components: dict[str, Any] | None = None
    paired_test: str = DEFAULT_PAIRED_TEST

    def to_dict(self) -> dict[str, Any]:
        """The JSON entry of results.json: every field by name, ``where``'s factors
        spread among them (after ``b``), nested records as dicts."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "where":
                out.update(value)
            elif f.name == "paired_test" and value == DEFAULT_PAIRED_TEST:
                continue  # left out at its default: every stored report reads the same
            elif f.name == "per_class":
                out[f.name] = {k: asdict(g) for k, g in value.items()}
            elif f.name == "per_user":
                out[f.name] = None if value is None else asdict(value)
            else:
                out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], *, source: str = "results.json"
                  ) -> Comparison:
        """The record of a stored entry (:meth:`to_dict`), verified: every field present
        with a value of its kind, no unknown one; else :class:`CorruptArtefactError`
        naming ``source`` and the field."""
        if not isinstance(entry, Mapping):
            raise CorruptArtefactError(source, "a comparison that is not an object")
        names = [f.name for f in fields(cls) if f.name != "where"]
        unknown = sorted(set(entry) - set(names) - set(FACTORS))
        if unknown:
            raise CorruptArtefactError(source, f"a comparison with unknown field {unknown[0]!r}")
        missing = [n for n in names if n not in entry and n not in ADDED_FIELDS
                   and n != "paired_test"]  # to_dict leaves it out at its default
        if missing:
            raise CorruptArtefactError(source, f"a comparison without {missing[0]!r}")
        values = {name: entry[name] for name in names if name in entry}
        for name, value in values.items():
            if not _STORED_KIND[name](value):
                raise CorruptArtefactError(
                    source, f"a comparison whose {name} is {str(value)[:40]!r}")
        values["per_class"] = {str(k): ClassGain(**g) for k, g in entry["per_class"].items()}
        if entry["per_user"] is not None:
            values["per_user"] = UserGains(**entry["per_user"])
        return cls(where={k: entry[k] for k in FACTORS if k in entry}, **values)


#: Fields of :class:`Comparison` a stored entry may lack, because the reports were made
#: before the field existed; they read back as the field's default. A test added to
#: :func:`run_level_tests` names its new fields here (with a default in the record), so
#: the committed reports still read.
ADDED_FIELDS: frozenset[str] = frozenset({
    "family", "run_ratio", "bayes_margin", "bayes_a_better", "bayes_equivalent", "bayes_b_better",
    "runs_for_power", "detectable_effect", "test_sampling_share", "ceiling",
    "variance_components", "paired_test"})


def _count(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _maybe(check):
    return lambda v: v is None or check(v)


#: A finite number or None (a stored field that may be absent).
_optional_number = _maybe(is_finite_number)


def _numbers_by_text(v: Any) -> bool:
    return isinstance(v, Mapping) and all(isinstance(k, str) and is_finite_number(x)
                                          for k, x in v.items())


def _class_gains(v: Any) -> bool:
    keys = {f.name for f in fields(ClassGain)}
    return isinstance(v, Mapping) and all(
        isinstance(g, Mapping) and set(g) == keys and is_finite_number(g["difference"])
        and _count(g["runs"]) and _optional_number(g["low"])
        and _optional_number(g["high"])
        for g in v.values())


def _user_gains(v: Any) -> bool:
    keys = {f.name for f in fields(UserGains)}
    return isinstance(v, Mapping) and set(v) == keys and all(
        _count(v[k]) for k in ("users", "helped", "hurt")) and all(
        isinstance(v[k], (int, float)) for k in ("median", "q25", "q75")) and \
        _numbers_by_text(v["gains"])


def _variance_components(v: Any) -> bool:
    """A stored :func:`tactbench.runner.analysis.variance.paired_variance_components` result."""
    parts = [f"{c}_{k}" for c in COMPONENTS for k in ("var", "sd", "share")]
    keys = {"split_seeds", "init_seeds", "test_sampling", "groups", "total_var",
            "observed_var", "clipped", *parts}
    return isinstance(v, Mapping) and set(v) == keys and all(
        _count(v[k]) for k in ("split_seeds", "init_seeds")) and all(
        is_finite_number(v[k]) for k in ("groups", "total_var", "observed_var")) and all(
        (_optional_number if k.endswith("_share") else is_finite_number)(v[k])
        for k in parts) and \
        v["test_sampling"] in TEST_SAMPLING and isinstance(v["clipped"], list) and \
        set(v["clipped"]) <= set(COMPONENTS)


#: What each stored field of a comparison may hold (:meth:`Comparison.from_dict`).
_STORED_KIND = {
    **{k: lambda v: isinstance(v, str) for k in ("dataset", "split", "factor", "method",
                                                 "verdict", "note", "paired_test")},
    "family": lambda v: v in FAMILIES, "ceiling": lambda v: isinstance(v, bool),
    **{k: _optional_number for k in ("bayes_margin", "bayes_a_better", "bayes_equivalent",
                                     "bayes_b_better", "detectable_effect",
                                     "test_sampling_share")},
    "run_ratio": is_finite_number,
    "runs_for_power": _maybe(_count),
    "a": lambda v: isinstance(v, (str, int)), "b": lambda v: isinstance(v, (str, int)),
    **{k: is_finite_number for k in ("difference", "low", "high", "confidence", "ratio",
                                     "p_b_better", "permutation_p", "accuracy_a",
                                     "accuracy_b", "runs_needed_half_width")},
    **{k: _optional_number for k in ("t_p", "p", "equivalence_margin", "equivalence_p",
                                     "p_holm", "equivalence_p_holm")},
    **{k: _count for k in ("runs", "b_better_runs", "a_better_runs", "tied_runs", "a_only",
                           "b_only", "discordant_recordings", "test_recordings",
                           "family_size")},
    "df": _maybe(_count), "runs_needed": _maybe(_count),
    "per_run": _numbers_by_text, "mcnemar_per_seed": _numbers_by_text,
    "per_class": _class_gains, "per_user": _maybe(_user_gains),
    "variance_components": _maybe(_variance_components),
}


def read_comparisons(entries: Iterable[Comparison | Mapping[str, Any]], *,
                     source: str = "results.json") -> list[Comparison]:
    """Records of ``entries``: records as they are, stored entries (results.json's
    ``comparisons``) through :meth:`Comparison.from_dict`."""
    return [e if isinstance(e, Comparison) else Comparison.from_dict(e, source=source)
            for e in entries]


# --------------------------------------------------------------------- a run's family


def comparisons(rows: Iterable[dict[str, Any]], *, contrasts: Sequence[str] = (),
                margin: float | None = None, users: Sequence[str] | None = None,
                confidence: float = CONFIDENCE, primary: Sequence[str] = (),
                paired_test: PairedTestChoice = DEFAULT_CHOICE) -> list[Comparison]:
    """Paired comparisons at run level: the pairs ``primary`` names (contrasts,
    :func:`parse_contrast`), then every two cells that differ in one of :data:`FACTORS`,
    and every pair a ``contrasts`` entry names.

    Only runs (seeds) both cells finished, and test sequences both predicted with the
    same label, are paired; rows without ``test_predictions`` are left out. A is the
    cell that comes first in the run (the scene's order), so a run listing ``raw`` before
    ``farneback`` reports farneback − raw; a contrast (primary or not) gives its own A
    and B. A pair a primary contrast names is not repeated among the others; one whose
    cells differ in one factor is shown as that factor's comparison.

    Two families (:data:`P_RULE`): the primary comparisons (confirmatory), and all the
    others (exploratory); each family's p-values are Holm-adjusted apart, and the
    verdicts rest on the adjusted ones (:func:`tactbench.runner.analysis.statistics.verdict`).
    ``margin`` (points) adds the equivalence test; ``users`` (the user of each dataset
    sample, by index) adds per-user gains; ``paired_test``: the test the p and interval
    come from (:mod:`~tactbench.runner.analysis.paired_tests`; refused in one line for
    runs of a design it does not declare). See :class:`Comparison` for each field.
    """
    if margin is not None and not (isinstance(margin, (int, float)) and margin > 0):
        raise InputError(f"margin must be a number of points > 0, got {margin!r}")
    groups = cell_groups(rows)
    blocks: dict[tuple, list[tuple]] = {}
    for key in groups:  # first-appearance order within each (dataset, split)
        blocks.setdefault(key[:2], []).append(key)
    out: list[Comparison] = []
    for (dataset, split), keys in blocks.items():
        cells = [dict(zip(FACTORS, key[2:])) for key in keys]
        for i, j, factor, value_a, value_b, family in _pairs(cells, contrasts, primary):
            where = pair_where(cells, i, factor, value_a)
            res = compare_cells(groups[keys[i]], groups[keys[j]], margin=margin,
                                users=users, confidence=confidence, paired_test=paired_test,
                                names={"dataset": dataset, "split": split, "factor": factor,
                                       "a": value_a, "b": value_b, "where": where})
            if res is not None:
                out.append(replace(res, family=family))
    for family in FAMILIES:
        at = [n for n, c in enumerate(out) if c.family == family]
        for n, c in zip(at, _family([out[n] for n in at], confidence)):
            out[n] = c
    return out


def _pairs(cells: list[dict[str, Any]], contrasts: Sequence[str], primary: Sequence[str]
           ) -> list[tuple]:
    """(index of A, index of B, factor, value of A, value of B, family) of every pair of
    ``cells`` compared: the primary ones first (:func:`primary_family`), then those
    differing in one factor and the contrasts' (a pair already primary is not
    repeated)."""
    labels = spec_labels(c["classifier"] for c in cells)
    todo = primary_family(cells, primary)
    seen: set[frozenset] = {frozenset((t[0], t[1])) for t in todo}
    for p in pairs_differing_in_one_factor(cells):
        if frozenset((p.a, p.b)) not in seen:
            todo.append((p.a, p.b, p.factor, p.value_a, p.value_b, "exploratory"))
    for text in contrasts:
        a_side, b_side = parse_contrast(text)
        for i, j in contrast_pairs(text, cells):
            if frozenset((i, j)) not in seen:
                todo.append((i, j, "contrast", side_label(cells[i], a_side, labels),
                             side_label(cells[j], b_side, labels), "exploratory"))
    return todo


def _family(comps: list[Comparison], confidence: float) -> list[Comparison]:
    """One family's comparisons: Holm on the corrected t's p (NaN: too few runs) and on
    the equivalence p, then each verdict and its note, and the runs 80 % power at the
    observed difference needs at the family's Bonferroni level."""
    alpha = 1 - confidence
    p = holm([c.p if c.p is not None else math.nan for c in comps])
    eq = holm([c.equivalence_p if c.equivalence_p is not None else math.nan for c in comps])
    size = int(sum(c.p is not None for c in comps))
    out = []
    for c, p_adj, eq_adj in zip(comps, p, eq):
        p_holm = None if math.isnan(p_adj) else float(p_adj)
        eq_holm = None if math.isnan(eq_adj) else float(eq_adj)
        said, note = verdict(c.low, c.high, 1.0 if p_holm is None else p_holm, c.runs,
                             alpha=alpha, discordant_recordings=c.discordant_recordings,
                             equivalence_p_adjusted=eq_holm)
        if c.ceiling:
            note = "a ceiling: both cells right on every recording of every run"
        if c.verdict == NOT_LEARNED:  # set by compare_cells; its p stays in the family
            said, note = c.verdict, c.note
        out.append(replace(c, p_holm=p_holm, equivalence_p_holm=eq_holm, family_size=size,
                           verdict=said, note=note, **_runs_and_effect(c, alpha / max(1, size))))
    return out


def _runs_and_effect(c: Comparison, level: float) -> dict[str, Any]:
    """``runs_for_power`` and ``detectable_effect`` of one comparison at ``level``, from
    the spread of its per-run differences (None with fewer than 2 runs or none)."""
    d = np.array(list(c.per_run.values()))
    if len(d) < 2 or not np.all(np.isfinite(d)):
        return {"runs_for_power": None, "detectable_effect": None}
    sd, ratio = float(d.std(ddof=1)), c.run_ratio
    effect = abs(c.difference)
    return {"runs_for_power": runs_for_power(effect, sd, ratio, alpha=level)
            if effect > 0 else None,
            "detectable_effect": 100 * detectable_effect(sd, ratio, len(d), alpha=level)}


# --------------------------------------------------------------------- one pair of cells


def independent(rows: Sequence[dict[str, Any]]) -> bool:
    """Whether every one of these rows' runs trained and tested on a data set of its own,
    drawn independently of the others' (their row field ``independent_runs``, written by
    :func:`tactbench.runner.execution.planning.cell_identity`): runs that are independent
    replications, whose training sets share nothing."""
    return bool(rows) and all(r.get(INDEPENDENT_RUNS) is True for r in rows)


#: The ``method`` of a comparison over independent replications, and of one over runs of
#: one fixed split (their start: a note on split-seed means may follow); every other
#: comparison's t is corrected for overlap.
INDEPENDENT_METHOD = "paired t over independent runs (each run its own data set)"
FIXED_METHOD = "paired t over runs of one fixed split (they differ by initialisation only)"


def plain_t(c: "Comparison") -> bool:
    """Whether comparison ``c`` is the plain paired t over runs (ratio 0: independent
    replications, or runs of one fixed split), not a t corrected for runs that overlap."""
    return c.method.startswith((INDEPENDENT_METHOD, FIXED_METHOD))


def design(rows: Sequence[dict[str, Any]]) -> str:
    """The split design of these rows' runs (:data:`~tactbench.contracts.SPLIT_DESIGNS`):
    ``independent`` where every run drew its own data set (:func:`independent`), else the
    one they record (``split_design``); rows made before rows recorded it, and rows that
    record two, read as every row did before: ``kfold`` with ``folds``, else ``resampled``."""
    if independent(rows):
        return "independent"
    recorded = {r.get(DESIGN_FIELD) for r in rows}
    if len(recorded) == 1 and None not in recorded:
        return recorded.pop()
    return "kfold" if rows[0].get("folds") else "resampled"


def correction(rows: Sequence[dict[str, Any]]) -> tuple[str, float, str]:
    """The design of these runs (:func:`design`), the correction of their per-fold
    (``kfold``: 1/(K − 1)) or per-run differences (``resampled``: n_test/n_train; 0 for
    ``fixed`` and ``independent``, whose t is the plain paired t over runs), and the test's
    name."""
    kind = design(rows)
    if kind in ("independent", "fixed"):
        return kind, 0.0, INDEPENDENT_METHOD if kind == "independent" else FIXED_METHOD
    folds = rows[0].get("folds")
    if kind == "kfold" and folds:
        return kind, 1.0 / (int(folds) - 1), (f"corrected repeated {int(folds)}-fold t "
                                              "(Bouckaert–Frank)")
    ratios = [r["n_test"] / r["n_train"] for r in rows if r.get("n_train") and r.get("n_test")]
    return "resampled", (statistics.fmean(ratios) if ratios else 1.0), \
        "corrected resampled t (Nadeau–Bengio)"


def compare_cells(runs_a: dict[tuple, dict[str, Any]], runs_b: dict[tuple, dict[str, Any]],
                  *, names: Mapping[str, Any], margin: float | None = None,
                  users: Sequence[str] | None = None, confidence: float = CONFIDENCE,
                  paired_test: PairedTestChoice = DEFAULT_CHOICE) -> Comparison | None:
    """Two cells compared run by run (``runs_*``: run key → row); None when they share
    no run with a paired test sequence. ``names``: the record's ``dataset``, ``split``,
    ``factor``, ``a``, ``b`` and ``where``.

    A run is one split seed; where the rows vary the initialisation too (``init_seed``),
    a split's runs are averaged first and the split is the unit. For K folds repeated
    over seeds, the corrected t runs over the K·r per-fold differences (Bouckaert–Frank)
    from the fold ids the rows record; rows without them (made before rows kept their
    folds) give the split seeds' means, and ``method`` says which.
    """
    shared = sorted(set(runs_a) & set(runs_b), key=lambda k: (k[0], -1 if k[1] is None else k[1]))
    per_seed = {key: run for key in shared
                if len((run := aligned(runs_a[key], runs_b[key])).ids)}
    if not per_seed:
        return None
    rows_a = [runs_a[k] for k in per_seed]
    kind, ratio, method = correction(rows_a + [runs_b[k] for k in per_seed])
    paired_test.check(kind)
    if paired_test.name != DEFAULT_PAIRED_TEST:
        method = f"{paired_test.test.label} over runs ({kind} design)"
    splits: dict[int, list[tuple]] = {}  # the unit: a split seed (its init seeds averaged)
    for key in per_seed:
        splits.setdefault(key[0], []).append(key)
    repeats: dict[int, int] = {}
    if kind == "resampled" and names["split"] != "paper":
        # over groups (sessions, people), a seed can draw a split already drawn: no new
        # evidence (a random split of recordings, ``paper``, never repeats in practice)
        splits, repeats = distinct_splits(splits, runs_a)
        if repeats:
            method += "; " + repeats_note(repeats, len(splits))
    d_run = np.array([np.mean([(per_seed[k].cb.mean() - per_seed[k].ca.mean()) for k in ks])
                      for ks in splits.values()])
    d_t, run_ratio = d_run, ratio
    if kind == "kfold":  # a run: the mean of its K folds'
        run_ratio = seed_mean_ratio(int(rows_a[0]["folds"]))
        per_fold = fold_differences(per_seed, splits)
        d_t, ratio = (d_run, run_ratio) if per_fold is None else (per_fold, ratio)
        method += (f" over {len(d_run)} split-seed means (the rows carry no fold ids)"
                   if per_fold is None else f" over {len(per_fold)} fold differences")
    return Comparison(
        **names, **run_level_tests(d_run, d_t, ratio, run_ratio, margin=margin,
                                   confidence=confidence, test=paired_test.test),
        paired_test=paired_test.name,
        method=method, ratio=ratio, run_ratio=run_ratio, runs=len(d_run),
        per_run={str(s): float(v) for s, v in zip(splits, d_run)},
        b_better_runs=int(np.sum(d_run > 0)), a_better_runs=int(np.sum(d_run < 0)),
        tied_runs=int(np.sum(d_run == 0)), p_b_better=float(np.mean(d_run > 0)),
        accuracy_a=float(np.mean([run.ca.mean() for run in per_seed.values()])),
        accuracy_b=float(np.mean([run.cb.mean() for run in per_seed.values()])),
        **recordings(per_seed),
        per_class=per_class_gains(per_seed, splits, list(rows_a[0]["classes"]), run_ratio,
                                   confidence),
        test_sampling_share=sampling_share(per_seed, splits, d_run),
        ceiling=all(bool(r.ca.all() and r.cb.all()) for r in per_seed.values()),
        variance_components=difference_components(per_seed, splits),
        per_user=None if users is None else per_user_gains(per_seed, users),
        **_not_learned(names, [runs_a[k] for k in per_seed], [runs_b[k] for k in per_seed]))


def _not_learned(names: Mapping[str, Any], rows_a: Sequence[dict[str, Any]],
                 rows_b: Sequence[dict[str, Any]]) -> dict[str, str]:
    """``verdict`` :data:`~tactbench.runner.analysis.statistics.NOT_LEARNED` and the ``note``
    naming the cell and why, where either cell's runs together did not learn or did not
    transfer (:func:`tactbench.runner.execution.learning.cell_learning`, over the runs
    paired here); nothing otherwise."""
    label = spec_label if names["factor"] == "classifier" else str
    said = [describe_cell(label(names[side]), cell_learning(rows))
            for side, rows in (("a", rows_a), ("b", rows_b))]
    said = [s for s in said if s]
    if not said:
        return {}
    return {"verdict": NOT_LEARNED,
            "note": "no verdict rests on a model at chance: " + "; ".join(said)}


def run_level_tests(d_run: np.ndarray, d_t: np.ndarray, ratio: float, run_ratio: float,
                    *, margin: float | None, confidence: float,
                    test: Any = DEFAULT_CHOICE.test) -> dict[str, Any]:
    """Every test over a pair's runs, by field of :class:`Comparison` — the one place a
    test of :mod:`tactbench.runner.analysis.statistics` or
    :mod:`tactbench.runner.analysis.power` is called on a comparison.

    ``d_run``: B − A per run (split seed); ``d_t``: the differences ``test`` (the paired
    test, :mod:`~tactbench.runner.analysis.paired_tests`) runs over (per fold for K
    folds, else ``d_run``); ``ratio``: its correction;
    ``run_ratio``: the correction of a mean of ``d_run`` (the same but for K folds);
    ``margin`` (points): the equivalence margin, None for none.
    """
    j = len(d_run)
    diff = float(d_run.mean())
    res: dict[str, Any] = {"difference": diff, "low": diff, "high": diff,
                           "confidence": confidence, "df": None, "t_p": None,
                           "permutation_p": float(sign_flip_p(d_run)), "p": None}
    if j >= 2:
        t = test.test(d_t, ratio=ratio, confidence=confidence)
        # a difference of accuracies lies in [−1, 1]; the t-interval of a few runs can pass it
        res.update(low=max(-1.0, float(t["low"])), high=min(1.0, float(t["high"])),
                   df=t["df"], p=float(t["p"]))
        res["t_p"] = float(corrected_t(d_t, ratio, confidence=confidence)["p"]) \
            if test is not DEFAULT_CHOICE.test else res["p"]  # the one rule: P_RULE
    half = (margin / 100) if margin else TARGET_HALF_WIDTH
    sd = float(d_run.std(ddof=1)) if j > 1 else None
    res["equivalence_margin"] = margin
    res["equivalence_p"] = (float(tost_p(d_run, run_ratio, margin / 100))
                            if margin and j >= 2 else None)
    res["runs_needed"] = runs_needed(sd, run_ratio, half, confidence=confidence)
    res["runs_needed_half_width"] = 100 * half
    rope = margin if margin else BAYES_DEFAULT_MARGIN
    if j >= 2:
        bayes = bayes_correlated_t(d_run, run_ratio, rope / 100)
        res.update(bayes_margin=rope, bayes_a_better=bayes["p_a_better"],
                   bayes_equivalent=bayes["p_equivalent"], bayes_b_better=bayes["p_b_better"])
    return res


