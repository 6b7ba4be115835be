"""The variance of a paired difference split into split, initialisation and test sampling
(tactbench/runner/analysis/variance.py), and where comparisons carry it (results.json, report.md).

The simulation: each split seed draws a split effect (SD ``sd_split``) and a test set;
A is right on a recording where its difficulty u < 0.7 (the same in every init seed of a
split); B is right where w < 0.7 + δ, δ = 5 points + split effect + init effect (SD
``sd_init``), w being the recording's u with probability 0.6 (B errs on A's hard
recordings) or a fresh uniform; on a users split a user's shift (SD ``sd_user``) moves B
on all its recordings. A run's true test-sampling variance is ``(π − δ²)/n`` with π
the probability that A and B disagree on a recording, known here in closed form; with
users, the variance of ``d − δ`` over the simulated runs.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactbench.errors import InputError
from tactbench.runner.analysis.variance import mean_variance, paired_variance_components
from prediction_rows import prediction_row  # tests/runner/prediction_rows.py


def _simulate(rng, *, splits=4, inits=4, n=300, sd_split=0.04, sd_init=0.03,
              per_user=1, sd_user=0.0):
    """(A, B, groups, test errors d − δ of every run, true test variances) of one
    simulated data set."""
    a, b, groups, errors, true = [], [], [], [], []
    for _ in range(splits):
        effect = rng.normal(0, sd_split)
        u = rng.random(n)
        g = np.arange(n) // per_user
        shift = rng.normal(0, sd_user, g.max() + 1)[g]
        rows_a, rows_b = [], []
        for _ in range(inits):
            delta = 0.05 + effect + rng.normal(0, sd_init)
            w = np.where(rng.random(n) < 0.6, u, rng.random(n))
            rows_a.append(u < 0.7)
            rows_b.append(w < 0.7 + delta + shift)
            errors.append(rows_b[-1].mean() - rows_a[-1].mean() - delta)
            p = 0.7 + delta  # B's chance; A's is 0.7: w = u (0.6) or a fresh uniform
            pi = 0.6 * abs(delta) + 0.4 * (0.7 * (1 - p) + 0.3 * p)
            true.append((pi - delta**2) / n)
        a.append(np.array(rows_a))
        b.append(np.array(rows_b))
        groups.append(g.astype(str))
    return a, b, groups, np.array(errors), np.array(true)


def test_the_components_are_recovered_on_average_over_simulated_data_sets():
    rng = np.random.default_rng(7)
    out, tests = [], []
    for _ in range(1000):
        a, b, _, _, true = _simulate(rng)
        out.append(paired_variance_components(a, b, truncate=False))
        tests.append(true)
    truth = {"split": 16.0, "init": 9.0, "test": 1e4 * np.concatenate(tests).mean()}
    for name, true in truth.items():
        est = np.array([o[f"{name}_var"] for o in out])
        # within 3.5 Monte Carlo standard errors (the plug-in test term is (n − 1)/n low)
        assert abs(est.mean() - true) < 3.5 * est.std() / np.sqrt(len(est)) + 0.01 * true, name
    assert {o["test_sampling"] for o in out} == {"per recording"}
    assert all(o["split_seeds"] == 4 and o["init_seeds"] == 4 for o in out)


def test_clustered_test_sampling_follows_errors_correlated_within_users():
    rng = np.random.default_rng(3)
    clustered, plain, errors = [], [], []
    for _ in range(400):
        a, b, g, e, _ = _simulate(rng, per_user=20, sd_user=0.1)
        clustered.append(paired_variance_components(a, b, g)["test_var"])
        plain.append(paired_variance_components(a, b)["test_var"])
        errors.append(e)
    true = 1e4 * np.concatenate(errors).var()
    # 15 users a test set: CR0 is low by about (G − 1)/G, and the true value is noisy
    assert 0.85 * true < np.mean(clustered) < 1.1 * true
    assert np.mean(plain) < 0.65 * true  # per recording misses the users' shared shifts


def test_one_recording_a_user_is_the_unclustered_variance_and_pi_minus_delta_squared():
    rng = np.random.default_rng(0)
    a, b, g, *_ = _simulate(rng, splits=3, inits=2, n=50)
    assert paired_variance_components(a, b, g) == paired_variance_components(a, b)
    D = b[0][0].astype(float) - a[0][0]
    pi, delta = np.mean(D != 0), D.mean()
    assert mean_variance(D) == pytest.approx((pi - delta**2) / 50)
    assert mean_variance(D, g[0]) == pytest.approx((pi - delta**2) / 50)


def test_shares_sum_to_one_and_a_negative_estimate_is_clipped():
    rng = np.random.default_rng(1)
    a, b, g, *_ = _simulate(rng, splits=2, inits=2, n=40, sd_split=0.0, sd_init=0.0)
    v = paired_variance_components(a, b, g)
    shares = [v[f"{k}_share"] for k in ("split", "init", "test")]
    assert sum(shares) == pytest.approx(1.0)
    assert v["total_var"] == pytest.approx(v["split_var"] + v["init_var"] + v["test_var"])
    for name in v["clipped"]:
        assert v[f"{name}_var"] == 0
    raw = paired_variance_components(a, b, g, truncate=False)
    assert raw["test_var"] == v["test_var"] and set(v["clipped"]) == {
        k for k in ("split", "init") if raw[f"{k}_var"] < 0}
    json.dumps(v, allow_nan=False)


@pytest.mark.parametrize("args, match", [
    (([np.ones((2, 5))], [np.ones((2, 5))]), "at least 2 split seeds"),
    (([np.ones((1, 5))] * 2, [np.ones((1, 5))] * 2), "same init seeds"),
    (([np.ones((2, 5)), np.ones((3, 5))], [np.ones((2, 5)), np.ones((3, 5))]), "same init"),
    (([np.ones((2, 5))] * 2, [np.ones((2, 4))] * 2), "one shape"),
    (([np.ones((2, 5))] * 2, [np.ones((2, 5))] * 2, [np.arange(4)] * 2), "groups for 5"),
    (([np.ones((2, 5))] * 2, [np.ones((2, 5))] * 2, [np.zeros(5)] * 2), "2 test groups"),
])
def test_shapes_that_cannot_be_decomposed_are_refused(args, match):
    with pytest.raises(InputError, match=match):
        paired_variance_components(*args)


# ------------------------------------------------------------------ in the comparisons


def _row(encoder, seed, truth, predicted):
    # each split seed tests recordings of its own (a seed repeating a split's test set
    # would be the same split, counted once: pairing.distinct_splits)
    return prediction_row(encoder, seed, truth, predicted, split="users", n_train=120,
                          indices=range(seed * len(truth), (seed + 1) * len(truth)))


def _rows(inits, splits=3, users=None):
    """Rows of two cells (raw, farneback) on 40 recordings, per split and init seed."""
    truth = [0, 1] * 20
    rows = []
    rng = np.random.default_rng(5)
    for split in range(splits):
        for init in inits:
            for encoder, miss in (("raw", 0.3), ("farneback", 0.15)):
                predicted = [1 - t if rng.random() < miss else t for t in truth]
                row = _row(encoder, split, truth, predicted)
                if init is not None:
                    row.update(init_seed=init, key=f"{row['key']}-{init}")
                if users:
                    row["test_predictions"]["groups"] = [f"u{i // users}" for i in range(40)]
                rows.append(row)
    return rows


def test_a_comparison_over_init_seeds_carries_the_decomposition_and_reads_back(tmp_path):
    from tactbench.runner.analysis.comparisons import Comparison, comparisons
    from tactbench.runner.orchestrate import write_reports

    [c] = comparisons(_rows([0, 1]))
    v = c.variance_components
    assert (v["split_seeds"], v["init_seeds"], v["test_sampling"]) == (3, 2, "per recording")
    assert Comparison.from_dict(json.loads(json.dumps(c.to_dict()))) == c
    [clustered] = comparisons(_rows([0, 1], users=10))
    assert clustered.variance_components["test_sampling"] == "clustered by group"
    assert clustered.variance_components["groups"] == 4
    paths = write_reports(tmp_path, _rows([0, 1]), plots=False)
    doc = json.loads(paths["json"].read_text())
    assert doc["comparisons"][0]["variance_components"] == v
    assert "### Where the difference's variance comes from" in paths["markdown"].read_text()


def test_without_init_seeds_or_with_one_there_is_none(tmp_path):
    from tactbench.runner.analysis.comparisons import Comparison, comparisons
    from tactbench.runner.orchestrate import write_reports

    for rows in (_rows([None]), _rows([0]), _rows([0, 1], splits=1),
                 _rows([0, 1], users=40)):  # one test user a split seed
        [c] = comparisons(rows)
        assert c.variance_components is None
    entry = c.to_dict()
    del entry["variance_components"]  # a report made before the field: still reads
    assert Comparison.from_dict(entry).variance_components is None
    text = write_reports(tmp_path, _rows([None]), plots=False)["markdown"].read_text()
    assert "variance comes from" not in text


def test_a_stored_decomposition_of_the_wrong_kind_is_refused():
    from tactbench.errors import CorruptArtefactError
    from tactbench.runner.analysis.comparisons import Comparison, comparisons

    [c] = comparisons(_rows([0, 1]))
    entry = c.to_dict()
    entry["variance_components"] = dict(entry["variance_components"], test_sampling="?")
    with pytest.raises(CorruptArtefactError, match="variance_components"):
        Comparison.from_dict(entry)


# ------------------------------------------------------------------ end to end


@pytest.mark.parametrize("init_seeds", [["--init-seed", "0-1"], []])
def test_a_tiny_run_with_init_seeds_decomposes_its_comparison(tmp_path, monkeypatch, init_seeds):
    """`tactbench run --seed 0-1 --init-seed 0-1`: results.json and report.md carry the
    decomposition of the difference; the same run without --init-seed does not."""
    from click.testing import CliRunner

    from tactbench.cli import cli

    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "out"
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    args = ["run", "--dataset", "synthetic-forearm:users=2,repetitions=1", "--encoder", "raw",
            "--encoder", "frame-diff", "--classifier", "logreg:max_iter=20", "-L", "2",
            "--seed", "0-1", *init_seeds, "--threads", "1", "--out", str(out),
            "--no-plots", str(scene)]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    [c] = json.loads((out / "results.json").read_text())["comparisons"]
    report = (out / "report.md").read_text()
    if init_seeds:
        v = c["variance_components"]
        assert (v["split_seeds"], v["init_seeds"]) == (2, 2)
        assert v["test_sampling"] == "per recording"  # paper split: a recording a group
        assert "### Where the difference's variance comes from" in report
        assert "| encoder | raw | frame-diff | logreg L=2 | 2 × 2 |" in report
    else:
        assert c["variance_components"] is None
        assert "variance comes from" not in report
