"""What ``tactbench plan`` says, decided: the forecast's records and its pure rules.

The records a plan is (:class:`Forecast`: its cells, :class:`CellForecast`, and its
primary comparisons, :class:`PrimaryForecast`) and the functions that decide them from
records alone — a pilot's rows, the planned cells, the split's sizes —, with no plan,
cache, store, disk or estimate of their own: :func:`tactbench.runner.forecasting.forecast`
composes those (execution) with these, as orchestrate composes a run.

A cell's time comes from a *pilot*: rows already stored in the scene's out folder (a run
of a seed or two), the median of its encoder × classifier's, said so; without one it is
unknown here, said with the pilot to run (:func:`_cells`). A comparison's per-run spread
comes from the pilot too, with its 95 % interval (at 2–3 runs it is wide: the power at
its upper end is said beside), and never below what test sampling of the pilot's own
disagreement gives (a pilot of identical differences is not "power 100 %"); without one
it is an **assumption**, said with its value: test sampling alone with the models
disagreeing on :data:`ASSUMED_DISCORDANCE` of the recordings — on the stored primaries
the observed per-run disagreement was 0–32 %, so it is no bound either way
(`python benchmarks/statistics_checks.py --part disagreement`) (:func:`_spread`). For a
fixed data set the floor no number of runs goes below, and how many recordings would
lower it (:mod:`tactbench.runner.analysis.power`); where every run draws its own data
set (``synthetic-forearm:people=per-run``) the runs are independent replications: ratio
0, no floor.

Every comparison of the primary family the run makes is forecast (the family decided by
:func:`tactbench.runner.analysis.family.primary_family`, the run's own: :func:`_family`),
each at the family's level (Holm's first step, α/m for m primary comparisons), exactly
(:func:`tactbench.runner.analysis.power.power`: :func:`_primary`); :func:`family_answered`
gives the family's chance of every one being answered, simulated through the run's own
procedure (Holm as the run spends it, the looks with ``--until``, comparisons sharing a
cell correlated: :func:`tactbench.runner.analysis.family_paths.family_forecast`). For a
run ``--until answered`` the forecast is of the sequential procedure itself
(:func:`tactbench.runner.analysis.sequential.procedure`: found, equivalent, the other
side, stopped early as futile, reached the maximum undecided, expected and largest runs,
by the simulation and rule the looks use, at that level and with the margin).
:attr:`PrimaryForecast.warnings` says, a line each (:func:`warnings`), an effect inside
the margin and a design short of 80 % power at its runs.
"""

from __future__ import annotations

import dataclasses
import statistics
from dataclasses import asdict, dataclass
from typing import Any, Protocol, Sequence

from tactbench.runner.analysis.comparisons import Comparison, comparisons
from tactbench.runner.analysis.family import pair_name, pair_where, primary_family
from tactbench.runner.analysis.family_paths import family_forecast
from tactbench.runner.analysis.power import (
    TARGET_POWER,
    detectable_effect,
    effect_floor,
    persistent_sd,
    power,
    recordings_for,
    runs_for_power,
    sampling_sd,
)
from tactbench.runner.analysis.sequential import procedure, unanswerable

#: The share of test recordings two models are assumed to disagree on without a pilot
#: (two models near 80 % whose errors are independent disagree on about 32 %).
ASSUMED_DISCORDANCE = 0.3



class PlannedCell(Protocol):
    """What the pure rules read of a planned cell (a plan's
    :class:`~tactbench.runner.execution.planning.Cell` is one)."""

    encoder: str
    classifier: str
    L: int
    key: str

    def label(self) -> str: ...


@dataclass
class CellForecast:
    """One cell: its label, estimated seconds (None: unknown) and where that comes from."""

    label: str
    seconds: float | None
    source: str


@dataclass
class PrimaryForecast:
    """What the planned runs can say about one primary comparison (points; ``level`` the
    α its power is at: the family's Holm level)."""

    name: str
    runs: int
    effect: float
    sd: float
    sd_source: str
    ratio: float
    power: float
    detectable: float
    floor: float
    recordings: int
    recordings_for_effect: int | None
    level: float = 0.05
    sd_high: float | None = None  # the upper end of a pilot's spread's 95 % interval
    power_at_sd_high: float | None = None
    margin: float | None = None
    runs_for_effect: int | None = None  # a fixed design's runs for 80 % power at effect
    # the part of the per-run spread more runs cannot remove: sd·√ratio (points)
    persistent: float = 0.0
    persistent_said: str = ""  # it, as plan says it (persistent_text)
    sequential: dict[str, Any] | None = None  # with --until: sequential.procedure's forecast
    # with --until: a first look seeing exactly the effect and spread would stop futile
    # (sequential.unanswerable: the look's own rule, out_of_reach)
    unanswerable: bool | None = None
    warnings: list[str] = dataclasses.field(default_factory=list)


