"""The component contracts, each written once, and the check that enforces them.

A component satisfies its contract by having the members below, with no need to
inherit (base classes such as :class:`tactbench.encoders.base.Encoder` and
:class:`tactbench.classifiers.base.SequenceClassifier` point here and fill in the
optional members). :meth:`tactbench.plugins.Registry.build` calls :func:`check` on every
component it builds, the way pluggy verifies a hook implementation when it is
registered, so a component that misses a required member is refused with its plugin,
name and the missing member named, before any work starts.

Optional members have one documented default, here; code reads them with
:meth:`Contract.get` (``ENCODER.get(encoder, "version")``), never with a private
``getattr(x, "...", default)``.

Shapes use ``T`` frames, ``N`` taxels, ``H × W`` pixels, ``C`` channels,
``B`` sequences in a batch, ``L`` frames in a window.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Callable

from tactbench.errors import ContractError

_REQUIRED = object()


@dataclass(frozen=True)
class Member:
    """One member of a contract: a method (called) or an attribute (read)."""

    name: str
    method: bool
    doc: str
    default: Any = _REQUIRED
    check: Callable[[Any], str | None] | None = None  # value → problem, or None

    @property
    def required(self) -> bool:
        return self.default is _REQUIRED


@dataclass(frozen=True)
class Contract:
    """What the code relies on for one kind of component."""

    kind: str
    members: tuple[Member, ...]

    def member(self, name: str) -> Member:
        for m in self.members:
            if m.name == name:
                return m
        raise KeyError(f"the {self.kind} contract has no member '{name}'")

    def get(self, obj: Any, name: str) -> Any:
        """``obj.name``, or the contract's default for an optional member ``obj`` lacks.

        Works on a built component and on its class (for members a class declares).
        """
        member = self.member(name)
        value = getattr(obj, name, _REQUIRED)
        if value is _REQUIRED:
            if member.required:
                raise ContractError(f"{self.kind} {_describe(obj)} has no '{name}'")
            # a fresh copy of a mutable default ({} for profiles): callers may change it
            return copy.copy(member.default)
        return value

    def problems(self, obj: Any) -> list[str]:
        """Everything ``obj`` misses or gets wrong, one phrase each (empty when it conforms)."""
        out = []
        for m in self.members:
            value = getattr(obj, m.name, _REQUIRED)
            if value is _REQUIRED:
                if m.required:
                    out.append(f"no {'method' if m.method else 'attribute'} '{m.name}' "
                               f"({m.doc})")
                continue
            if m.method and not callable(value):
                out.append(f"'{m.name}' is not callable ({m.doc})")
            elif m.check is not None:
                problem = m.check(value)
                if problem:
                    out.append(f"'{m.name}' {problem}")
        return out


def _describe(obj: Any) -> str:
    return type(obj).__name__ if not isinstance(obj, type) else obj.__name__


def _channels(value: Any) -> str | None:
    if isinstance(value, str) or not hasattr(value, "__len__") or len(value) == 0 \
            or not all(isinstance(c, str) and c for c in value):
        return f"must be a non-empty sequence of channel names, got {value!r}"
    if len(set(value)) != len(value):
        return f"names a channel twice: {value!r}"
    return None


def _frame_rank(value: Any) -> str | None:
    if value not in (1, 3, None) or isinstance(value, bool):
        return f"must be 3 (images), 1 (taxel vectors) or None (either), got {value!r}"
    return None


def _ranges(value: Any) -> str | None:
    try:
        ok = all(len(r) == 2 and float(r[0]) <= float(r[1]) for r in value)
    except (TypeError, ValueError):
        ok = False
    return None if ok else f"must be (low, high) pairs, one per channel, got {value!r}"


def _text(value: Any) -> str | None:
    # Versions go into cache keys as text; a number is accepted (str(2) is stable).
    if isinstance(value, bool) or not isinstance(value, (str, int)) or value == "":
        return f"must be a non-empty string, got {value!r}"
    return None


def _spec(value: Any) -> str | None:
    if not isinstance(value, str) or value != value.strip() or any(c.isspace() for c in value):
        return f"must be a non-empty string without spaces, or '', got {value!r}"
    return None


def _count(value: Any) -> str | None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        return f"must be a positive integer, got {value!r}"
    return None


def _optional_count(value: Any) -> str | None:
    return None if value is None else _count(value)


def _profiles(value: Any) -> str | None:
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, dict)
                                              for k, v in value.items()):
        return f"must map profile names to option dicts, got {value!r}"
    return None


def _taxel_ids(value: Any) -> str | None:
    kind = getattr(getattr(value, "dtype", None), "kind", None)
    if getattr(value, "ndim", None) != 1 or kind not in ("i", "u"):
        shape = getattr(value, "shape", None)
        return (f"must be an integer array (N,), got {type(value).__name__}"
                + (f" of shape {shape} and dtype {value.dtype}" if shape is not None else ""))
    return None


#: Encoders: ``(T, H, W)`` float32 in [0, 1] → ``(T, C, H, W)`` float32.
#: A plugin needs only ``channels`` and ``encode``; :class:`tactbench.encoders.base.Encoder`
#: fills in the rest (and the shared input checks). Flow encoders have ``flow``,
#: ``max_flow`` and ``min_magnitude``: see :func:`tactbench.encoders.flow.is_flow_encoder`.
ENCODER = Contract("encoder", (
    Member("channels", False, "names of the C output channels", check=_channels),
    Member("encode", True, "encode(seq (T, H, W) float32 in [0, 1]) → (T, C, H, W) float32"),
    Member("name", False, "a label for messages and metadata; '' means use the registered "
           "name or the class name", default=""),
    Member("version", False, "changes when the output for the same input changes; part of "
           "cache keys", default="1", check=_text),
    Member("ranges", False, "(low, high) per channel, checked by the conformance suite; "
           "() means not declared", default=(), check=_ranges),
    Member("options", True, "options() → the keyword options it was built with "
           "(None: not known)", default=None),
    Member("metadata", True, "metadata() → name, version, options, channels, ranges "
           "(None: built from channels)", default=None),
    Member("encode_vectors", True, "encode_vectors(seq (T, N) float32 in [0, 1]) → (T, C·N) "
           "float32, the channels side by side: the encoding of taxel vectors, for "
           "layout-free classifiers (None: the encoder needs images)", default=None),
    Member("flow", True, "flow(prev, curr) → (N, H, W, 2) px/frame, of a dense-flow "
           "encoder (None: not a flow encoder; see is_flow_encoder)", default=None),
    Member("max_flow", False, "a flow encoder's flow (px/frame) that maps to magnitude 1",
           default=None),
    Member("min_magnitude", False, "a flow encoder's smallest magnitude kept (below it: 0)",
           default=None),
))

#: Classifiers: ``fit`` on windows ``(B, L, C, H, W)`` or ``(B, L, N)``, then ``predict``.
#: ``frame_shape``, ``L`` and ``n_classes`` are state a fitted (or loaded) classifier
#: knows.
CLASSIFIER = Contract("classifier", (
    Member("fit", True, "fit(train, val, *, seed, device, progress) → JSON-ready report"),
    Member("predict", True, "predict(batch) → class indices (B,)"),
    Member("predict_proba", True, "predict_proba(batch) → (B, n_classes) probabilities"),
    Member("save", True, "save(path, metadata) without pickle"),
    Member("frame_rank", False, "3: frames are images (C, H, W); 1: taxel vectors (N,); "
           "None: either", default=3, check=_frame_rank),
    Member("version", False, "changes when training changes for the same options",
           default="1", check=_text),
    Member("profiles", False, "profile name → default options (quick, paper)", default={},
           check=_profiles),
    Member("frame_shape", False, "the frame shape it was fitted on, (C, H, W) or (N,); "
           "None before fit", default=None),
    Member("L", False, "the window length L it was fitted on; None before fit",
           default=None),
    Member("classes", False, "the number of classes K it was built for: each cell of a run "
           "builds its classifier with the option classes=K (None: learnt from the labels "
           "in fit)", default=None, check=_optional_count),
    Member("n_classes", False, "the number of classes it outputs; None before fit",
           default=None, check=_optional_count),
    Member("batch_size", False, "windows per training batch (the runner's memory "
           "estimate)", default=1, check=_count),
    Member("preflight", True, "preflight(device) raises a TactbenchError naming the "
           "problem when the classifier could not run here on device (one this machine "
           "lacks; a bad setting in the environment): called when a run is planned, "
           "before any work (None: nothing to check)", default=None),
    Member("estimate_seconds", True, "estimate_seconds(*, frame_shape, L, n_classes, "
           "n_train_windows, n_frames, n_test_windows) → the seconds one cell takes on "
           "one thread, for `tactbench plan` before any pilot (None: unknown until a "
           "pilot row exists)", default=None),
    Member("export", True, "export() → (config, tensors): its JSON-ready configuration and "
           "named tensors, for checking a saved model (None: nothing to export)",
           default=None),
    Member("frame_features", True, "frame_features(frame (C, H, W) or (N,)) → the frame's "
           "features, computed once per frame by live classification; with window_proba "
           "(None: live classification calls predict_proba on each whole window)",
           default=None),
    Member("window_proba", True, "window_proba(features of L frames) → (n_classes,) "
           "probabilities, as predict_proba gives for the window of those frames (None: "
           "see frame_features)", default=None),
))

#: Sensors: live sources of frames, used as context managers (``with sensor:``).
#: ``taxel_ids`` is known when the sensor is built: the replay sensor reads it from the
#: recording, ``cyskin-can`` from its ``taxel_ids`` or ``layout`` option.
SENSOR = Contract("sensor", (
    Member("taxel_ids", False, "int (N,): the taxel each value belongs to", check=_taxel_ids),
    Member("frames", True, "frames() → Frame objects in time order"),
    Member("close", True, "close() ends frames()"),
    Member("__enter__", True, "sensors are context managers: __enter__() → the sensor"),
    Member("__exit__", True, "__exit__(*exc) closes the sensor"),
    Member("layout", False, "the TaxelLayout when the sensor knows it", default=None),
    Member("stats", False, "counters of what was received and lost (with to_dict()); None "
           "when the sensor keeps none", default=None),
    Member("bus_load", True, "bus_load() → the expected load of the bus it reads (with "
           "describe()); None for sensors without a bus", default=None),
))

#: What a sensor's ``frames()`` yields (checked where frames are read, not at build).
FRAME = Contract("frame", (
    Member("timestamp", False, "seconds"),
    Member("values", False, "float32 (N,), in the order of the sensor's taxel_ids"),
    Member("missing", False, "values of this sweep that did not arrive (held or zeroed)",
           default=0),
    Member("label", False, "the gesture marker in force, when the source has markers",
           default=None),
))

#: Datasets: built with keyword options (``path=...``), loaded on demand.
DATASET = Contract("dataset", (
    Member("load", True, "load() → tactbench.data.recording.Dataset"),
    Member("run_spec", True, "run_spec(seed) → the spec of the data set run `seed` trains "
           "and tests on, for a dataset that draws a new one for every run (independent "
           "replications, docs/statistics.md); None: one data set for every run",
           default=None),
))

#: The designs a split declares (its ``design``): how its runs relate, and so which t
#: a comparison of two cells' runs uses (docs/statistics.md, "Which t a split's design
#: gets").
SPLIT_DESIGNS = {
    "resampled": "a random train/test split redrawn for every seed: the Nadeau–Bengio "
                 "corrected t, with n_test/n_train",
    "kfold": "K folds per run, each recording tested once (repeated over seeds): the "
             "corrected repeated K-fold t, 1/(K − 1)",
    "fixed": "the same train/test split every seed (runs differ by initialisation only): "
             "the plain paired t over runs, about this one split",
    "independent": "the test set of each run from data of its own, independent of the "
                   "others': the plain paired t over runs",
}


def _design(value: Any) -> str | None:
    if value is None or (isinstance(value, str) and value in SPLIT_DESIGNS):
        return None
    return f"must be one of {', '.join(SPLIT_DESIGNS)} (or None: undeclared), got {value!r}"


def _group_key(value: Any) -> str | None:
    if value is None or (isinstance(value, str) and value.isidentifier()):
        return None
    return f"must be the name of recording metadata ('user', 'position') or None, " \
           f"got {value!r}"


#: Splits: how a dataset's recordings become train/test pairs (docs/plugins.md).
#: ``split`` returns one :class:`tactbench.data.splits.Split` per fold, numbered from 0,
#: each with a group id for every test recording; the runner checks what it returns
#: (:func:`tactbench.data.splits.check_splits`) before training on it.
SPLIT = Contract("split", (
    Member("split", True, "split(data: SplitData, *, seed) → [Split, ...], one per fold, "
           "folds 0, 1, ...; the same for the same data and seed"),
    Member("spec", False, "how cell identities and rows record this split ('users:folds=5'); "
           "'' means its name with its options sorted", default="", check=_spec),
    Member("design", False, "how its runs relate, one of SPLIT_DESIGNS: 'resampled', "
           "'kfold', 'fixed', 'independent'; it picks the t of every comparison (None: "
           "undeclared, read as 'resampled', or 'kfold' where it returns several folds)",
           default=None, check=_design),
    Member("group_key", False, "the recording metadata ('user', 'position', ...) whose "
           "values it keeps apart: no value in both the train and the test set of a fold, "
           "checked on every draw (None: a split over recordings)", default=None,
           check=_group_key),
))

#: Test windows: which L-frame windows of a recording a classifier is trained and tested
#: on, and how the predictions of one test recording's windows combine.
TEST_WINDOW = Contract("test-window", (
    Member("training", True, "training(sequences, labels, L, *, prepared) → Windows: the "
           "training windows of these recordings (sequences[i]: (T_i, *frame))"),
    Member("test", True, "test(sequences, labels, L, *, prepared) → Windows: the test "
           "windows, seq_index naming each one's recording"),
    Member("combine", True, "combine(classifier, windows, n) → (n,) int: the class of each "
           "of the n test recordings from the predictions of its windows"),
    Member("prepare", True, "prepare(dataset) → one picklable value per recording (its "
           "contact onset, ...), computed once per run and given back, for the recordings "
           "at hand, as prepared (None: nothing to prepare; prepared is then None)",
           default=None),
))

#: What a paired test declares, beside the split designs, for the looks of a run
#: ``--until answered``: a test with a known null distribution at each look.
SEQUENTIAL = "sequential"


def _paired_designs(value: Any) -> str | None:
    known = {*SPLIT_DESIGNS, SEQUENTIAL}
    if isinstance(value, (set, frozenset, tuple, list)) and value and set(value) <= known:
        return None
    return f"must be a non-empty collection of {', '.join(sorted(known))}, got {value!r}"


def _label(value: Any) -> str | None:
    return None if isinstance(value, str) and value.strip() else \
        f"must be non-empty text, got {value!r}"


#: Paired tests: the test a comparison's p and interval come from (docs/statistics.md,
#: :mod:`tactbench.runner.analysis.paired_tests`).
PAIRED_TEST = Contract("paired-test", (
    Member("test", True, "test(d, *, ratio, confidence) → {'low', 'high', 'p', 'df'}: B − A "
           "per run (a float array) → the interval and two-sided p, df None where none"),
    Member("designs", False, "the split designs (SPLIT_DESIGNS) and 'sequential' (the looks "
           "of --until) it is valid for; refused for the others", check=_paired_designs),
    Member("label", False, "how report.md names it ('Wilcoxon signed-rank test')",
           check=_label),
))

CONTRACTS: dict[str, Contract] = {c.kind: c for c in (ENCODER, CLASSIFIER, SENSOR, DATASET,
                                                      SPLIT, TEST_WINDOW, PAIRED_TEST)}


def check(kind: str, obj: Any, *, name: str = "", plugin: str = "") -> Any:
    """Return ``obj`` if it satisfies the ``kind`` contract, else raise :class:`ContractError`
    naming the plugin, the component and every problem found."""
    problems = CONTRACTS[kind].problems(obj)
    if problems:
        who = f"{kind} '{name}'" if name else f"{kind} {_describe(obj)}"
        where = f" (plugin '{plugin}')" if plugin else ""
        raise ContractError(f"{who}{where} breaks the {kind} contract: "
                            f"{'; '.join(problems)}. See tactbench.contracts.")
    return obj
