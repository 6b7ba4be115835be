"""A folder's analysis: what its rows say, decided once, before anything is shown.

:func:`analyse` makes an :class:`Analysis` from rows alone (every row of a folder, ok and
failed, in the scene's order): the summaries over seeds, the paired comparisons and their
verdicts, the variance decomposition, the looks of a run ``--until answered`` and whether
they answered it (:attr:`Analysis.answered`, the decision a run's loop stops on), and the
runs that computed the rows. Presentation only formats an :class:`Analysis`
(:func:`tactbench.runner.presentation.writers.render`); the run's loop reads its
decisions here (:mod:`tactbench.runner.orchestrate`), never from a rendered report.
"""

from __future__ import annotations

import dataclasses
import shlex
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

from tactbench.runner.analysis.answering import History, comparison_name, replay
from tactbench.runner.analysis.comparisons import Comparison, comparisons
from tactbench.runner.analysis.paired_tests import (DEFAULT_CHOICE, DEFAULT_PAIRED_TEST,
                                                    PairedTestChoice)
from tactbench.runner.analysis.sequential import FUTILE
from tactbench.runner.analysis.statistics import DECIDED, NOT_LEARNED, UNRESOLVED
from tactbench.runner.analysis.summaries import summarise, variance_decomposition
from tactbench.runner.execution.results import command_line, failed_rows, ok_rows
from tactbench.runner.execution.scene import Design


@dataclass
class Analysis:
    """What a folder's rows say, decided: ``rows`` (every row, ok and failed, in the
    scene's order), ``summaries`` (one per dataset, split, encoder, classifier and L,
    over seeds), ``comparisons`` (paired over runs, each with its verdict), ``variance``,
    ``statistics`` (the options they were made with), ``runs`` (the command lines and git
    revisions that computed the rows), ``looks`` (a run ``--until answered``: every look,
    replayed; None for a fixed design) and ``history`` (the looks as computed, which the
    next look of the same run goes on from: :func:`analyse`'s ``resume``; in no file)."""

    rows: list[dict[str, Any]]
    summaries: list[dict[str, Any]]
    comparisons: list[Comparison]
    variance: list[dict[str, Any]]
    statistics: dict[str, Any]
    runs: list[dict[str, Any]]
    looks: dict[str, Any] | None = None
    history: History | None = field(default=None, repr=False, compare=False)
    #: why ``--budget`` ended a run ``--until answered`` after this look (None: it did not;
    #: :func:`~tactbench.runner.analysis.answering.budget_stop`)
    budget_stop: str | None = None

    @property
    def ok(self) -> list[dict[str, Any]]:
        """Rows of the cells that finished."""
        return ok_rows(self.rows)

    @property
    def failed(self) -> list[dict[str, Any]]:
        """Rows of the cells that raised (retried by the next run of the same scene)."""
        return failed_rows(self.rows)

    @property
    def answered(self) -> bool:
        """Whether the looks closed every primary question — decided, or futile (no
        number of runs up to the maximum can decide it) — so that a run
        ``--until answered`` stops (the looks' ``stopped_because`` tells the two apart);
        False for a fixed design."""
        return bool((self.looks or {}).get("answered"))


