"""Where the variance of a paired difference comes from: split, initialisation, test sampling.

A pure function (arrays in, numbers out): :func:`paired_variance_components` takes, for
each split seed, whether cell A and cell B were right on each test recording in each of
its init seeds' runs, and splits the variance of the per-run difference
``d = acc_B − acc_A`` into three method-of-moments components (docs/statistics.md,
"Where the difference's variance comes from", gives the formulas and an example):

- **test sampling**: for each run, the variance of its mean difference over draws of
  the test recordings, ``(π − δ²)/n`` (π the share of discordant recordings, δ the
  difference, n the recordings), averaged over runs; where the recordings are grouped
  (the users of a users split), the cluster-robust variance of that mean over the
  groups, ``Σ_g (Σ_{i∈g} D_i − n_g·δ)² / n²`` (equal to ``(π − δ²)/n`` with one
  recording a group);
- **initialisation**: the within-split-seed variance of d over init seeds, less the
  test-sampling noise that does not cancel between runs on the same test recordings;
- **split**: the variance of the split seeds' mean d, less what initialisation
  (``init / J``) and the test sampling shared by a split's runs contribute to it.

Hand-written over numpy: the moments are a few sums of squares, and the clustered
variance is a matrix product with the group indicator; no library decomposes a paired
difference of per-recording outcomes with a test set shared by a split's runs.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from tactbench.errors import InputError

#: The components, in the order reports show them.
COMPONENTS = ("split", "init", "test")
#: The fewest split seeds and init seeds (every split seed with the same init seeds) a
#: decomposition needs: one variance across each, so 2 of each; with 2 split seeds the
#: split component rests on one degree of freedom (a rough number, said so in the docs).
MIN_SPLIT_SEEDS = 2
MIN_INIT_SEEDS = 2
#: How the test-sampling component was computed.
TEST_SAMPLING = ("clustered by group", "per recording")


def mean_variance(values: np.ndarray, groups: np.ndarray | None = None) -> np.ndarray:
    """The variance of the mean over the last axis of ``values`` (``(..., n)``) over
    draws of its n recordings: ``Σ_i (x_i − x̄)² / n²`` (the plug-in ``var/n``, ddof = 0),
    or, with ``groups`` (``(n,)``, a label each), the cluster-robust (CR0) version over
    the groups, ``Σ_g (Σ_{i∈g} (x_i − x̄))² / n²`` — the same with one recording a group."""
    x = np.asarray(values, dtype=np.float64)
    n = x.shape[-1]
    dev = x - x.mean(axis=-1, keepdims=True)
    if groups is None:
        return (dev * dev).sum(axis=-1) / n**2
    _, inverse = np.unique(np.asarray(groups), return_inverse=True)
    indicator = np.zeros((n, int(inverse.max()) + 1))
    indicator[np.arange(n), inverse] = 1.0
    sums = dev @ indicator
    return (sums * sums).sum(axis=-1) / n**2


def _check_splits(correct_a: Sequence[Any], correct_b: Sequence[Any],
                  groups: Sequence[Any] | None) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Each split seed's per-recording differences ``D`` (``(J, n)``, B − A in {−1, 0,
    1}) with its groups (None without); :class:`InputError` on a shape that cannot be."""
    if len(correct_a) != len(correct_b):
        raise InputError(f"{len(correct_a)} split seeds for A and {len(correct_b)} for B")
    if groups is not None and len(groups) != len(correct_a):
        raise InputError(f"groups for {len(groups)} split seeds, runs for {len(correct_a)}")
    if len(correct_a) < MIN_SPLIT_SEEDS:
        raise InputError(f"a decomposition needs at least {MIN_SPLIT_SEEDS} split seeds, "
                         f"got {len(correct_a)}")
    out, inits = [], set()
    for s, (a, b) in enumerate(zip(correct_a, correct_b)):
        a, b = np.asarray(a), np.asarray(b)
        if a.ndim != 2 or a.shape != b.shape or a.shape[1] == 0:
            raise InputError(f"split seed {s}: A and B must be (init seeds, recordings) "
                             f"arrays of one shape, got {a.shape} and {b.shape}")
        g = None if groups is None else np.asarray(groups[s])
        if g is not None and g.shape != (a.shape[1],):
            raise InputError(f"split seed {s}: {g.shape} groups for {a.shape[1]} recordings")
        inits.add(a.shape[0])
        out.append((b.astype(np.float64) - a.astype(np.float64), g))
    if len(inits) != 1 or min(inits) < MIN_INIT_SEEDS:
        raise InputError(f"a decomposition needs the same init seeds (at least "
                         f"{MIN_INIT_SEEDS}) in every split seed, got {sorted(inits)}")
    return out


