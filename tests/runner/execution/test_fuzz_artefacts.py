"""Fuzzing the readers of what a run stores: cache entries (``meta.json``, ``offsets.npy``,
the header and values of ``frames.npy``) and cell rows, mutated the ways damage and
careless edits do (bytes flipped, cut short, appended; JSON values replaced, with and
without a recomputed checksum).

Whatever the mutation: the reader raises :class:`CorruptArtefactError` (tactbench's own
error, one line) or returns exactly what was stored, a run rebuilds the entry, nothing
large is allocated (``memory_cap``), and no file on disk is changed by a failed read.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.errors import CorruptArtefactError
from tactbench.integrity import hash_file
from tactbench.runner import EncodingCache, ResultStore, ensure_encodings, load_encoding, plan
from tactbench.runner.execution import entries as entries_module
from tactbench.runner.execution.entries import seal
from tactbench.runner.execution.results import check_row, row_checksum

FUZZ = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

#: JSON values, hostile ones included (huge counts, negative sizes, wrong types, nesting).
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True)
    | st.text(max_size=8) | st.sampled_from([2 ** 63, 10 ** 30, -1, 0, 1e308, "float64"]),
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12)

MUTATIONS = ("flip", "truncate", "append", "replace", "replace+reseal")


def _paths(doc, prefix=()):
    """Every place in a JSON document: key/index paths to each value."""
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))


def _replace(doc, path, value):
    if not path:
        return value
    parent = doc
    for step in path[:-1]:
        parent = parent[step]
    parent[path[-1]] = value
    return doc


def mutate(data: bytes, draw, kind: str, reseal=None) -> bytes:
    """``data`` damaged the ``kind`` way (``reseal(doc)``: recompute a JSON checksum)."""
    if kind == "flip":
        i = draw(st.integers(0, len(data) - 1))
        out = bytearray(data)
        out[i] ^= draw(st.integers(1, 255))
        return bytes(out)
    if kind == "truncate":
        return data[: draw(st.integers(0, len(data) - 1))]
    if kind == "append":
        return data + draw(st.binary(min_size=1, max_size=64))
    doc = json.loads(data)
    paths = list(_paths(doc))
    path = draw(st.sampled_from(paths))
    doc = _replace(doc, path, draw(JSON_VALUES))
    if kind == "replace+reseal" and reseal is not None and isinstance(doc, dict):
        doc = reseal(doc)
    return json.dumps(doc).encode()


def _snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


def _restore(root: Path, files: dict[str, bytes]) -> None:
    for name, data in files.items():
        (root / name).write_bytes(data)


def _forget_verified() -> None:
    # each example is a new version of the entry; the per-process memo keys on the files'
    # inode, size and times, which two versions written within one clock tick can share
    entries_module._VERIFIED.clear()
    entries_module._LOADED.clear()


# ------------------------------------------------------------------- cache entries


@pytest.fixture
def stored(tmp_path):
    """A uint8 entry ``k`` (mutated) and a float32 entry ``other`` (a bystander)."""
    cache = EncodingCache(tmp_path / "cache")
    rng = np.random.default_rng(0)
    seqs = [rng.random((t, 2, 3, 4), dtype=np.float32) for t in (3, 1, 4)]
    cache.write("k", seqs, {"encoder": "raw"}, precision="uint8")
    cache.write("other", seqs[:2], {"encoder": "frame-diff"})
    loaded, _ = load_encoding(cache.path("k"))
    return cache, [np.asarray(s) for s in loaded], _snapshot(cache.root)


@FUZZ
@given(data=st.data(), name=st.sampled_from(["meta.json", "offsets.npy", "frames.npy"]),
       kind=st.sampled_from(MUTATIONS))
def test_a_mutated_cache_entry_is_refused_or_read_unchanged(stored, memory_cap, data, name,
                                                            kind):
    cache, want, files = stored
    _restore(cache.root, files)
    _forget_verified()
    path = cache.path("k") / name
    if name != "meta.json" and kind.startswith("replace"):
        # the file damaged, and meta.json made to agree with it (sizes and checksums):
        # not detectable as damage, but still never more than tactbench's error
        kind = "forged"
        path.write_bytes(mutate(path.read_bytes(), data.draw,
                                data.draw(st.sampled_from(["flip", "truncate", "append"]))))
        meta = json.loads((cache.path("k") / "meta.json").read_text())
        meta["files"][name] = {"bytes": path.stat().st_size,
                               "checksum": hash_file(path)}
        (cache.path("k") / "meta.json").write_text(json.dumps(seal(meta)))
    else:
        path.write_bytes(mutate(path.read_bytes(), data.draw, kind, reseal=seal))
    before = _snapshot(cache.root)
    with memory_cap(16):
        try:
            loaded, meta = load_encoding(cache.path("k"))
            got = [np.asarray(s) for s in loaded]
        except CorruptArtefactError as exc:
            assert "\n" not in str(exc) and str(cache.path("k")) in str(exc)
            got = None
    if got is not None and kind not in ("forged", "replace+reseal"):
        # only a mutation that changed nothing the entry is made of passes its checks
        assert len(got) == len(want) and all(np.array_equal(a, b) for a, b in zip(got, want))
    assert _snapshot(cache.root) == before  # a read changes no file


@pytest.fixture
def tiny_plan(tiny_scene, cache):
    p = plan(tiny_scene(encoders=["raw"], classifiers=["logreg"], seeds=[0],
                        precision="uint8"))
    (folder,) = ensure_encodings(p, cache, p.cells).values()
    loaded, _ = load_encoding(folder)
    return p, cache, Path(folder), [np.asarray(s) for s in loaded], _snapshot(Path(folder))


@settings(FUZZ, max_examples=15)
@given(data=st.data(), name=st.sampled_from(["meta.json", "offsets.npy", "frames.npy"]),
       kind=st.sampled_from(MUTATIONS))
def test_a_run_rebuilds_a_mutated_entry_to_the_same_encoding(tiny_plan, data, name, kind):
    p, cache, folder, want, files = tiny_plan
    if not folder.is_dir():
        folder.mkdir()
    _restore(folder, files)
    _forget_verified()
    if name != "meta.json" and kind.startswith("replace"):
        kind = "truncate"
    path = folder / name
    path.write_bytes(mutate(path.read_bytes(), data.draw, kind, reseal=seal))
    ensure_encodings(p, cache, p.cells)
    got = [np.asarray(s) for s in load_encoding(folder)[0]]
    assert len(got) == len(want) and all(np.array_equal(a, b) for a, b in zip(got, want))
    assert cache.temporaries() == []


# ----------------------------------------------------------------------- cell rows


@pytest.fixture
def rows(tmp_path):
    """Rows ``a`` (mutated) and ``b`` (a bystander), as a run writes them."""
    store = ResultStore(tmp_path / "out")
    cell = {"dataset": "d", "split": "paper", "encoder": "raw", "classifier": "logreg",
            "L": 3, "seed": 0, "classes": ["x", "y"], "peak_step": "fit",
            "confusion": [[2, 0], [1, 1]], "per_class_accuracy": {"x": 1.0, "y": 0.5},
            "train_s": 0.25, "fit": {"epochs": [0.5, 0.25]}, "error": None}
    store.put({**cell, "key": "a", "status": "ok", "accuracy": 0.75})
    store.put({**cell, "key": "b", "status": "ok", "accuracy": 0.75, "seed": 1})
    return store, store.read("a"), _snapshot(store.out)


def _reseal_row(doc):
    return {**doc, "checksum": row_checksum(doc)}


@FUZZ
@given(data=st.data(), kind=st.sampled_from(MUTATIONS))
def test_a_mutated_cell_row_is_refused_or_read_unchanged(rows, memory_cap, data, kind):
    from tactbench.runner.analysis.summaries import summarise

    store, want, files = rows
    _restore(store.out, files)
    path = store.path("a")
    path.write_bytes(mutate(path.read_bytes(), data.draw, kind, reseal=_reseal_row))
    before = _snapshot(store.out)
    with memory_cap(16):
        try:
            got = store.read("a")
        except CorruptArtefactError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc)
            got = None
    assert _snapshot(store.out) == before
    if got is None:
        assert store.get("a") is None and not store.finished("a")
        return
    if kind != "replace+reseal":
        assert got == want  # nothing but a consistent rewrite passes the checksum
    assert check_row(got, "a") is None
    summarise([got, store.read("b")])  # whatever is accepted, the reports can use
