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
- ``learning``: :data:`LEARNED`; :data:`DID_NOT_LEARN` (the test accuracy is within noise
  of chance, and so is the accuracy on its own training windows: the fit found nothing);
  or :data:`DID_NOT_TRANSFER` (within noise of chance on the test recordings, well above
  it on the training windows: it fitted what does not carry over).

*Within noise* (:func:`within_noise`) is a one-sided exact binomial test: an accuracy
``a`` on ``n`` independent trials is within noise of a chance level ``c`` when
``P(X ≥ a·n)`` for ``X ~ Binomial(n, c)`` exceeds :data:`NOISE_ALPHA`, that is, when
"no better than guessing" cannot be rejected at 5 %. The trials are the test recordings
for the test accuracy; for the training windows, which overlap and share recordings,
the training recordings (at most the windows scored), so the bound is not narrowed by
counting one recording's windows as many trials. Only a test accuracy within noise
marks a cell; the training accuracy tells the two reasons apart.

Rows made before these fields existed have none: their learning is unknown
(:func:`row_learning` gives None), never "did not learn".
"""

from __future__ import annotations

from typing import Any, Callable, Iterable, Mapping, Sequence

#: What :func:`learning_status` may say of a cell.
LEARNED, DID_NOT_LEARN, DID_NOT_TRANSFER = "learned", "did not learn", "did not transfer"
STATUSES = (LEARNED, DID_NOT_LEARN, DID_NOT_TRANSFER)
#: The statuses that take every verdict away from the comparisons of the cell.
NOT_LEARNED_STATUSES = (DID_NOT_LEARN, DID_NOT_TRANSFER)
#: The row field holding a cell's status.
LEARNING_FIELD = "learning"
#: The one-sided level of the binomial test of "no better than guessing".
NOISE_ALPHA = 0.05
#: At most this many training windows are scored per fold (a seeded sample).
TRAIN_SAMPLE = 2000
#: The mark of a flagged cell's accuracy in the tables.
MARK = "†"


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
    """Whether a row records that its model did not learn or did not transfer."""
    return row_learning(row) in NOT_LEARNED_STATUSES


def _pct(value: Any) -> str:
    return "?" if not isinstance(value, (int, float)) else f"{100 * value:.0f} %"


def describe(name: str, rows: Iterable[Mapping[str, Any]]) -> str:
    """``raw did not learn in run 0, 2 (test 20 % where guessing gives 20 %, training
    windows 21 %)``: the runs of one cell whose model did not learn or transfer, by
    status ("" where none)."""
    parts = []
    flagged = [r for r in rows if not_learned(r)]
    for status in NOT_LEARNED_STATUSES:
        these = sorted((r for r in flagged if r[LEARNING_FIELD] == status),
                       key=lambda r: int(r["seed"]))
        if not these:
            continue
        seeds = list(dict.fromkeys(str(r["seed"]) for r in these))
        worst = max(these, key=lambda r: r.get("accuracy", 0.0))
        runs = f"run{'s' if len(seeds) > 1 else ''} {', '.join(seeds)}"
        parts.append(f"{name} {status} in {runs} (test up to {_pct(worst['accuracy'])}"
                     f" where guessing gives {_pct(worst.get('chance_accuracy'))}, its "
                     f"training windows {_pct(worst.get('train_accuracy'))})")
    return "; ".join(parts)


def flagged_runs(rows: Iterable[Mapping[str, Any]]) -> dict[str, list[int]]:
    """Status → the seeds of ``rows`` (one cell's) recorded as not learned, for a
    summary's ``learning`` (empty where every run learned or none recorded it)."""
    out: dict[str, list[int]] = {}
    for r in rows:
        seeds = out.setdefault(r[LEARNING_FIELD], []) if not_learned(r) else None
        if seeds is not None and int(r["seed"]) not in seeds:
            seeds.append(int(r["seed"]))
    return out


def accuracy_mark(summary: Mapping[str, Any]) -> str:
    """:data:`MARK` after a summary's accuracy where a run of it did not learn."""
    return f" {MARK}" if summary.get(LEARNING_FIELD) else ""


def legend(summaries: Sequence[Mapping[str, Any]], label: Callable[[Any], str]) -> list[str]:
    """The lines under a table of ``summaries`` explaining :data:`MARK` (none without
    one); ``label(summary)`` names a cell."""
    marked = [s for s in summaries if s.get(LEARNING_FIELD)]
    if not marked:
        return []
    lines = [f"{MARK} In some runs the model did not learn or did not transfer: its test "
             f"accuracy is within noise of guessing (1/k or the majority class; one-sided "
             f"binomial test at {NOISE_ALPHA:g}); no comparison with the cell gets a "
             f"verdict (docs/reliability.md)."]
    for s in marked:
        runs = "; ".join(f"{status} in run{'s' if len(seeds) > 1 else ''} "
                         f"{', '.join(map(str, seeds))}"
                         for status, seeds in s[LEARNING_FIELD].items())
        lines.append(f"{MARK} {label(s)}: {runs}.")
    return lines