def analyse(rows: Sequence[dict[str, Any]], *, contrasts: Sequence[str] = (),
            margin: float | None = None, users: Sequence[str] | None = None,
            primary: Sequence[str] = (), sequential: Design | None = None,
            resume: History | None = None,
            paired_test: PairedTestChoice = DEFAULT_CHOICE) -> Analysis:
    """The :class:`Analysis` of ``rows`` (failed cells are kept in ``rows`` and left out
    of the summaries and comparisons).

    ``contrasts``, ``margin`` (points) and ``primary`` (the contrasts of the confirmatory
    family): see :func:`tactbench.runner.analysis.comparisons.comparisons`; ``users``: the
    user of each dataset sample (by index), for per-user results; ``sequential``: the
    :class:`~tactbench.runner.execution.scene.Design` of a run ``--until answered``, whose
    looks are replayed from the rows (:func:`tactbench.runner.analysis.answering.replay`;
    ``resume``: an earlier analysis's ``history`` of the same run, whose looks are not
    computed again); ``paired_test``: the test every comparison's p and interval come
    from (:mod:`tactbench.runner.analysis.paired_tests`), recorded in ``statistics``
    where it is not the default.
    """
    rows = list(rows)
    looks = history = None
    if sequential is not None and sequential.looks and primary:
        paired_test.check(None, sequential=True)  # the looks: one line, before any file
        history = replay(rows, seed_order=sequential.seed_order, looks=sequential.looks,
                         primary=primary, margin=margin, resume=resume)
        looks = history.as_dict()
        looks["budget"] = sequential.budget
        looks["train_cpu_seconds"] = training_cpu_seconds(rows)
        looks["runs_stored"] = len({int(r["seed"]) for r in ok_rows(rows)})
    comps = comparisons(rows, contrasts=contrasts, margin=margin, users=users, primary=primary,
                        paired_test=paired_test)
    if looks is not None:
        comps = [sequential_verdict(c, looks) if c.family == "primary" else c for c in comps]
    return Analysis(
        rows=rows, summaries=summarise(rows, users=users), comparisons=comps,
        variance=variance_decomposition(rows),
        statistics={"unit": "run (one split seed)", "contrasts": list(contrasts),
                    "margin": margin, "per_user": users is not None,
                    **({"primary": list(primary)} if primary else {}),
                    **({"paired_test": paired_test.name}
                       if paired_test.name != DEFAULT_PAIRED_TEST else {})},
        runs=computed_by(rows), looks=looks, history=history)


def sequential_verdict(c: Comparison, looks: dict[str, Any]) -> Comparison:
    """A primary comparison of a run ``--until answered`` with the verdict its looks
    reached: better, worse or equivalent where a look's boundary decided it, else
    unresolved with the looks' reason in the note. The fixed-design verdict at the last
    run count would ignore the looks before it (and overstate the evidence); the
    interval and p beside it stay the unadjusted ones, labelled so."""
    name = comparison_name(c)
    seen = [(lk["runs"], lk["comparisons"][name]) for lk in looks.get("looks", ())
            if name in lk["comparisons"]]
    if not seen or c.verdict == NOT_LEARNED:  # a run of its cells did not learn: no verdict
        return c
    runs, last = seen[-1]
    decided = (looks.get("decisions") or {}).get(name)
    if decided in DECIDED:
        return dataclasses.replace(c, verdict=decided, note=(
            f"group-sequential: decided at the look after {runs} runs, α spent over "
            f"{len(seen)} look(s)"))
    why = (f"futile after {runs} runs" + (f" ({last['why']})" if last.get("why") else "")
           if last["decision"] == FUTILE
           else f"no verdict in {len(seen)} look(s) up to {runs} runs ({last['why']})"
           if last.get("why")  # a boundary crossed below the minimum of evidence
           else f"no boundary crossed in {len(seen)} look(s) up to {runs} runs")
    return dataclasses.replace(c, verdict=UNRESOLVED, note=f"group-sequential: {why}")


def training_cpu_seconds(rows: Iterable[dict[str, Any]]) -> float | None:
    """The training CPU-seconds (every thread of the fitting process) summed over the
    ok rows that record it; None when none does (rows from before it was recorded)."""
    values = []
    for row in ok_rows(list(rows)):
        fits = row.get("fit")
        for fit in fits if isinstance(fits, list) else [fits]:
            value = fit.get("train_cpu_seconds") if isinstance(fit, dict) else None
            if isinstance(value, (int, float)) and value >= 0:
                values.append(float(value))
    return sum(values) if values else None


def computed_by(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The runs that computed ``rows``: ``{"command", "git", "cells"}`` for each distinct
    command line and git revision a row records (``run``), the earliest first. A command
    is shown as :func:`~tactbench.runner.execution.results.command_line` writes it (rows from
    before it kept the program's path: ``/src/tactbench/__main__.py run`` is
    ``tactbench run``)."""
    runs: dict[tuple, dict[str, Any]] = {}
    for row in sorted(rows, key=lambda r: (str(r.get("finished", "")), str(r.get("key")))):
        run = row.get("run") if isinstance(row.get("run"), dict) else {}
        command = run.get("command")
        try:
            command = command_line(shlex.split(command)) if isinstance(command, str) \
                else command
        except ValueError:  # unbalanced quotes: shown as recorded
            pass
        entry = runs.setdefault((str(command), str(run.get("git"))), {
            "command": command, "git": run.get("git"), "cells": 0})
        entry["cells"] += 1
    return list(runs.values())
