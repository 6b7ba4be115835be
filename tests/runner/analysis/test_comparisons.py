"""Paired comparisons: the record, its JSON form, and folds read from the rows."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tactbench.errors import CorruptArtefactError
from tactbench.runner.analysis.comparisons import ADDED_FIELDS, Comparison, comparisons, read_comparisons
from tactbench.runner.analysis.statistics import corrected_t

REPORTS = Path(__file__).resolve().parents[3] / "docs" / "reports"

N, POSITIONS, USERS, K, SEEDS = 36, 6, 9, 3, range(4)
POSITION = [i % POSITIONS for i in range(N)]
USER = [i // 4 for i in range(N)]  # users cut across positions


def _position_fold_rows(*, with_folds: bool = True) -> tuple[list[dict], np.ndarray]:
    """Rows of a ``group:position:folds=3`` run made by hand, 4 split seeds: each seed
    deals the 6 positions into 3 folds; A is wrong on a third of fold 0's recordings and
    on one of fold 2's, B on one of fold 1's. Returns the rows and the K × seeds fold
    differences B − A, from the position folds the rows record."""
    truth = [i % 2 for i in range(N)]
    rows, expected = [], []
    for seed in SEEDS:
        fold = [(POSITION[i] + seed) % K for i in range(N)]
        order = sorted(range(N), key=lambda i: (fold[i], i))  # the cell's pooled fold order
        by_fold = {k: [i for i in order if fold[i] == k] for k in range(K)}
        wrong = {"raw": set(by_fold[0][: 4 + seed % 2]) | {by_fold[2][seed]},
                 "farneback": {by_fold[1][seed]}}
        for k in range(K):
            ids = by_fold[k]
            expected.append((sum(i in wrong["raw"] for i in ids)
                             - sum(i in wrong["farneback"] for i in ids)) / len(ids))
        for enc in ("raw", "farneback"):
            pred = [1 - truth[i] if i in wrong[enc] else truth[i] for i in order]
            tp = {"indices": order, "labels": [truth[i] for i in order], "predictions": pred}
            if with_folds:
                tp.update(folds=[fold[i] for i in order],
                          groups=[f"p{POSITION[i]}" for i in order])
            acc = sum(p == truth[i] for p, i in zip(pred, order)) / N
            rows.append({"key": f"{enc}-{seed}", "dataset": "d", "split": "group:position:folds=3",
                         "folds": K, "split_seed": seed, "encoder": enc, "classifier": "logreg",
                         "L": 5, "seed": seed, "status": "ok", "classes": ["a", "b"],
                         "accuracy": acc, "per_class_accuracy": {"a": acc, "b": acc},
                         "confusion": [[1, 0], [0, 1]], "n_train": 24, "n_test": N,
                         "test_predictions": tp})
    return rows, np.array(expected)


def test_a_position_fold_comparison_runs_over_the_position_folds_the_rows_record():
    """group:position:folds=3 over 4 seeds: the corrected t runs over the K × runs = 12
    fold differences of the position folds, not of folds drawn again over users."""
    rows, expected = _position_fold_rows()
    users = [f"u{u}" for u in USER]
    [c] = comparisons(rows, users=users)
    assert c.method == ("corrected repeated 3-fold t (Bouckaert–Frank) over 12 fold "
                        "differences")
    assert c.runs == 4 and c.df == 11 and c.ratio == pytest.approx(1 / 2)
    t = corrected_t(expected, 1 / 2)
    assert (c.low, c.high, c.t_p) == (pytest.approx(float(t["low"])),
                                      pytest.approx(float(t["high"])),
                                      pytest.approx(float(t["p"])))
    # the users play no part in the folds: the same comparison without them
    [plain] = comparisons(rows)
    assert (plain.low, plain.high, plain.df) == (c.low, c.high, c.df)
    # the run level is unchanged: the mean of the folds' differences is each seed's
    assert c.difference == pytest.approx(expected.mean())


def test_rows_without_fold_ids_fall_back_to_the_split_seeds_means_and_say_so():
    rows, _ = _position_fold_rows(with_folds=False)
    [c] = comparisons(rows)
    assert c.method == ("corrected repeated 3-fold t (Bouckaert–Frank) over 4 split-seed "
                        "means (the rows carry no fold ids)")
    assert c.df == 3
    d = np.array(list(c.per_run.values()))
    # seed means of K = 3 folds: the factor is K/(K − 1) = 3/2, not 1/(K − 1)
    assert c.ratio == c.run_ratio == pytest.approx(3 / 2)
    assert (c.low, c.high) == (pytest.approx(float(corrected_t(d, 3 / 2)["low"])),
                               pytest.approx(float(corrected_t(d, 3 / 2)["high"])))


def test_a_comparison_round_trips_through_its_json_form():
    rows, _ = _position_fold_rows()
    [c] = comparisons(rows, users=[f"u{u}" for u in USER], margin=2.0)
    entry = json.loads(json.dumps(c.to_dict()))
    assert list(entry)[:7] == ["dataset", "split", "factor", "a", "b", "classifier", "L"]
    assert Comparison.from_dict(entry) == c
    assert read_comparisons([c, entry]) == [c, c]


@pytest.mark.parametrize("damage, field", [
    (lambda e: e.pop("low"), "low"),
    (lambda e: e.update(runs="4"), "runs"),
    (lambda e: e.update(surprise=1), "surprise"),
    (lambda e: e["per_class"]["a"].pop("runs"), "per_class"),
    (lambda e: e.update(t_p=float("nan")), "t_p"),
])
def test_a_damaged_stored_comparison_is_refused_naming_the_field(damage, field):
    rows, _ = _position_fold_rows()
    [c] = comparisons(rows)
    entry = c.to_dict()
    damage(entry)
    with pytest.raises(CorruptArtefactError, match=f"out/results.json: .*{field}"):
        Comparison.from_dict(entry, source="out/results.json")


def test_every_stored_comparison_reads_back_as_a_record_and_writes_the_same_json():
    stored = sorted(REPORTS.glob("*/*/results.json"))
    assert stored
    for path in stored:
        for entry in json.loads(path.read_text())["comparisons"]:
            again = Comparison.from_dict(entry, source=str(path)).to_dict()
            kept = {k: v for k, v in again.items() if k in entry}
            assert kept == entry and list(kept) == list(entry)
            assert set(again) - set(entry) <= ADDED_FIELDS  # made before those fields


def test_a_field_added_after_a_report_was_made_reads_back_as_its_default(monkeypatch):
    from tactbench.runner.analysis import comparisons as module

    rows, _ = _position_fold_rows()
    [c] = comparisons(rows)
    entry = c.to_dict()
    del entry["note"]
    with pytest.raises(CorruptArtefactError, match="without 'note'"):
        Comparison.from_dict(entry)
    monkeypatch.setattr(module, "ADDED_FIELDS", frozenset({"note"}))
    assert Comparison.from_dict(entry) == replace(c, note="")