@dataclass
class Forecast:
    """A run's plan: cells with their times, the total, the peak memory, the primaries."""

    cells: list[CellForecast]
    seconds: float | None
    unknown: int
    peak_mb: float | None
    primaries: list[PrimaryForecast]
    n_test: int
    n_train: int
    alpha: float
    independent: bool = False  # each run draws its own data set: no overlap, no floor
    design: str = "resampled"  # the split's design (contracts.SPLIT_DESIGNS)
    runs_not_made: int = 0  # runs whose own data set the plan did not make (all but one)
    # the run's wall time on this machine (runner.estimate), at each look with --until
    # (cumulative; one entry without): encoding, cells side by side, the run around them
    wall_s: list[float] | None = None
    looks: list[int] | None = None  # runs at each look (with --until)
    workers: int = 1  # cells at once (runner.execution.workers), and what set it
    workers_limit: str = "cores"
    worker_peak_mb: float | None = None  # one worker's forecast peak, and its source
    worker_peak_source: str = ""
    run_peak_mb: float | None = None  # the whole run's: its own process and its workers
    memory_mb: float | None = None  # this machine's
    cache_bytes: int = 0  # the new encodings the run writes to the cache (its first data set's)
    cache_free: int | None = None  # free on the cache's disk (None: it cannot say)
    family_answered: float | None = None  # every primary answered (family_answered)
    family: dict[str, Any] | None = None  # family_paths.family_forecast's, as a dict
    distinct_splits: int | None = None  # the distinct splits the planned seeds draw
    runs_asked: int = 0  # the runs (seeds) planned
    record: dict[str, Any] | None = None  # the run's record, as the run will make it

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def family_answered(primaries: list[PrimaryForecast], pairs: list[tuple], *,
                    alpha: float, looks: list[int] | None = None,
                    margin: float | None = None) -> dict[str, Any] | None:
    """The chance that every comparison of the primary family is answered (declared
    better either way, or equivalent), simulated through the run's own procedure
    (:func:`tactbench.runner.analysis.family_paths.family_forecast`): each comparison at
    the plan's effect and spread, the comparisons correlated by the cells they share
    (``pairs``: each comparison's two cells), Holm as the run spends it (α passed on
    after a rejection), and with ``looks`` (``--until``) the sequential looks, else one
    fixed test at the planned runs. None without primaries."""
    if not primaries:
        return None
    f = family_forecast([p.effect / 100 for p in primaries], [p.sd / 100 for p in primaries],
                        [p.ratio for p in primaries], pairs, runs=primaries[0].runs,
                        looks=looks, alpha=alpha,
                        margin=None if margin is None else margin / 100)
    return f.as_dict()


def _cells(cells: Sequence[PlannedCell], pilot: list[dict[str, Any]]) -> list[CellForecast]:
    """Each planned cell's time: 0 when finished, the pilot's median training and
    inference time of its encoder × classifier (whose encoding the pilot has cached),
    else unknown."""
    done = {r["key"] for r in pilot}
    by_pair: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in pilot:
        by_pair.setdefault((r["encoder"], r["classifier"]), []).append(r)
    out = []
    for cell in cells:
        label = cell.label()
        rows = by_pair.get((cell.encoder, cell.classifier))
        if cell.key in done:
            out.append(CellForecast(label, 0.0, "finished (stored)"))
        elif rows:
            train = statistics.median(float(r.get("train_s") or 0.0) for r in rows)
            infer = statistics.median(float(r.get("inference_ms_per_sequence") or 0.0)
                                      * int(r.get("n_test") or 0) / 1e3 for r in rows)
            out.append(CellForecast(label, train + infer,
                                    f"pilot: median of {len(rows)} stored row(s)"))
        else:
            out.append(CellForecast(label, None, "no stored row of this encoder × "
                                    "classifier: run a pilot (one seed) for a timing"))
    return out


