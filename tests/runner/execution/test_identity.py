"""The "left out of the identity at its default" rule, written once (identity.py), and the
migration of rows keyed before a field entered identities."""

from __future__ import annotations

import pytest

from tactbench.runner.execution import identity as ident
from tactbench.runner.execution.identity import (IDENTITY_DEFAULTS, digest, migrated_row,
                                                 row_identity, row_keys, without_defaults)
from tactbench.runner.execution.planning import row_key_problem
from tactbench.runner.execution.results import ResultStore

BASE = {"schema": 1, "dataset": "d", "dataset_hash": "h", "split": "paper",
        "test_per_class": 3, "imaging": {"kind": "vectors"}, "encoder": "raw",
        "encoder_version": "1", "classifier": "logreg", "profile": "quick", "L": 3,
        "seed": 0}


def _row(key_of: dict, **recorded) -> dict:
    """A stored row of ``BASE`` keyed by ``key_of``, recording ``recorded``."""
    return {**BASE, **recorded, "key": digest(key_of), "status": "failed",
            "error": {"type": "E", "message": "m", "traceback": ""}}


def test_every_field_is_left_out_at_its_default_by_one_rule():
    at_defaults = {**BASE, **IDENTITY_DEFAULTS}
    assert without_defaults(at_defaults) == BASE
    assert row_identity(at_defaults) == BASE  # a row reads back as its identity was made
    changed = {**at_defaults, "threads": 2, "device": "cuda", "precision": "uint8"}
    assert without_defaults(changed) == {**BASE, "threads": 2, "device": "cuda",
                                         "precision": "uint8"}
    assert ident.compute_identity(1) == {}  # a 1-thread CPU cell on AVX2: nothing added
    assert ident.compute_identity(2, "cuda") == {"threads": 2, "device": "cuda"}


def test_a_row_keyed_before_the_device_is_its_cells_until_migrated():
    after_36 = {**BASE, "threads": 2}  # keyed with its threads, not yet its device
    row = _row(after_36, threads=2, device="cuda:1", cpu_kernels="avx2")
    assert row["key"] in row_keys(row)[1:] and row_key_problem(row) is None
    moved = migrated_row(row)
    assert moved["key"] == digest({**after_36, "device": "cuda"}) == row_keys(moved)[0]
    assert (moved["device"], moved["device_used"]) == ("cuda", "cuda:1")
    assert migrated_row(moved) is None  # migrated once


def test_a_cpu_row_keeps_its_key_and_one_from_before_issue_36_gets_its_threads():
    cpu = _row(BASE, device="cpu", threads=1, cpu_kernels="avx2")
    assert migrated_row(cpu) is None and row_key_problem(cpu) is None
    old = _row(BASE, device="cpu", threads=2)  # keyed before threads entered identities
    assert migrated_row(old)["key"] == digest({**BASE, "threads": 2,
                                               "cpu_kernels": "not recorded"})


def test_a_row_keyed_by_no_identity_of_its_own_is_refused_and_nothing_moves(tmp_path):
    forged = {**_row(BASE, device="cuda"), "key": digest({**BASE, "seed": 9})}
    with pytest.raises(ValueError, match="is not keyed by its identity"):
        migrated_row(forged)
    assert row_key_problem(forged) is not None


def test_the_migration_script_moves_rows_through_the_package(tmp_path):
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "pin_identities", Path(__file__).parents[3] / "benchmarks" / "pin_identities.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    store = ResultStore(tmp_path)
    store.put(_row(BASE, device="cuda", threads=1, cpu_kernels="avx2"))
    store.put(_row({**BASE, "seed": 1}, seed=1, device="cpu", threads=1, cpu_kernels="avx2"))
    assert script.rekey(tmp_path) == (1, 1)
    keys = {r["key"]: r["device"] for r in ResultStore(tmp_path).stored_rows()}
    assert keys == {digest({**BASE, "device": "cuda"}): "cuda",
                    digest({**BASE, "seed": 1}): "cpu"}
