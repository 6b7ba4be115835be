"""Contracts: written once, checked when a component is built, optional members keep their
documented defaults, and every built-in component satisfies its kind's contract."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from tactbench import contracts, hookimpl
from tactbench.contracts import CLASSIFIER, CONTRACTS, ENCODER, SENSOR
from tactbench.errors import ContractError, InputError, PluginError
from tactbench.plugins import collect_registry, make_plugin_manager
from tactbench.registry import KINDS

MODULE = "tb_contract_plugins"  # where the tiny plugin classes below are importable from
TINY_SYNTHETIC = "synthetic-forearm:users=1,repetitions=1,positions=1"


# ----------------------------------------------------------------------------- tiny plugins
# Written against the documented protocol only: no tactbench base class.


class MinimalEncoder:
    """An encoder with only ``channels`` and ``encode``."""

    channels = ("pressure",)

    def encode(self, seq):
        return np.asarray(seq, dtype=np.float32)[:, None]


class MinimalClassifier:
    """A classifier with only ``fit``, ``predict``, ``predict_proba`` and ``save``:
    it predicts the most frequent training label."""

    def fit(self, train, val, *, seed, device, progress, n_classes=None):
        counts = np.bincount(np.asarray(train.labels), minlength=n_classes or 0)
        self.proba = (counts / counts.sum()).astype(np.float32)
        return {"epochs": 1}

    def predict_proba(self, batch):
        return np.tile(self.proba, (len(batch), 1))

    def predict(self, batch):
        return self.predict_proba(batch).argmax(1).astype(np.int64)

    def save(self, path, metadata=None):
        return path


class NoEncode:
    channels = ("pressure",)


class NoProba(MinimalClassifier):
    predict_proba = None  # declared but not callable: as bad as missing


class NamelessChannels(MinimalEncoder):
    channels = "pressure"  # a string, not a sequence of names


class BadRank(MinimalClassifier):
    frame_rank = 2


class NoBatch(MinimalClassifier):
    batch_size = 0


class NoSplitMethod:
    spec = "no-split"


class NumberSpec:
    spec = 3

    def split(self, data, *, seed):
        return []


class NoCombine:
    def training(self, sequences, labels, L, *, prepared=None):
        return None

    def test(self, sequences, labels, L, *, prepared=None):
        return None


@pytest.fixture
def registry(monkeypatch):
    """Built-ins plus a plugin ``tiny`` registering the classes above by target."""
    module = types.ModuleType(MODULE)
    for cls in (MinimalEncoder, MinimalClassifier, NoEncode, NoProba, NamelessChannels,
                BadRank, NoBatch, NoSplitMethod, NumberSpec, NoCombine):
        setattr(module, cls.__name__, cls)
    monkeypatch.setitem(sys.modules, MODULE, module)

    @hookimpl
    def register_encoders(register):
        for name, cls in (("minimal", "MinimalEncoder"), ("no-encode", "NoEncode"),
                          ("string-channels", "NamelessChannels")):
            register(name, f"{MODULE}:{cls}", summary=name)

    @hookimpl
    def register_classifiers(register):
        for name, cls in (("minimal", "MinimalClassifier"), ("no-proba", "NoProba"),
                          ("rank-2", "BadRank"), ("no-batch", "NoBatch")):
            register(name, f"{MODULE}:{cls}", summary=name)

    @hookimpl
    def register_splits(register):
        for name, cls in (("no-split", "NoSplitMethod"), ("number-spec", "NumberSpec")):
            register(name, f"{MODULE}:{cls}", summary=name)

    @hookimpl
    def register_test_windows(register):
        register("no-combine", f"{MODULE}:NoCombine", summary="no-combine")

    tiny = types.SimpleNamespace(register_encoders=register_encoders,
                                 register_classifiers=register_classifiers,
                                 register_splits=register_splits,
                                 register_test_windows=register_test_windows)
    return collect_registry(make_plugin_manager(entry_points=False, extra=[("tiny", tiny)]))


# ----------------------------------------------------------------------------- refused


@pytest.mark.parametrize("kind, name, missing", [
    ("encoder", "no-encode", "no method 'encode'"),
    ("encoder", "string-channels", "'channels' must be a non-empty sequence"),
    ("classifier", "no-proba", "'predict_proba' is not callable"),
    ("classifier", "rank-2", "'frame_rank' must be 3 (images), 1 (taxel vectors) or None"),
    ("classifier", "no-batch", "'batch_size' must be a positive integer, got 0"),
    ("split", "no-split", "no method 'split'"),
    ("split", "number-spec", "'spec' must be a non-empty string without spaces, or '', got 3"),
    ("test-window", "no-combine", "no method 'combine'"),
])
def test_a_component_breaking_its_contract_is_refused_at_build(registry, kind, name, missing):
    with pytest.raises(ContractError) as err:
        registry.build(kind, name)
    message = str(err.value)
    assert f"{kind} '{name}'" in message and "plugin 'tiny'" in message
    assert missing in message and "tactbench.contracts" in message
    # a plugin's mistake, and a TypeError for callers that catch that
    assert isinstance(err.value, PluginError) and isinstance(err.value, TypeError)


def test_check_lists_every_problem_at_once():
    class Empty:
        pass

    with pytest.raises(ContractError) as err:
        contracts.check("classifier", Empty(), name="empty")
    for member in ("fit", "predict", "predict_proba", "save"):
        assert f"'{member}'" in str(err.value)


# ----------------------------------------------------------------------------- accepted


def test_a_documented_protocol_encoder_builds_runs_and_gets_the_defaults(registry):
    from tactbench.encoders.evaluation.conformance import check_contract

    enc = registry.build("encoder", "minimal")
    out = enc.encode(np.zeros((4, 5, 6), np.float32))
    assert out.shape == (4, 1, 5, 6) and out.dtype == np.float32
    assert ENCODER.get(enc, "version") == "1" and ENCODER.get(enc, "ranges") == ()
    assert ENCODER.get(enc, "options") is None and ENCODER.get(enc, "metadata") is None
    check_contract(enc)  # the conformance suite's contract check agrees


def test_a_documented_protocol_classifier_builds_fits_and_predicts(registry):
    from tactbench.classifiers.conformance import tiny_windows

    clf = registry.build("classifier", "minimal")
    assert CLASSIFIER.get(clf, "frame_rank") == 3
    assert CLASSIFIER.get(type(clf), "frame_rank") == 3  # the class answers too (planning)
    assert CLASSIFIER.get(clf, "version") == "1" and CLASSIFIER.get(clf, "profiles") == {}
    assert CLASSIFIER.get(clf, "frame_shape") is None
    # what the runner and live read of it: the contract's defaults
    assert CLASSIFIER.get(clf, "batch_size") == 1 and CLASSIFIER.get(clf, "n_classes") is None
    assert CLASSIFIER.get(clf, "classes") is None
    for member in ("preflight", "export", "frame_features", "window_proba"):
        assert CLASSIFIER.get(clf, member) is None, member
    train, test = tiny_windows(3)
    clf.fit(train, None, seed=0, device="cpu", progress=None)
    assert clf.predict(test).shape == (len(test),)


def test_a_declared_member_wins_over_the_default():
    from tactbench.classifiers.classical import PooledLogReg

    assert CLASSIFIER.get(PooledLogReg, "frame_rank") is None  # images or vectors
    assert CLASSIFIER.get(PooledLogReg(), "frame_rank") is None


def test_the_builtin_classifiers_expose_what_the_runner_and_live_use():
    from tactbench.classifiers.models import SmallCnnLstm

    clf = SmallCnnLstm(batch_size=8, classes=3)
    assert CLASSIFIER.get(clf, "batch_size") == 8 and CLASSIFIER.get(clf, "n_classes") is None
    assert CLASSIFIER.get(clf, "classes") == 3  # as the runner builds a cell's classifier
    for member in ("preflight", "export", "frame_features", "window_proba"):
        assert callable(CLASSIFIER.get(clf, member)), member
    with pytest.raises(InputError, match="unknown device 'gpu7'"):
        clf.preflight("gpu7")  # refused when planned, not in every cell


def test_get_refuses_names_outside_the_contract_and_missing_required_members():
    with pytest.raises(KeyError, match="no member 'frames_rank'"):
        CLASSIFIER.get(object(), "frames_rank")
    with pytest.raises(ContractError, match="has no 'channels'"):
        ENCODER.get(object(), "channels")


def test_every_kind_has_one_contract():
    assert set(CONTRACTS) == set(KINDS)


# ----------------------------------------------------------------------------- built-ins


def _builtin_specs(registry, kind, tmp_path):
    """Every built-in component of ``kind`` with the options it needs to be built."""
    needs = {
        ("sensor", "replay"): {"path": TINY_SYNTHETIC},
        ("sensor", "cyskin-can"): {"taxel_ids": "0-10,16-26", "channel": "tb-contracts"},
        ("dataset", "cyskin-text"): {"path": str(tmp_path)},
        ("dataset", "cost"): {"path": str(tmp_path / "cost.csv")},
        ("dataset", "haart"): {"path": str(tmp_path)},
        ("dataset", "folder"): {"path": str(tmp_path)},
        ("split", "group"): {"key": "position"},
        ("split", "sklearn"): {"splitter": "GroupKFold"},
    }
    for comp in registry.components(kind):
        if comp.plugin.startswith("tactbench."):
            yield comp, needs.get((kind, comp.name), {})


@pytest.mark.parametrize("kind", KINDS)
def test_every_builtin_component_satisfies_its_contract(kind, tmp_path):
    registry = collect_registry(make_plugin_manager(entry_points=False))
    (tmp_path / "cost.csv").write_text("")
    built = 0
    for comp, options in _builtin_specs(registry, kind, tmp_path):
        if comp.missing_requirements():
            continue
        obj = registry.build(kind, comp.name, **options)
        try:
            assert CONTRACTS[kind].problems(obj) == [], comp.name
        finally:
            if kind == "sensor":
                obj.close()
                getattr(obj, "bus", None) and obj.bus.shutdown()
        built += 1
    assert built >= {"sensor": 2, "dataset": 3, "encoder": 3, "classifier": 4, "split": 4,
                     "test-window": 3, "paired-test": 2}[kind]


def test_sensors_know_their_taxels_when_built():
    registry = collect_registry(make_plugin_manager(entry_points=False))
    with registry.build("sensor", "cyskin-can", taxel_ids="0-3", channel="tb-ids") as sensor:
        assert SENSOR.get(sensor, "taxel_ids").tolist() == [0, 1, 2, 3]
        assert SENSOR.get(sensor, "stats") is not None
    with registry.build("sensor", "replay", path=TINY_SYNTHETIC) as sensor:
        assert SENSOR.get(sensor, "bus_load") is None  # a replay reads no bus


# ----------------------------------------------------------------------------- the rules

PACKAGE = __import__("pathlib").Path(contracts.__file__).parent


def _nodes(path):
    """Every node of the module at ``path``'s syntax tree."""
    import ast

    return ast.walk(ast.parse(path.read_text()))


