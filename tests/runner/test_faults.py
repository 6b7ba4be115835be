"""Fault injection: every artefact a run stores, damaged in every way, is detected (one
warning line naming it and the problem), rebuilt, and the run's results equal a clean
run's.

One clean run (2 encoders × 1 seed, logreg, models saved) is made per module; each case
copies its output folder and cache, damages one artefact, and runs again.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tactbench.runner import EncodingCache, Scene, run

pytestmark = pytest.mark.usefixtures("one_torch_thread")

# the tiny grid of tests/runner/conftest.py, with a fast classifier
SCENE = dict(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw", "frame-diff"],
             classifiers=["logreg:max_iter=20"], L=[3], seeds=[0], test_per_class=1,
             pixel_mm=10.0, threads=1, workers=1, save_models=True)


def _results(rows):
    return sorted((r["key"], r["status"], r["accuracy"], r["confusion"]) for r in rows)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """The clean run: its folder, cache, rows, and the keys of its entries and cells."""
    root = tmp_path_factory.mktemp("clean")
    scene = Scene(**SCENE, out=str(root / "out"))
    cache = EncodingCache(root / "cache")
    result = run(scene, progress=False, cache=cache)
    assert len(result.ok) == 2
    entries = {e["encoder"]: e["key"] for e in cache.entries()}
    cells = {r["encoder"]: r["key"] for r in result.rows}
    return root, result.rows, entries, cells


@pytest.fixture
def copy(clean, tmp_path):
    """A copy of the clean run: ``(scene, cache, entries, cells)`` in ``tmp_path``."""
    root, _, entries, cells = clean
    shutil.copytree(root / "out", tmp_path / "out")
    shutil.copytree(root / "cache", tmp_path / "cache")
    return (Scene(**SCENE, out=str(tmp_path / "out")), EncodingCache(tmp_path / "cache"),
            entries, cells)


def _rerun(scene, cache, caplog, **over):
    caplog.clear()
    with caplog.at_level("WARNING"):
        result = run(replace(scene, **over), progress=False, cache=cache)
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    return result, warnings


# ------------------------------------------------------------------- cache entries


def _zero_frames(folder: Path, other: Path) -> None:
    path = folder / "frames.npy"
    data = bytearray(path.read_bytes())
    data[128:] = bytes(len(data) - 128)  # the header is 128 bytes; every value 0
    path.write_bytes(bytes(data))


def _nan_frame(folder: Path, other: Path) -> None:
    path = folder / "frames.npy"
    data = bytearray(path.read_bytes())
    data[-4:] = np.float32("nan").tobytes()
    path.write_bytes(bytes(data))


def _truncate_frames(folder: Path, other: Path) -> None:
    path = folder / "frames.npy"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _swap_entry(folder: Path, other: Path) -> None:
    shutil.rmtree(folder)
    shutil.copytree(other, folder)  # another encoder's entry under this key


def _swap_frames(folder: Path, other: Path) -> None:
    shutil.copyfile(other / "frames.npy", folder / "frames.npy")


def _shift_offsets(folder: Path, other: Path) -> None:
    offsets = np.load(folder / "offsets.npy")
    offsets[1:-1] += 1
    np.save(folder / "offsets.npy", offsets)


def _missing_meta(folder: Path, other: Path) -> None:
    (folder / "meta.json").unlink()


def _missing_offsets(folder: Path, other: Path) -> None:
    (folder / "offsets.npy").unlink()


def _edit_meta(folder: Path, other: Path) -> None:
    meta = json.loads((folder / "meta.json").read_text())
    meta["scale"] = [2.0 * s for s in meta["scale"]]  # a flipped number
    (folder / "meta.json").write_text(json.dumps(meta))


def _garbage_meta(folder: Path, other: Path) -> None:
    (folder / "meta.json").write_text("[1]")


@pytest.mark.parametrize("damage, problem", [
    (_zero_frames, "frames.npy does not match its checksum"),
    (_nan_frame, "frames.npy does not match its checksum"),
    (_truncate_frames, "frames.npy is .* bytes, meta.json records .* \\(truncated\\)"),
    (_swap_entry, "meta.json belongs to entry"),
    (_swap_frames, "frames.npy is .* bytes"),
    (_shift_offsets, "offsets.npy does not match its checksum"),
    (_missing_meta, "meta.json is missing"),
    (_missing_offsets, "offsets.npy is missing"),
    (_edit_meta, "meta.json does not match its checksum"),
    (_garbage_meta, "meta.json is not a JSON object"),
], ids=lambda x: getattr(x, "__name__", "")[1:])
def test_a_damaged_cache_entry_is_detected_and_rebuilt(copy, clean, caplog, damage,
                                                       problem):
    scene, cache, entries, _ = copy
    key = entries["raw"]
    damage(cache.path(key), cache.path(entries["frame-diff"]))
    result, warnings = _rerun(scene, cache, caplog, rerun=True)
    (line,) = warnings
    assert key in line and "encoding it again" in line and "\n" not in line
    import re

    assert re.search(problem, line), line
    assert _results(result.rows) == _results(clean[1])
    meta = cache.verify(key)  # rebuilt, whole, and its checksums verified
    assert meta["encoder"] == "raw" and meta["key"] == key
    assert [e["state"] for e in cache.entries()] == ["ok", "ok"]


def test_an_intact_cache_is_used_without_a_warning(copy, clean, caplog):
    scene, cache, entries, _ = copy
    created = {e["key"]: e["created"] for e in cache.entries()}
    result, warnings = _rerun(scene, cache, caplog, rerun=True)
    assert warnings == [] and _results(result.rows) == _results(clean[1])
    assert {e["key"]: e["created"] for e in cache.entries()} == created  # not re-encoded


# ---------------------------------------------------------------------- cell rows


def _other_row(path: Path, other: Path) -> None:
    shutil.copyfile(other, path)


def _flip_number(path: Path, other: Path) -> None:
    row = json.loads(path.read_text())
    row["confusion"][0][0] += 1
    path.write_text(json.dumps(row, indent=2))


def _nan_accuracy(path: Path, other: Path) -> None:
    row = json.loads(path.read_text())
    row["accuracy"] = float("nan")
    del row["checksum"]  # as a row written before checksums would be
    path.write_text(json.dumps(row))


@pytest.mark.parametrize("damage, problem", [
    (_other_row, "is the row of cell"),
    (lambda p, o: p.write_text("{}"), "is the row of cell 'None'"),
    (lambda p, o: p.write_text("[1]"), "holds a JSON list, not a row"),
    (lambda p, o: p.write_bytes(p.read_bytes()[:100]), "is not valid JSON"),
    (lambda p, o: p.write_bytes(b"\xff\xfe" * 10), "is not valid JSON"),
    (_flip_number, "does not match its checksum"),
    (_nan_accuracy, "has no accuracy in \\[0, 1\\]"),
], ids=["other-cells", "empty-object", "list", "truncated", "binary", "flipped-number",
        "nan-accuracy"])
def test_a_damaged_cell_row_is_detected_and_the_cell_recomputed(copy, clean, caplog, damage,
                                                                problem):
    import re

    scene, cache, _, cells = copy
    store = Path(scene.out) / "cells"
    path, other = store / f"{cells['raw']}.json", store / f"{cells['frame-diff']}.json"
    damage(path, other)
    result, warnings = _rerun(scene, cache, caplog)
    (line,) = warnings
    assert str(path) in line and "computed again" in line and re.search(problem, line), line
    assert (result.computed, result.skipped) == (1, 1)
    assert _results(result.rows) == _results(clean[1])
    assert json.loads(path.read_text())["key"] == cells["raw"]


# -------------------------------------------------------------------------- models


def _model_nan(path: Path, other: Path) -> None:
    data = bytearray(path.read_bytes())
    data[-4:] = np.float32("nan").tobytes()  # the last value of the last tensor
    path.write_bytes(bytes(data))


def _model_zeroed(path: Path, other: Path) -> None:
    data = bytearray(path.read_bytes())
    header = 8 + int.from_bytes(data[:8], "little")
    data[header:] = bytes(len(data) - header)
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("damage", [
    lambda p, o: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),
    _model_zeroed,
    _model_nan,
    lambda p, o: shutil.copyfile(o, p),  # another cell's model
    lambda p, o: p.write_bytes(b""),
], ids=["truncated", "zeroed", "nan", "other-cells", "empty"])
def test_a_damaged_model_is_not_kept_and_its_cell_is_recomputed(copy, clean, caplog, damage):
    from tactbench.classifiers.io import load_model

    scene, cache, _, cells = copy
    models = Path(scene.out) / "models"
    path = models / f"{cells['raw']}.safetensors"
    damage(path, models / f"{cells['frame-diff']}.safetensors")
    result, warnings = _rerun(scene, cache, caplog)
    (line,) = warnings
    assert str(path) in line and "computed again" in line and "\n" not in line
    assert (result.computed, result.skipped) == (1, 1)
    assert _results(result.rows) == _results(clean[1])
    _, meta = load_model(path)  # rebuilt and sound
    assert meta["cell"] == cells["raw"]


def test_sound_models_are_kept(copy, clean, caplog):
    scene, cache, _, cells = copy
    path = Path(scene.out) / "models" / f"{cells['raw']}.safetensors"
    before = path.stat().st_mtime_ns
    result, warnings = _rerun(scene, cache, caplog)
    assert warnings == [] and (result.computed, result.skipped) == (0, 2)
    assert path.stat().st_mtime_ns == before
