"""Whether a cell's model learned: its accuracy on its training windows and on its test
recordings, each against what guessing gives.

A comparison of two cells rests on both having learned something: a model at chance
(a network that collapsed on unscaled inputs, a classifier that predicts one class)
loses to anything, and "B better, +25 points" would then say only that A did not learn.
Every cell therefore records (:func:`learning_fields`, written by
:mod:`tactbench.runner.execution.cell`):

- ``train_accuracy``: the accuracy on a seeded sample of at most :data:`TRAIN_SAMPLE` of
  its training windows (all folds' together), and ``train_chance``, what guessing gives
  on them;
- ``chance_accuracy``: what guessing gives on its test recordings, the larger of 1/k and
  the test set's majority-class share (a model that always answers the commonest class
  scores that);
- ``learning``: that one run's status (:func:`learning_status`): :data:`LEARNED`;
  :data:`DID_NOT_LEARN` (the test accuracy is within noise of chance, and so is the
  accuracy on its own training windows) or :data:`DID_NOT_TRANSFER` (within noise on the
  test recordings, well above chance on the training windows). It describes the run;
  no verdict rests on it.

*Within noise* (:func:`within_noise`) is a one-sided exact binomial test: an accuracy
``a`` on ``n`` independent trials is within noise of a chance level ``c`` when
``P(X ≥ a·n)`` for ``X ~ Binomial(n, c)`` exceeds :data:`NOISE_ALPHA`.

**What a verdict rests on is the cell, not one run** (:func:`cell_learning`): one run's
test set can be small or lopsided (19 recordings of 4 classes), and a model 10 points
above chance fails a one-run test in about one run in eight, so "any run flagged" calls a
modest learner "not learned" the surer the more runs there are. A cell is judged from
all its runs together: :data:`DID_NOT_LEARN` where its mean training accuracy is near
guessing (Cohen's κ against the training chance below :data:`TRAIN_KAPPA_MIN`), whatever
its test p; else not learned where the test recordings of all its runs pooled cannot be
told from guessing (the exact test of :func:`pooled_p`, each run guessing at its own
chance level); else learned. Rows made before rows recorded these fields are judged when
read, from their test predictions (:func:`row_evidence`): :data:`NOT_ABOVE_CHANCE` where
the pooled test cannot tell them from guessing (they record no training accuracy).
Error rates of the rule, by simulation: docs/statistics.md ("not learned").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

#: What :func:`learning_status` may say of a cell.
LEARNED, DID_NOT_LEARN, DID_NOT_TRANSFER = "learned", "did not learn", "did not transfer"
STATUSES = (LEARNED, DID_NOT_LEARN, DID_NOT_TRANSFER)
#: The statuses that take every verdict away from the comparisons of the cell.
NOT_LEARNED_STATUSES = (DID_NOT_LEARN, DID_NOT_TRANSFER)
#: The status of a cell whose test accuracy is within noise of guessing and whose rows
#: record no training accuracy (rows made before they recorded it): judged when read.
NOT_ABOVE_CHANCE = "not above chance"
#: The row field holding a cell's status.
LEARNING_FIELD = "learning"
#: The one-sided level of the binomial test of "no better than guessing".
NOISE_ALPHA = 0.05
#: At most this many training windows are scored per fold (a seeded sample).
TRAIN_SAMPLE = 2000


def chance_level(labels: Sequence[int], k: int) -> float:
    """What guessing scores on ``labels`` (class indices, ``k`` classes): the larger of
    ``1/k`` and the commonest class's share (0 for no labels)."""
    import numpy as np

    labels = np.asarray(labels, dtype=np.int64)
    if labels.size == 0 or k < 1:
        return 0.0
    return max(1.0 / k, float(np.bincount(labels, minlength=k).max() / labels.size))


def within_noise(accuracy: float, chance: float, n: int) -> bool:
    """Whether ``accuracy`` on ``n`` independent trials cannot be told from ``chance``:
    the exact one-sided binomial p of at least that many right, each right with
    probability ``chance``, exceeds :data:`NOISE_ALPHA` (True for ``n < 1``)."""
    from scipy import stats

    if n < 1:
        return True
    right = int(round(accuracy * n))
    return float(stats.binom.sf(right - 1, n, min(1.0, max(0.0, chance)))) > NOISE_ALPHA


def learning_status(*, train_accuracy: float, train_chance: float, train_n: int,
                    test_accuracy: float, test_chance: float, test_n: int) -> str:
    """:data:`LEARNED` unless the test accuracy is within noise of ``test_chance`` (on
    ``test_n`` recordings); then :data:`DID_NOT_LEARN` if the training accuracy is within
    noise of ``train_chance`` too (on ``train_n`` trials), else :data:`DID_NOT_TRANSFER`."""
    if not within_noise(test_accuracy, test_chance, test_n):
        return LEARNED
    if within_noise(train_accuracy, train_chance, train_n):
        return DID_NOT_LEARN
    return DID_NOT_TRANSFER


