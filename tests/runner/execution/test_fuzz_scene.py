"""Fuzzing scene files: mutated TOML and JSON scenes through loading and planning.

A valid scene (a tiny saved dataset with a layout, two encoders, a classifier) is written
as TOML or JSON, then mutated as a hostile user would: a field's value swapped for one of
another type or an extreme one, a field dropped, given twice (also as its alias), an
unknown field added, or the file's text cut or spliced. Loading it and planning it (every
check a run makes before any work; nothing is trained) may only raise tactbench's own
error type, must stay within a memory cap, and must change nothing already saved (the
scene file, the dataset folder, the working folder).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactbench.errors import TactbenchError

#: Fields of the base scene; values are filled in per test (paths).
BASE = {
    "encoders": ["raw", "frame-diff"],
    "classifiers": ["logreg:max_iter=5"],
    "L": [2, "3-4"],
    "seeds": [0, 1],
    "split": "paper",
    "test_per_class": 1,
    "profile": "quick",
    "pixel_mm": 10.0,
    "imaging": "linear",
    "precision": "float32",
    "device": "cpu",
    "threads": 1,
    "executor": "local",
    "workers": 1,
    "rerun": False,
    "save_models": False,
}
FIELDS = [*BASE, "dataset", "out", "scheduler"]
ALIASES = {"encoders": "encoder", "classifiers": "classifier", "L": "lengths",
           "seeds": "seed"}

EXTREME_INTS = [0, -1, 1, 2, 7, 1000, 10**6, 2**31, 2**63 - 1, -2**63, 2**63, 10**30]
EXTREME_FLOATS = [0.0, -0.0, 1.5, -1.0, 1e-320, 1e-6, 1e-3, 1e308, math.inf, -math.inf,
                  math.nan]
SPECS = ["raw", "frame-diff", "farneback:winsize=9,winsize=11", "raw:winsize=3",
         "logreg:max_iter=-1", "logreg:max_iter=1e999", "logreg:max_iter=nan",
         "small-cnn-lstm:batch_size=0", "small-cnn-lstm:input_size=100000000",
         "small-cnn-lstm:batch_size=100000000", "taxel-lstm", "raw:", ":x=1", "logreg:a",
         "no-such-encoder", "farneback:levels=1000000"]
TEXTS = ["", " ", "\x00", "1-3000000", "5-2", "-3", "paper", "users", "cuda", "cuda:-1",
         "auto", "gpu", "uint8", "int4", "gaussian", "nearest", "dask", "tcp://x:1", "ü" * 50,
         "a" * 5000]


SCALARS = st.one_of(
    st.sampled_from(EXTREME_INTS), st.integers(), st.sampled_from(EXTREME_FLOATS),
    st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
    st.sampled_from(TEXTS + SPECS), st.text(max_size=30))
#: A value of any type a TOML or JSON file can hold, some extreme, some nested.
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=3)),
    max_leaves=8)
#: Paths for ``dataset`` and ``out``, placeholders :func:`fill_paths` fills in.
PATH_TOKENS = ["@dataset", "@file", "@file/out", "@foreign", "@out", "@work", "@manifest",
               "", "\x00", "out\x00x", "no-such", "a" * 5000, "synthetic-forearm:users=0"]


def _toml_key(key: str) -> str:
    return json.dumps(key)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # TOML basic strings take JSON's escapes
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}"
                               for k, v in value.items()) + "}"
    raise TypeError(type(value))


def to_text(pairs: list[tuple[str, object]], fmt: str) -> str:
    """Key-value pairs (a key may repeat) as a TOML or JSON document."""
    pairs = [(k, v) for k, v in pairs if v is not None]  # (neither format needs None)
    if fmt == "json":
        return "{" + ", ".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in pairs) + "}"
    return "".join(f"{_toml_key(k)} = {_toml_value(v)}\n" for k, v in pairs)


@st.composite
def mutated_scenes(draw):
    """``(format, text)`` of a mutated scene file (paths as ``@`` placeholders)."""
    fmt = draw(st.sampled_from(["toml", "json"]))
    pairs = [("dataset", "@dataset"), *BASE.items(), ("out", "@out")]
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["swap", "swap", "swap", "drop", "twice", "alias",
                                   "unknown", "spec"]))
        if not pairs:
            break
        i = draw(st.integers(0, len(pairs) - 1))
        key, value = pairs[i]
        if op == "swap":
            if key in ("dataset", "out"):  # only hostile values that touch nothing outside
                new = draw(st.one_of(st.sampled_from(PATH_TOKENS), st.integers(),
                                     st.lists(st.sampled_from(PATH_TOKENS))))
            else:
                new = draw(VALUES)
            pairs[i] = (key, new)
        elif op == "drop" and key != "dataset":  # (the default dataset is a big simulation)
            pairs.pop(i)
        elif op == "twice":
            pairs.append((key, draw(VALUES)))
        elif op == "alias" and key in ALIASES:
            pairs.append((ALIASES[key], value))
        elif op == "unknown":
            pairs.append((draw(st.sampled_from(["colour", "seedz", "Encoders", "", "L "])),
                          draw(VALUES)))
        elif op == "spec":  # component specs with hostile options, in place
            name = draw(st.sampled_from(["encoders", "classifiers"]))
            specs = draw(st.lists(st.sampled_from(SPECS), min_size=1, max_size=3))
            pairs = [(k, specs if k == name else v) for k, v in pairs]
    text = to_text(pairs, fmt)
    cut = draw(st.one_of(st.none(), st.integers(0, max(0, len(text) - 1))))
    if cut is not None:  # the file's text itself damaged: cut, or a fragment spliced in
        text = text[:cut] + draw(st.sampled_from(["", "[", "{", "\"", "=", "\x00", "\n[x]\n",
                                                  "]]]", "\\u0000"])) + text[cut + 1:]
    return fmt, text


def fill_paths(text: str, paths: dict[str, str], fmt: str) -> str:
    """Put the test's real paths in place of the ``@`` placeholders (longest first)."""
    for token in sorted(paths, key=len, reverse=True):
        path = json.dumps(paths[token])[1:-1]  # escaped as inside a string of either format
        text = text.replace(token, path)
    return text


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    """A saved dataset on a 4 × 4 taxel grid: 3 classes × 4 samples of 4–6 frames."""
    from tactbench.data.dataset import Dataset
    from tactbench.data.layout import TaxelLayout
    from tactbench.data.recording import Recording, Sample

    yy, xx = np.mgrid[0:4, 0:4]
    layout = TaxelLayout(ids=np.arange(16), positions=np.column_stack(
        [xx.ravel(), yy.ravel()]).astype(float) * 7.5, name="grid")
    rng = np.random.default_rng(0)
    samples = []
    for i in range(12):
        n = 4 + i % 3
        rec = Recording(rng.uniform(0, 1, (n, 16)).astype(np.float32), np.arange(n) * 0.1,
                        np.arange(16))
        samples.append(Sample(rec, label=i % 3, user=f"u{i % 2}", position="front",
                              repetition=i // 3, source="fuzz"))
    path = tmp_path_factory.mktemp("fuzz") / "tiny"
    Dataset(name="tiny", samples=samples, classes=("a", "b", "c"), layout=layout).save(path)
    return path


@pytest.fixture(scope="module")
def registry():
    from tactbench.plugins import load_registry

    return load_registry()


def _snapshot(folder) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


@settings(max_examples=150, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                 HealthCheck.too_slow])
@given(scene=mutated_scenes())
def test_mutated_scene_files_raise_only_tactbench_errors_before_any_work(
        scene, tiny_dataset, registry, tmp_path, monkeypatch, memory_cap):
    from tactbench.runner import Scene, load_scene_file, plan

    work = tmp_path / "work"
    work.mkdir(exist_ok=True)
    monkeypatch.chdir(work)  # relative paths of mutated fields land here
    (work / "a-file").write_text("not a folder")
    (work / "foreign").mkdir(exist_ok=True)
    (work / "foreign" / "notes.txt").write_text("mine")
    paths = {"@dataset": str(tiny_dataset), "@file": str(work / "a-file"),
             "@foreign": str(work / "foreign"), "@out": str(work / "out"), "@work": str(work),
             "@manifest": str(tiny_dataset / "manifest.json")}
    fmt, text = scene
    scene_file = tmp_path / f"scene.{fmt}"
    scene_file.write_text(fill_paths(text, paths, fmt), encoding="utf-8")
    saved = scene_file.read_bytes()
    before = (_snapshot(tiny_dataset), _snapshot(work))
    try:
        with memory_cap(64):  # (the largest seen: 30 MiB, loading the dataset)
            plan(Scene(**load_scene_file(scene_file)), registry)
    except TactbenchError as exc:  # anything else fails the test, with its traceback
        assert str(exc).strip() and "\n" not in str(exc).strip(), str(exc)
    assert scene_file.read_bytes() == saved
    assert (_snapshot(tiny_dataset), _snapshot(work)) == before


def test_the_base_scene_is_valid_and_plans(tiny_dataset, registry, tmp_path):
    """The fuzz starts from a scene that plans: mutations, not the base, are refused."""
    from tactbench.runner import Scene, load_scene_file, plan

    for fmt in ("toml", "json"):
        path = tmp_path / f"scene.{fmt}"
        path.write_text(to_text([("dataset", str(tiny_dataset)), *BASE.items(),
                                 ("out", str(tmp_path / "out"))], fmt))
        p = plan(Scene(**load_scene_file(path)), registry)
        assert len(p.cells) == 2 * 1 * 3 * 2