def paired_variance_components(correct_a: Sequence[Any], correct_b: Sequence[Any],
                               groups: Sequence[Any] | None = None, *,
                               truncate: bool = True) -> dict[str, Any]:
    """The variance of the per-run difference B − A split into split, initialisation and
    test sampling (points² and points).

    ``correct_a``/``correct_b``: one array per split seed, ``(J, n_s)`` booleans — row j
    whether the cell was right on each of the split's n_s test recordings in init seed
    j's run (the same J init seeds, and the same recordings across a split's runs);
    ``groups``: one ``(n_s,)`` array of group labels per split seed (the test users), or
    None. Test sampling is clustered by group where some group holds more than one
    recording (and then needs at least 2 groups in every split seed). With ``truncate`` a negative init or split estimate is reported as 0 and
    named in ``clipped``; without, the unbiased moments as they come.

    Returns ``split_seeds``, ``init_seeds``, ``test_sampling`` (``"clustered by group"``
    or ``"per recording"``), ``groups`` (the mean number of test groups of a split
    seed), ``<component>_var`` (points²), ``<component>_sd`` (points) and
    ``<component>_share`` (of ``total_var``, the sum of the three; None where it is 0)
    for ``split``, ``init`` and ``test``, ``observed_var`` (the sample variance of the
    per-run differences, for comparison) and ``clipped``.
    """
    splits = _check_splits(correct_a, correct_b, groups)
    clustered = any(g is not None and len(np.unique(g)) < len(g) for _, g in splits)
    if clustered and any(len(np.unique(g)) < 2 for _, g in splits):
        raise InputError("clustered test sampling needs at least 2 test groups in every "
                         "split seed: over one group (one test user) it cannot be estimated")
    per_run_test, shared_test, unshared_test, within, means, runs = [], [], [], [], [], []
    for D, g in splits:
        g = g if clustered else None
        j = D.shape[0]
        d = D.mean(axis=1)  # the runs' differences
        mean_d = D.mean(axis=0)  # per recording, over init seeds
        per_run_test.append(mean_variance(D, g).mean())
        shared_test.append(float(mean_variance(mean_d, g)))
        unshared_test.append(float(mean_variance(D - mean_d, g).sum()) / (j - 1))
        within.append(float(d.var(ddof=1)))
        means.append(float(d.mean()))
        runs.extend(d.tolist())
    j = splits[0][0].shape[0]
    test = float(np.mean(per_run_test))
    init = float(np.mean(within) - np.mean(unshared_test))
    split = float(np.var(means, ddof=1) - init / j - np.mean(shared_test))
    clipped = [name for name, v in (("split", split), ("init", init)) if truncate and v < 0]
    values = {"split": max(split, 0.0) if truncate else split,
              "init": max(init, 0.0) if truncate else init, "test": test}
    total = sum(values.values())
    out: dict[str, Any] = {
        "split_seeds": len(splits), "init_seeds": j,
        "test_sampling": TEST_SAMPLING[0] if clustered else TEST_SAMPLING[1],
        "groups": float(np.mean([len(np.unique(g)) if g is not None else D.shape[1]
                                 for D, g in splits]))}
    for name in COMPONENTS:
        v = 1e4 * values[name]
        out[f"{name}_var"] = v
        out[f"{name}_sd"] = float(np.sqrt(v)) if v >= 0 else -float(np.sqrt(-v))
        out[f"{name}_share"] = values[name] / total if total > 0 else None
    out.update(total_var=1e4 * total, observed_var=1e4 * float(np.var(runs, ddof=1)),
               clipped=clipped)
    return out