def learning_fields(*, train_right: int, train_scored: int, train_chance: float,
                    train_recordings: int, truth: Sequence[int], predicted: Sequence[int],
                    k: int) -> dict[str, Any]:
    """A row's fields on learning (see the module docstring) from the training windows
    scored (``train_right`` of ``train_scored``, guessing ``train_chance``; the windows
    come from ``train_recordings`` recordings per fold) and the test recordings'
    ``truth`` and ``predicted`` classes."""
    import numpy as np

    truth, predicted = np.asarray(truth), np.asarray(predicted)
    test_accuracy = float((truth == predicted).mean()) if truth.size else 0.0
    train_accuracy = train_right / train_scored if train_scored else 0.0
    chance = chance_level(truth, k)
    return {"train_accuracy": float(train_accuracy), "train_chance": float(train_chance),
            "train_windows_scored": int(train_scored), "chance_accuracy": chance,
            LEARNING_FIELD: learning_status(
                train_accuracy=train_accuracy, train_chance=train_chance,
                train_n=min(train_scored, train_recordings), test_accuracy=test_accuracy,
                test_chance=chance, test_n=int(truth.size))}


def row_learning(row: Mapping[str, Any]) -> str | None:
    """The status a row records, None where it records none (a row made before)."""
    value = row.get(LEARNING_FIELD)
    return value if value in STATUSES else None


def not_learned(row: Mapping[str, Any]) -> bool:
    """Whether a row records that its model did not learn or did not transfer in that one
    run (a description of the run; verdicts rest on :func:`cell_learning`)."""
    return row_learning(row) in NOT_LEARNED_STATUSES


def _pct(value: Any) -> str:
    return "?" if not isinstance(value, (int, float)) else f"{100 * value:.0f} %"


def summary_learning(rows: Iterable[Mapping[str, Any]]) -> dict[str, list[int]]:
    """A summary's ``learning``: status → the seeds judged, where the cell's runs together
    did not learn (:func:`cell_learning`); empty where it learned or nothing tells."""
    judged = cell_learning(rows)
    if judged is None or judged.learned:
        return {}
    return {judged.status: list(judged.seeds)}


# ------------------------------------------------------------------ a cell's runs together

#: A cell's training accuracy this close to guessing is "did not learn", whatever its
#: test p: Cohen's κ of the training windows against their chance level,
#: ``(train − chance) / (1 − chance)``, below this. 0.10 is the lower half of Landis &
#: Koch's (1977) "slight" agreement; every learned cell of the stored reports has κ ≥ 0.29.
TRAIN_KAPPA_MIN = 0.10


@dataclass(frozen=True)
class CellLearning:
    """Whether one cell's model learned, judged from all its runs together
    (:func:`cell_learning`).

    ``status``: :data:`LEARNED`, :data:`DID_NOT_LEARN`, :data:`DID_NOT_TRANSFER` or
    :data:`NOT_ABOVE_CHANCE`; ``seeds``: the runs judged; ``test_n``, ``test_right``: the
    test recordings of all runs and how many were right; ``test_chance``: what guessing
    gets right on them (the runs' chance levels weighted by their recordings); ``p``: the
    pooled exact p of "no better than guessing"; ``train_accuracy``, ``train_chance``,
    ``train_kappa``: the runs' mean training accuracy, its chance level and κ (None where
    no row records it)."""

    status: str
    seeds: tuple[int, ...]
    test_n: int
    test_right: int
    test_chance: float
    p: float
    train_accuracy: float | None
    train_chance: float | None
    train_kappa: float | None

    @property
    def learned(self) -> bool:
        return self.status == LEARNED


def row_evidence(row: Mapping[str, Any]) -> tuple[int, int, float] | None:
    """(test recordings, right, chance level) of one row, from its test predictions (the
    chance level: :func:`chance_level` of its labels over its classes), so that a row made
    before rows recorded ``learning`` is judged when read; None without predictions."""
    import numpy as np

    tp = row.get("test_predictions")
    if not isinstance(tp, Mapping):
        return None
    labels, predicted = tp.get("labels"), tp.get("predictions")
    if not isinstance(labels, list) or not isinstance(predicted, list) or \
            len(labels) != len(predicted) or not labels:
        return None
    truth, guess = np.asarray(labels, dtype=np.int64), np.asarray(predicted, dtype=np.int64)
    k = len(row.get("classes") or ()) or int(max(truth.max(), guess.max())) + 1
    return int(truth.size), int((truth == guess).sum()), chance_level(truth, k)


