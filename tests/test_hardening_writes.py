"""Nothing a user made is lost: every command that writes refuses to replace what it did
not write and never replaces its own input (tactbench.paths.check_output_file /
check_output_folder, `run --out` included), runs sharing an out folder keep one grid
(ResultStore.claim), a row too large to read back is a failed cell, not a silent gap."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.errors import InputError
from tactbench.paths import check_output_file, check_output_folder, temp_name
from tactbench.runner.execution.results import ROW_MAX_BYTES, ResultStore


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def hashes(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def dataset(tmp_path):
    """A tiny folder of recordings (2 classes × 2 recordings of 5×4×4 frames)."""
    root = tmp_path / "rec"
    rng = np.random.default_rng(0)
    for cls in ("a", "b"):
        (root / cls).mkdir(parents=True)
        for i in range(2):
            np.save(root / cls / f"r{i}.npy", rng.random((5, 4, 4)).astype(np.float32))
    return root


def test_data_synth_refuses_a_folder_holding_anything(tmp_path):
    for held in ("notes.txt", "manifest.json"):
        out = tmp_path / held.split(".")[0]
        out.mkdir()
        (out / held).write_text("mine")
        before = hashes(out)
        result = run("data", "synth", "--out", out, "--users", 1, "--repetitions", 1)
        assert result.exit_code == 2, result.output
        assert "already holds" in result.output and "nothing was written" in result.output
        assert hashes(out) == before


def test_encode_never_replaces_its_input_or_a_file_it_did_not_write(tmp_path):
    src = tmp_path / "seq.npy"
    np.save(src, np.random.default_rng(1).random((4, 6, 6)))
    src_hash = hashlib.sha256(src.read_bytes()).hexdigest()
    for out in (src, tmp_path / "seq", tmp_path / "." / "seq.npy"):
        result = run("encode", "-e", "raw", "-i", src, "-o", out)
        assert result.exit_code == 2 and "is the input" in result.output, result.output
    assert hashlib.sha256(src.read_bytes()).hexdigest() == src_hash

    # -o X writes X.npy, and records and prints the file it wrote
    result = run("encode", "-e", "raw", "-i", src, "-o", tmp_path / "enc", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert doc["output"] == str(tmp_path / "enc.npy") and Path(doc["output"]).is_file()
    assert np.load(tmp_path / "enc.npy").shape == (4, 1, 6, 6)
    # its own earlier output is replaced; a user's file of that name is not
    assert run("encode", "-e", "frame-diff", "-i", src, "-o", tmp_path / "enc").exit_code == 0
    for name in ("user.npy", "user.json"):
        (tmp_path / name).write_text("a user's file")
        result = run("encode", "-e", "raw", "-i", src, "-o", tmp_path / "user.npy")
        assert result.exit_code == 2 and "tactbench did not write it" in result.output
        assert (tmp_path / name).read_text() == "a user's file"
        (tmp_path / name).unlink()


def test_preview_replaces_only_its_own_pictures(dataset, tmp_path):
    out = tmp_path / "p.png"
    assert run("data", "preview", dataset, "--out", out).exit_code == 0
    assert run("data", "preview", dataset, "--out", out, "--sample", 1).exit_code == 0
    users = tmp_path / "photo.png"
    users.write_bytes(b"\x89PNG\r\n\x1a\n a user's picture")
    result = run("data", "preview", dataset, "--out", users)
    assert result.exit_code == 2 and "tactbench did not write it" in result.output
    assert users.read_bytes().endswith(b"a user's picture")
    result = run("data", "preview", dataset, "--out", users / "x.png")  # under a file
    assert result.exit_code == 2 and "is a file, not a folder" in result.output
    result = run("data", "preview", dataset / "a" / "r0.npy", "--out", dataset / "a" / "r0.npy")
    assert result.exit_code == 2


def test_no_output_inside_the_cache_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    for check in (check_output_file, check_output_folder):
        with pytest.raises(InputError, match="inside the cache folder"):
            check(tmp_path / "cache" / "results")
    check_output_folder(tmp_path / "elsewhere")  # beside it is fine


def test_import_refuses_an_out_folder_inside_its_source(dataset):
    result = run("data", "import", dataset, "--out", dataset / "a" / "copy")
    assert result.exit_code == 2 and "overlaps the input" in result.output


def _row(key: str, classes: int) -> dict:
    return {"key": key, "encoder": "raw", "classifier": "logreg", "L": 3, "seed": 0,
            "status": "ok", "accuracy": 0.5, "classes": [f"c{i}" for i in range(classes)],
            "confusion": [[1] * classes for _ in range(classes)],
            "per_class_accuracy": {f"c{i}": 0.5 for i in range(classes)},
            "test_predictions": {"indices": [], "labels": [], "predictions": []}}


@pytest.mark.parametrize("limit", [
    pytest.param(None, id="the-real-limit", marks=pytest.mark.slow(
        "builds and serialises a confusion matrix over the real 16 MiB row limit")),
    pytest.param(1 << 16, id="a-64-KiB-limit"),  # the same path at a size that is fast
])
def test_a_row_too_large_to_read_back_is_a_failed_cell_not_a_gap(tmp_path, monkeypatch, limit):
    from tactbench.runner.execution import results

    if limit is not None:
        monkeypatch.setattr(results, "ROW_MAX_BYTES", limit)
    store = ResultStore(tmp_path)
    small = store.put(_row("k1", 3))
    assert small["status"] == "ok" and store.read("k1")["accuracy"] == 0.5
    classes = int((results.ROW_MAX_BYTES / 2) ** 0.5) + 50  # a confusion beyond the limit
    stored = store.put(_row("k2", classes))
    assert stored["status"] == "failed" and "limit" in stored["error"]["message"]
    back = store.read("k2")  # read back sound: reported as a failed cell, retried next
    assert back["status"] == "failed" and back["encoder"] == "raw"
    assert store.path("k2").stat().st_size < 10_000


def test_a_second_grid_into_the_same_out_is_refused_naming_the_first(tmp_path):
    store = ResultStore(tmp_path)
    row = _row("old", 2)
    row["run"] = {"command": "tactbench run --seed 0-2"}
    store.put(row)
    claim = store.claim(["old", "new"])  # a larger grid that keeps every cell: fine
    claim.unlink()
    with pytest.raises(InputError, match=r"1 cell\(s\) of another grid \(raw × logreg L=3 "
                                         r"seed=0, from `tactbench run --seed 0-2`\)"):
        store.claim(["new"])


def test_two_runs_at_once_must_plan_the_same_grid(tmp_path):
    store = ResultStore(tmp_path)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        store.cells.mkdir(parents=True)
        name = temp_name("run").replace(f"-{os.getpid()}-", f"-{other.pid}-")
        (store.cells / name).write_text(json.dumps({"keys": ["a"],
                                                    "command": "tactbench run -L 5"}))
        os.utime(store.cells / name, ns=(1, 1))  # it started first
        same = store.claim(["a"])  # the same grid: both go on, and share their cells
        same.unlink()
        with pytest.raises(InputError, match=f"in use by another run .*process {other.pid}"
                                             f": tactbench run -L 5"):
            store.claim(["a", "b"])
        assert [p.name for p in store.cells.iterdir()] == [name]  # its claim withdrawn
    finally:
        other.kill()
        other.wait()
    assert store.claim(["b"]).exists()  # its process gone: the claim no longer counts


def test_a_class_folder_named_in_bytes_that_are_not_utf8_is_one_line(dataset):
    bad = os.fsencode(dataset) + b"/caf\xe9"
    os.rename(os.fsencode(dataset / "b"), bad)
    from tactbench.datasets.folder import read_folder

    with pytest.raises(InputError, match=r"caf\\xe9: the name is not valid UTF-8"):
        read_folder(dataset)