def _family(cells: Sequence[PlannedCell], primary: tuple[str, ...] | list[str],
            pilot: list[dict[str, Any]]
            ) -> list[tuple[str, Comparison | None, tuple[int, int]]]:
    """Each comparison of the primary family, by the one function the run decides it
    with (:func:`~tactbench.runner.analysis.family.primary_family`), named as the
    looks name it, with the pilot's comparison of that pair (None without one) and its
    two cells (indices into the grid: comparisons sharing a cell are correlated)."""
    grid = list({(c.encoder, c.classifier, c.L): {"encoder": c.encoder,
                                                  "classifier": c.classifier, "L": c.L}
                 for c in cells}.values())
    stored = {pair_name(c.a, c.b, c.where): c for c in comparisons(pilot, primary=primary)
              if c.family == "primary"} if pilot and primary else {}
    out = []
    for i, j, factor, value_a, value_b, _ in primary_family(grid, primary):
        name = pair_name(value_a, value_b, pair_where(grid, i, factor, value_a))
        out.append((name, stored.get(name), (i, j)))
    return out


def _spread(found: Comparison | None, n_test: int, effect: float,
            ratio: float) -> tuple[float, float | None, float, str]:
    """The per-run spread a forecast uses: ``(sd, the upper end of the pilot's 95 %
    interval where the plan uses the pilot's own spread, else None; ratio, where it
    comes from)`` (fractions): a pilot's as it gives it, raised — and said so, with the
    reason — only to the test sampling of its own disagreement; without one, the
    assumption, said with its value."""
    from scipy import stats

    if not (found is not None and found.runs >= 2):
        sd = sampling_sd(n_test, ASSUMED_DISCORDANCE,
                         min(effect, ASSUMED_DISCORDANCE ** 0.5))
        return sd, None, ratio, (
            f"assumed, no pilot: the models disagree on {ASSUMED_DISCORDANCE:.0%} of the "
            f"{n_test} test recordings and the spread is test sampling alone; training "
            f"variability adds to it, less disagreement takes from it (on the stored "
            f"primaries 0–32 %): a pilot of 2–3 runs replaces the assumption")
    c = found
    d = list(c.per_run.values())
    df = c.runs - 1
    pilot_sd = statistics.stdev(d)
    pi = min(1.0, (c.a_only + c.b_only) / max(1, c.runs * n_test))
    least = sampling_sd(n_test, pi, min(abs(c.difference), pi ** 0.5)) if pi > 0 else 0.0
    if max(pilot_sd, least) == 0:  # one difference in every run: nothing to plan from
        sd = sampling_sd(n_test, ASSUMED_DISCORDANCE,
                         min(effect, ASSUMED_DISCORDANCE ** 0.5))
        seen = ("the models agree on every recording" if pi == 0 else
                f"one model is right on every recording and the other wrong ("
                f"{100 * c.difference:+.1f} points in every run)")
        return sd, None, c.run_ratio, (
            f"pilot: {c.runs} stored runs in which {seen}: no spread to plan from; "
            f"assumed instead: they disagree on {ASSUMED_DISCORDANCE:.0%} of the test "
            f"recordings, test sampling alone")
    sd = max(pilot_sd, least)
    # the interval is the pilot's spread's, whatever the plan then uses
    high = pilot_sd * (df / float(stats.chi2.ppf(0.025, df))) ** 0.5
    low = pilot_sd * (df / float(stats.chi2.isf(0.025, df))) ** 0.5
    said = (f"pilot: {c.runs} stored runs, spread {100 * pilot_sd:.2f} points (its 95 % "
            f"interval {100 * low:.2f} to {100 * high:.2f}, from {df} degree(s) of freedom)")
    if least <= pilot_sd:
        return sd, high, c.run_ratio, said
    said += (f"; planned with {100 * least:.2f}, raised to the test sampling of the "
             f"pilot's own disagreement ({pi:.0%} of the recordings), which no real "
             f"spread is below")
    if least > high:
        said += (f" — above the pilot's own 95 % upper limit ({100 * high:.2f}): the pilot's "
                 f"runs varied less than their test sets alone would make them")
    return sd, None, c.run_ratio, said