def test_optional_members_are_read_through_their_contract_only():
    """No ``getattr(x, "<member>", default)`` outside contracts.py: the default of an
    optional member is written once, in its contract."""
    import ast

    members = {m.name for c in CONTRACTS.values() for m in c.members}
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "contracts.py":
            continue
        for node in _nodes(path):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id == "getattr" and len(node.args) == 3
                    and isinstance(node.args[1], ast.Constant)
                    and node.args[1].value in members):
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno} "
                             f"{node.args[1].value}")
    assert not found, found


#: What the runner and live may import of the component stages: the encoding pass and
#: shared encoder helpers, and the model files; never a component's module.
RUNNER_MAY_IMPORT = {"tactbench.encoders.encoding", "tactbench.encoders.parallel",
                     "tactbench.encoders.flow", "tactbench.encoders.base",
                     "tactbench.classifiers.io"}


def test_the_runner_and_live_know_components_only_through_registry_and_contracts():
    import ast

    paths = sorted((PACKAGE / "runner").glob("*.py")) + [PACKAGE / "live.py"]
    wrong = []
    for path in paths:
        for node in _nodes(path):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(
                    ("tactbench.encoders", "tactbench.classifiers")) \
                    and node.module not in RUNNER_MAY_IMPORT:
                wrong.append(f"{path.relative_to(PACKAGE)} imports {node.module}")
            # a component's private member (clf._export(), clf._device)
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__")
                    and isinstance(node.value, ast.Name)
                    and node.value.id in ("clf", "encoder", "enc", "classifier")):
                wrong.append(f"{path.relative_to(PACKAGE)}:{node.lineno} reads "
                             f"{node.value.id}.{node.attr}")
    assert not wrong, wrong
