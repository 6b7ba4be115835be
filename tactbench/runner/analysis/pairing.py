"""How the rows of two cells pair up, recording by recording, run by run.

A comparison (:mod:`tactbench.runner.analysis.comparisons`) pairs the test recordings both cells
predicted in each run: :func:`aligned` finds them (with the fold that tested each, as the
rows record it), and the functions here reduce them to what a comparison reports beside
its run-level tests: the recordings the cells disagree on and McNemar's p per seed, the
per-fold differences of a K-fold design, per-class and per-user gains, the share of
the per-run variance that test sampling explains, and (with init seeds) that variance
split into split, initialisation and test sampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np

from tactbench.runner.analysis.statistics import corrected_t, mcnemar_p
from tactbench.runner.analysis.variance import (
    MIN_INIT_SEEDS,
    MIN_SPLIT_SEEDS,
    paired_variance_components,
)


@dataclass(frozen=True)
class ClassGain:
    """The gain B − A on one class's test recordings: the mean over runs, its run-level
    interval (None where fewer than 2 runs test the class) and the runs that test it."""

    difference: float
    low: float | None
    high: float | None
    runs: int


@dataclass(frozen=True)
class UserGains:
    """Per-user gains B − A (accuracy fractions): users tested, helped (gain > 0), hurt
    (gain < 0), the median and quartiles of the gains, and user → gain."""

    users: int
    helped: int
    hurt: int
    median: float
    q25: float
    q75: float
    gains: dict[str, float]


class Run(NamedTuple):
    """One run's test recordings both cells predicted with the same label: their ids,
    true labels, whether A and B were right, their fold ids and their groups (the test
    user on a users split; None: not in the rows)."""

    ids: np.ndarray
    y: np.ndarray
    ca: np.ndarray
    cb: np.ndarray
    folds: np.ndarray | None
    groups: np.ndarray | None = None


def _predictions(row: dict[str, Any]) -> dict[int, tuple[int, int]]:
    """Test sequence index → (true label, predicted label) of one row."""
    tp = row["test_predictions"]
    return {int(i): (int(t), int(p))
            for i, t, p in zip(tp["indices"], tp["labels"], tp["predictions"])}


def _fold_ids(row: dict[str, Any]) -> dict[int, int] | None:
    """Test sequence index → the fold that tested it, as the row records it (None for a
    row made before rows kept their folds)."""
    tp = row["test_predictions"]
    if tp.get("folds") is None:
        return None
    return {int(i): int(f) for i, f in zip(tp["indices"], tp["folds"])}


def _group_ids(row: dict[str, Any]) -> dict[int, str] | None:
    """Test sequence index → the group it was left out with (its user on a users split),
    as the row records it (None for a row made before rows kept their groups)."""
    tp = row["test_predictions"]
    if tp.get("groups") is None:
        return None
    return {int(i): str(g) for i, g in zip(tp["indices"], tp["groups"])}


def aligned(row_a: dict[str, Any], row_b: dict[str, Any]) -> Run:
    """The test sequences both rows predicted with the same label; their fold ids and
    groups where both rows record the same for each (None otherwise)."""
    ta, tb = _predictions(row_a), _predictions(row_b)
    ids = [i for i in sorted(set(ta) & set(tb)) if ta[i][0] == tb[i][0]]
    fa, fb = _fold_ids(row_a), _fold_ids(row_b)
    folds = None
    if fa is not None and fb is not None and all(fa[i] == fb[i] for i in ids):
        folds = np.array([fa[i] for i in ids], dtype=np.int64)
    ga, gb = _group_ids(row_a), _group_ids(row_b)
    groups = None
    if ga is not None and gb is not None and all(ga[i] == gb[i] for i in ids):
        groups = np.array([ga[i] for i in ids], dtype=str)
    return Run(np.array(ids, dtype=np.int64), np.array([ta[i][0] for i in ids], dtype=np.int64),
                np.array([ta[i][1] == ta[i][0] for i in ids], dtype=bool),
                np.array([tb[i][1] == tb[i][0] for i in ids], dtype=bool), folds, groups)


def recordings(per_seed: Mapping[tuple, Run]) -> dict[str, Any]:
    """The rows and recordings the cells disagree on, and McNemar's p per seed."""
    discordant: set[int] = set()
    recordings: set[int] = set()
    for run in per_seed.values():
        discordant.update(run.ids[run.ca != run.cb].tolist())
        recordings.update(run.ids.tolist())
    return {"a_only": sum(int(np.sum(r.ca & ~r.cb)) for r in per_seed.values()),
            "b_only": sum(int(np.sum(r.cb & ~r.ca)) for r in per_seed.values()),
            "discordant_recordings": len(discordant), "test_recordings": len(recordings),
            "mcnemar_per_seed": {_seed_label(k): mcnemar_p(r.ca, r.cb)
                                 for k, r in per_seed.items()}}