def _primary(text: str, found: Comparison | None, runs: int, effect: float,
             ratio: float, n_test: int, level: float, recordings: int, *,
             margin: float | None = None, looks: list[int] | None = None,
             n_train: int = 0) -> PrimaryForecast:
    """One primary comparison's forecast at ``runs`` runs for a true ``effect`` at the
    family's ``level``; with ``looks`` (a run ``--until answered``), the sequential
    procedure's too."""
    sd, high, ratio, source = _spread(found, n_test, effect, ratio)
    floor = effect_floor(sd, ratio, alpha=level)
    runs = max(2, runs)
    f = PrimaryForecast(
        name=text, runs=runs, effect=100 * effect, sd=100 * sd, sd_source=source,
        ratio=ratio, power=power(effect, sd, ratio, runs, alpha=level),
        detectable=100 * detectable_effect(sd, ratio, runs, alpha=level),
        floor=100 * floor, recordings=recordings,
        recordings_for_effect=recordings_for(effect, floor, recordings)
        if effect > 0 else None, level=level, margin=margin,
        sd_high=None if high is None else 100 * high,
        power_at_sd_high=None if high is None else power(effect, high, ratio, runs,
                                                          alpha=level),
        runs_for_effect=runs_for_power(effect, sd, ratio, alpha=level),
        persistent=100 * persistent_sd(sd, ratio))
    if looks:
        proc = procedure(effect, sd, ratio, looks, alpha=level,
                         margin=None if margin is None else margin / 100)
        f.sequential = {"looks": list(looks), **proc.as_dict()}
        f.unanswerable = unanswerable(effect, sd, ratio, looks, alpha=level,
                                      margin=None if margin is None else margin / 100)
    f.persistent_said = persistent_text(f, n_test, n_train)
    f.warnings = warnings(f)
    return f


def persistent_text(f: PrimaryForecast, n_test: int, n_train: int) -> str:
    """The part of the spread more runs cannot remove, as plan says it, with its formula
    and numbers: ``sd·√(n_test/n_train) = 3.40·√(165/208) = 3.03 points`` (the ratio by
    its value where it is not n_test/n_train, as for seed means of K folds)."""
    named = n_train and abs(f.ratio - n_test / n_train) < 1e-12
    root = f"√({n_test}/{n_train})" if named else f"√{f.ratio:.4g}"
    return (f"the part of the per-run spread more runs cannot remove: sd·√"
            f"{'(n_test/n_train)' if named else 'ratio'} = {f.sd:.2f}·{root} = "
            f"{f.persistent:.2f} points (the corrected standard error sd·√(1/J + ratio) "
            f"tends to it as the runs J grow, not to 0)")


def points(value: float) -> str:
    """An effect in points as a plan says it, signed: one decimal, and two significant
    digits where one decimal would say 0.0 (``--effect 1e-9``: ``+1e-09``)."""
    return f"{value:+.1f}" if value == 0 or abs(value) >= 0.05 else f"{value:+.2g}"


def warnings(f: PrimaryForecast) -> list[str]:
    """What a plan must say before any work, a line each: an effect (or the effect found
    at 80 % power) inside the margin, a question the looks' own rule says cannot be
    answered within the maximum (:func:`~tactbench.runner.analysis.sequential.unanswerable`),
    and a design short of 80 % power at its runs."""
    out = []
    m = f.margin
    if m and f.effect <= m:
        out.append(f"{f.name}: {points(f.effect)} points lies inside the ±{m:g} margin: the "
                   f"runs would end \"equivalent\", not \"better\"")
    elif m and f.detectable <= m:
        out.append(f"{f.name}: the effect found with 80 % power at {f.runs} runs, "
                   f"{f.detectable:.2f} points, lies inside the ±{m:g} margin: such a "
                   f"difference would end \"equivalent\"")
    seq = f.sequential
    if f.unanswerable:
        out.append(f"{f.name}: cannot be answered within {f.runs} runs: a first look that "
                   f"saw exactly {points(f.effect)} points with this spread would stop "
                   f"futile (the look's own rule); more data would, not more runs")
    if seq is not None and seq["power"] < TARGET_POWER:
        out.append(f"{f.name}: the sequential run finds {points(f.effect)} points with "
                   f"{seq['power']:.0%} power at most {f.runs} runs (a fixed design of "
                   f"{f.runs}: {f.power:.0%}); " + _needs(f))
    elif seq is None and f.power < TARGET_POWER:
        out.append(f"{f.name}: at {f.runs} runs, power {f.power:.0%} for "
                   f"{points(f.effect)} points, short of 80 %; " + _needs(f))
    return out


def _needs(f: PrimaryForecast) -> str:
    if f.runs_for_effect is not None:
        return f"a fixed design needs {f.runs_for_effect} runs"
    more = "" if not f.recordings_for_effect else \
        f"; about {f.recordings_for_effect} recordings (now {f.recordings}) would bring " \
        f"the floor to it"
    return (f"no number of runs of these recordings reaches it (floor "
            f"{f.floor:.1f} points){more}")