def pooled_p(evidence: Sequence[tuple[int, int, float]]) -> float:
    """The exact one-sided p of ``Σ right`` over runs ``(n, right, chance)`` when each run
    guesses: ``P(Σ X_s ≥ Σ right_s)`` for independent ``X_s ~ Binomial(n_s, chance_s)``
    (their pmfs convolved); 1.0 for no evidence."""
    import numpy as np
    from scipy import stats

    if not evidence:
        return 1.0
    by_chance: dict[float, int] = {}  # runs guessing alike sum to one binomial
    for n, _, chance in evidence:
        c = min(1.0, max(0.0, float(chance)))
        by_chance[c] = by_chance.get(c, 0) + int(n)
    right = sum(r for _, r, _ in evidence)
    if len(by_chance) == 1:
        [(c, n)] = by_chance.items()
        return float(stats.binom.sf(right - 1, n, c))
    pmf = np.ones(1)
    for c, n in by_chance.items():
        pmf = np.convolve(pmf, stats.binom.pmf(np.arange(n + 1), n, c))
    return float(min(1.0, pmf[right:].sum()))


def cell_learning(rows: Iterable[Mapping[str, Any]]) -> CellLearning | None:
    """One cell's learning judged from its runs (``rows``) together, never from one run's
    noise: :data:`DID_NOT_LEARN` where the runs' mean training accuracy is near guessing
    (κ below :data:`TRAIN_KAPPA_MIN`), whatever the test says; else, where the test
    recordings of all runs pooled cannot be told from guessing (:func:`pooled_p` above
    :data:`NOISE_ALPHA`), :data:`DID_NOT_TRANSFER` (or :data:`NOT_ABOVE_CHANCE` where no
    row records its training accuracy); else :data:`LEARNED`. None where no row has test
    predictions."""

    rows = list(rows)
    judged = [(r, e) for r in rows if (e := row_evidence(r)) is not None]
    if not judged:
        return None
    evidence = [e for _, e in judged]
    p = pooled_p(evidence)
    test_n = sum(n for n, _, _ in evidence)
    trained = [(float(r["train_accuracy"]), float(r["train_chance"])) for r, _ in judged
               if all(isinstance(r.get(k), (int, float)) and math.isfinite(r[k])
                      for k in ("train_accuracy", "train_chance"))]
    train = chance = kappa = None
    if trained:
        train = sum(t for t, _ in trained) / len(trained)
        chance = sum(c for _, c in trained) / len(trained)
        kappa = (train - chance) / (1 - chance) if chance < 1 else 0.0
    if kappa is not None and kappa < TRAIN_KAPPA_MIN:
        status = DID_NOT_LEARN
    elif p > NOISE_ALPHA:
        status = DID_NOT_TRANSFER if kappa is not None else NOT_ABOVE_CHANCE
    else:
        status = LEARNED
    return CellLearning(
        status=status, seeds=tuple(sorted({int(r["seed"]) for r, _ in judged})),
        test_n=test_n, test_right=sum(r for _, r, _ in evidence),
        test_chance=sum(n * c for n, _, c in evidence) / test_n, p=p,
        train_accuracy=train, train_chance=chance, train_kappa=kappa)


def runs_text(seeds: Sequence[int]) -> str:
    """``runs 0, 1, 2`` (``run 3`` for one): the runs a cell was judged over."""
    return f"run{'s' if len(seeds) != 1 else ''} {', '.join(map(str, seeds))}"


def describe_cell(name: str, judged: CellLearning | None) -> str:
    """``raw did not learn over runs 0, 1, 2 (training windows 21 % where guessing gives
    20 %, κ 0.01 < 0.10; test 20 % of 750 recordings pooled, guessing 20 %, p 0.48)``:
    why a cell is not learned ("" where it learned or is unknown)."""
    if judged is None or judged.learned:
        return ""
    test = (f"test {_pct(judged.test_right / judged.test_n)} of {judged.test_n} recordings "
            f"pooled, guessing {_pct(judged.test_chance)}, p {judged.p:.2g}")
    if judged.train_kappa is None:
        train = "no training accuracy recorded"
    else:
        train = (f"training windows {_pct(judged.train_accuracy)} where guessing gives "
                 f"{_pct(judged.train_chance)}, κ {judged.train_kappa:.2f}")
        if judged.status == DID_NOT_LEARN:
            train += f" < {TRAIN_KAPPA_MIN:.2f}"
    return f"{name} {judged.status} over {runs_text(judged.seeds)} ({train}; {test})"