def fold_differences(per_seed: Mapping[tuple, Run], splits: Mapping[int, list[tuple]]
                      ) -> np.ndarray | None:
    """The differences B − A of every (split seed, fold), each fold's test recordings
    found by the fold ids the rows record (a split seed's init seeds averaged); None
    where a run has no fold ids, or fewer than 2 differences come out."""
    out = []
    for keys in splits.values():
        if any(per_seed[k].folds is None for k in keys):
            return None
        for fold in sorted({int(f) for k in keys for f in per_seed[k].folds}):
            vals = []
            for key in keys:
                run = per_seed[key]
                m = run.folds == fold
                if m.any():
                    vals.append(float(run.cb[m].mean() - run.ca[m].mean()))
            out.append(float(np.mean(vals)))
    return np.array(out) if len(out) >= 2 else None


def sampling_share(per_seed: Mapping[tuple, Run], splits: Mapping[int, list[tuple]],
                         d_run: np.ndarray) -> float | None:
    """The share of the variance of the per-run differences that test sampling accounts
    for: the mean over runs of ``(π − δ²)/n`` (π: the share of the run's recordings the
    cells disagree on, δ its difference, n its recordings; a split seed's init seeds
    averaged) over the variance of ``d_run``. None with fewer than 2 runs or no spread.
    An estimate: above 1 where the runs happened to agree more than test sampling alone
    would make them."""
    if len(d_run) < 2 or float(d_run.var(ddof=1)) == 0:
        return None
    parts = []
    for keys in splits.values():
        v = []
        for k in keys:
            r = per_seed[k]
            pi, delta = float(np.mean(r.ca != r.cb)), float(r.cb.mean() - r.ca.mean())
            v.append(max(0.0, pi - delta * delta) / len(r.ids))
        parts.append(float(np.mean(v)) / len(keys))
    return float(np.mean(parts) / d_run.var(ddof=1))


def difference_components(per_seed: Mapping[tuple, Run], splits: Mapping[int, list[tuple]]
                          ) -> dict[str, Any] | None:
    """The variance of the per-run difference split into split, initialisation and test
    sampling (:func:`tactbench.runner.analysis.variance.paired_variance_components`), over the
    init seeds every split seed ran (at least 2, in at least 2 split seeds) and, within a
    split seed, the test recordings all its runs paired; test sampling clustered by the
    groups the rows record (the users of a users split). None where the runs do not vary
    the initialisation that far, or a split seed tests a single group (one user)."""
    inits = set.intersection(*({k[1] for k in keys} for keys in splits.values()))
    inits.discard(None)
    if len(splits) < MIN_SPLIT_SEEDS or len(inits) < MIN_INIT_SEEDS:
        return None
    correct_a, correct_b, groups = [], [], []
    for split in splits:
        runs = [per_seed[(split, i)] for i in sorted(inits)]
        ids = np.array(sorted(set.intersection(*(set(r.ids.tolist()) for r in runs))))
        if not len(ids):
            return None
        at = [np.searchsorted(r.ids, ids) for r in runs]
        correct_a.append(np.array([r.ca[m] for r, m in zip(runs, at)]))
        correct_b.append(np.array([r.cb[m] for r, m in zip(runs, at)]))
        groups.append(None if runs[0].groups is None else runs[0].groups[at[0]])
    use = None if any(g is None for g in groups) else groups
    if use is not None and any(len(set(g.tolist())) < 2 for g in use):
        return None  # one test user a split seed: no variance over users to estimate
    return paired_variance_components(correct_a, correct_b, use)


