"""Runs added until the primary questions are answered: the looks, replayed from the rows.

``tactbench run --until answered`` runs the grid's seeds in batches (a *look* after each)
and stops when every primary comparison (``--primary``) is decided — better, worse,
equivalent within ``--margin``, futile, or not learned (a run of one of its cells did not
learn: no verdict rests on it, :mod:`tactbench.runner.execution.learning`) — or when
``--max-runs`` or ``--budget`` is reached. What each look saw is never stored apart from
the cells: :func:`replay` recomputes every look from the rows (the first ``n_k`` seeds of
the run's seed order at look k, :class:`~tactbench.runner.execution.scene.Design`), so a
resumed or re-rendered report shows the same looks, and a look's decision cannot drift
from its evidence; within one run, each look goes on from the last (``resume``). The
decisions follow :mod:`tactbench.runner.analysis.sequential` (α spent over the looks,
Holm carried over them).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from tactbench.errors import InputError
from tactbench.runner.analysis.comparisons import Comparison, comparisons
from tactbench.runner.analysis.family import pair_name
from tactbench.runner.execution.results import ok_rows
from tactbench.runner.execution.scene import Design
from tactbench.runner.analysis.sequential import FUTILE, FamilyState, Look, family_look
from tactbench.runner.analysis.statistics import NOT_LEARNED


def comparison_name(c: Comparison) -> str:
    """A primary comparison's name in the looks: ``raw → farneback (L=5, small-cnn-lstm)``
    (:func:`tactbench.runner.analysis.family.pair_name`, the plan's too)."""
    return pair_name(c.a, c.b, c.where)


@dataclass
class History:
    """Every look so far: its run count, each primary comparison's :class:`Look`, and
    the final state (decided comparisons and α shares)."""

    looks: list[int]
    max_runs: int
    seen: list[dict[str, Look]] = field(default_factory=list)
    state: FamilyState | None = None

    @property
    def answered(self) -> bool:
        """Whether every primary comparison is closed: decided, or futile (stopped
        unanswered: no number of runs up to the maximum can decide it), so the run
        stops; :meth:`stopped_because` tells the two apart."""
        return self.state is not None and len(self.state.closed) == len(self.state.names)

    def stopped_because(self) -> str:
        if self.state is None:
            return (f"no look made yet: the first is after {self.looks[0]} runs with "
                    f"every primary cell")
        if self.answered:
            closed = [lk.decision for lk in self.state.closed.values()]
            futile, unlearned = closed.count(FUTILE), closed.count(NOT_LEARNED)
            if not futile and not unlearned:
                return "every primary question is answered"
            return ", ".join(
                [f"{n} of {len(closed)} primary question(s) stopped unanswered ({why})"
                 for n, why in ((futile, "futile: more runs of these data would not decide "
                                 "them"), (unlearned, "a model did not learn: no verdict "
                                           "rests on it")) if n]
                + [f"{len(closed) - futile - unlearned} answered"])
        done = self.looks[len(self.seen) - 1] if self.seen else 0
        return f"{done} of {self.max_runs} runs made; questions still open"

    def as_dict(self) -> dict[str, Any]:
        return {"looks": [{"runs": self.looks[k], "comparisons": {
                    name: look.as_dict() for name, look in seen.items()}}
                          for k, seen in enumerate(self.seen)],
                "max_runs": self.max_runs, "answered": self.answered,
                "stopped": self.stopped_because(),
                "decisions": {} if self.state is None else {
                    n: lk.decision for n, lk in self.state.closed.items()}}


def replay(rows: Sequence[dict[str, Any]], *, seed_order: Sequence[int],
           looks: Sequence[int], primary: Sequence[str], margin: float | None = None,
           alpha: float = 0.05, resume: History | None = None) -> History:
    """Every look the rows allow: at look k, the comparisons of the rows of the first
    ``looks[k]`` seeds of ``seed_order``; a look is made only when every one of those
    seeds has a row of each primary cell. ``primary``: the contrasts naming the
    confirmatory comparisons (none: no look). ``resume``: the history an earlier report
    of the same run made (stored rows never change), so only the looks after its last
    are computed: a look's work does not grow with the looks before it."""
    rows = ok_rows(rows)
    history = History(list(looks), looks[-1])
    if resume is not None and list(resume.looks) == list(looks):
        history.seen, history.state = list(resume.seen), copy.deepcopy(resume.state)
    for k in range(len(history.seen), len(looks) if primary else 0):
        if history.answered:
            break
        seeds = set(seed_order[:looks[k]])
        subset = [r for r in rows if int(r["seed"]) in seeds]
        prim = [c for c in comparisons(subset, primary=primary, margin=margin,
                                       confidence=1 - alpha) if c.family == "primary"]
        if not prim or any(len({s.split("/")[0] for s in c.mcnemar_per_seed}) < looks[k]
                           for c in prim):
            break  # this look's runs are not all there yet (repeated splits count too)
        history.seen.append(_look(history, prim, looks[:k + 1], margin, alpha))
    return history


def _look(history: History, prim: Sequence[Comparison], looks: Sequence[int],
          margin: float | None, alpha: float) -> dict[str, Look]:
    """One look of the open primary comparisons ``prim`` (the family's state, made at
    the first look, carried on in ``history``)."""
    diffs = {comparison_name(c): list(c.per_run.values()) for c in prim}
    if history.state is None:
        history.state = FamilyState(alpha, list(diffs))
    open_now = [name for name in history.state.names if name not in history.state.closed]
    ratios = {comparison_name(c): c.run_ratio for c in prim}
    return family_look(history.state, {n: diffs[n] for n in open_now},
                       {n: ratios[n] for n in open_now}, looks=list(looks),
                       max_runs=history.max_runs,
                       margin=None if margin is None else margin / 100,
                       not_learned={comparison_name(c): c.note for c in prim
                                    if c.verdict == NOT_LEARNED},
                       discordant={comparison_name(c): c.discordant_recordings
                                   for c in prim})


def first_look_to_run(stored_seeds: set[int], seed_order: Sequence[int],
                      looks: Sequence[int]) -> int:
    """The index of the first look whose seeds cover every seed already stored: a
    resumed run plans at least those (one out folder holds one grid)."""
    if not stored_seeds:
        return 0
    unknown = stored_seeds - set(seed_order)
    if unknown:
        raise InputError(f"the out folder holds runs of seed(s) {sorted(unknown)[:5]} this "
                         f"run --until answered does not plan; give a new --out, or --seed "
                         f"to include them")
    last = max(seed_order.index(s) for s in stored_seeds) + 1
    return next(k for k, n in enumerate(looks) if n >= last)


def beyond_looks(looks: Mapping[str, Any]) -> str:
    """Where more runs are stored than the last look used: the tables use them all, the
    verdicts only the looks'."""
    stored, seen = looks.get("runs_stored"), looks.get("looks") or ()
    used = seen[-1]["runs"] if seen else 0
    if not stored or stored <= used:
        return ""
    return (f" {stored} runs are stored and the tables use them all; the looks, and the "
            f"verdicts they give, use the first {used} (the {stored - used} beyond: a "
            "batch not yet complete, or runs made under an earlier stopping rule or by "
            "hand; a verdict a look reached does not change).")


def budget_stop(design: Design, elapsed: float, next_batch: float) -> str | None:
    """Why ``--budget`` ends a run after a look, or None where it goes on: the next
    batch, taking about ``next_batch`` seconds, would end past the design's budget with
    ``elapsed`` seconds spent (no batch is begun that the budget cannot hold)."""
    if design.budget_seconds is None or elapsed + next_batch <= design.budget_seconds:
        return None
    return (f"the budget of {design.budget}: {elapsed / 60:.1f} min spent, the next batch "
            f"would take about {next_batch / 60:.1f} more")