def _seed_label(key: tuple) -> str:
    return str(key[0]) if key[1] is None else f"{key[0]}/{key[1]}"


def per_class_gains(per_seed: Mapping[tuple, Run], splits: Mapping[int, list[tuple]],
                     classes: Sequence[str], ratio: float, confidence: float
                     ) -> dict[str, ClassGain]:
    """Class → gain B − A on that class's test sequences, per run, with the run-level
    interval (None where fewer than 2 runs test the class)."""
    out = {}
    for c, name in enumerate(classes):
        d = []
        for ks in splits.values():
            vals = [per_seed[k].cb[per_seed[k].y == c].mean()
                    - per_seed[k].ca[per_seed[k].y == c].mean()
                    for k in ks if np.any(per_seed[k].y == c)]
            if vals:
                d.append(float(np.mean(vals)))
        if not d:
            continue
        low = high = None
        if len(d) >= 2:
            t = corrected_t(np.array(d), ratio, confidence=confidence)
            low, high = max(-1.0, float(t["low"])), min(1.0, float(t["high"]))
        out[name] = ClassGain(difference=float(np.mean(d)), low=low, high=high, runs=len(d))
    return out


def per_user_gains(per_seed: Mapping[tuple, Run], users: Sequence[str]) -> UserGains:
    """Per user (the test sequences of each user, over the runs that test them): the
    gain B − A, and how many users it helped or hurt, its median and quartiles."""
    users = list(users)
    gains: dict[str, list[float]] = {}
    for run in per_seed.values():
        who = np.array([str(users[i]) for i in run.ids])
        for u in dict.fromkeys(who.tolist()):
            m = who == u
            gains.setdefault(u, []).append(float(run.cb[m].mean() - run.ca[m].mean()))
    per_user = {u: float(np.mean(g)) for u, g in sorted(gains.items())}
    values = np.array(list(per_user.values()))
    q25, q50, q75 = np.percentile(values, [25, 50, 75]) if values.size else (math.nan,) * 3
    return UserGains(users=len(per_user), helped=int(np.sum(values > 0)),
                     hurt=int(np.sum(values < 0)), median=float(q50), q25=float(q25),
                     q75=float(q75), gains=per_user)


def distinct_splits(splits: Mapping[int, list[tuple]], rows: Mapping[tuple, dict[str, Any]]
                    ) -> tuple[dict[int, list[tuple]], dict[int, int]]:
    """The split seeds of ``splits`` (split seed → its run keys) grouped by the split
    they drew — the same test recordings (``test_predictions.indices``) and training
    size — so that seeds that repeat a split count once, their runs averaged like init
    seeds of one split (few sessions or people allow few distinct splits: 4 sessions,
    one left out, give 4). Rows that record no test groups are each a split of their
    own, as before. Returns the grouped splits (keyed by each split's first seed)
    and ``repeats``: seed → the earlier seed whose split it repeats."""
    first: dict[tuple, int] = {}
    out: dict[int, list[tuple]] = {}
    repeats: dict[int, int] = {}
    for seed, keys in splits.items():
        row = rows[keys[0]]
        predictions = row.get("test_predictions") or {}
        indices = predictions.get("indices")
        if not isinstance(indices, list) or not isinstance(predictions.get("groups"), list):
            # rows that record no test groups (made before they did) read as before
            out[seed] = list(keys)
            continue
        identity = (tuple(sorted(int(i) for i in indices)), row.get("n_train"))
        seen = first.setdefault(identity, seed)
        if seen != seed:
            repeats[seed] = seen
        out.setdefault(seen, []).extend(keys)
    return out, repeats


def repeats_note(repeats: Mapping[int, int], distinct: int) -> str:
    """``4 distinct splits of 6 runs: runs 4, 5 repeat the splits of runs 0, 1, each
    split's runs averaged as one``."""
    seeds = sorted(repeats)
    return (f"{distinct} distinct splits of {distinct + len(repeats)} runs: run"
            f"{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))} repeat"
            f"{'' if len(seeds) > 1 else 's'} the split{'s' if len(seeds) > 1 else ''} of "
            f"run{'s' if len(seeds) > 1 else ''} "
            f"{', '.join(str(repeats[k]) for k in seeds)}, each split's runs averaged as one")
