"""Planning: check a whole scene before any work and expand it into cells.

A cell is one point of the grid (encoder × classifier × L × seed). Its *identity* is
everything that decides its result (dataset content hash, split, imaging, encoder and
version, storage precision, classifier with all options, profile, L, seed); the hash of
the identity is the cell's key, which names its result file, so a changed setting is a
new cell. The precision is written into the identity only when it is not ``float32``, so
float32 cells keep the keys they had before precisions existed.

(Named ``planning``, not ``plan``: the package re-exports the function :func:`plan`,
which would hide a submodule of the same name.)
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

from tactbench.errors import (
    InputError,
    check_choice,
    check_positive_float,
    check_positive_int,
)
from tactbench.runner.scene import EXECUTORS, Scene

#: Part of every cell's identity: bump it when a row's meaning changes, so that old
#: rows are not taken for new ones.
ROW_SCHEMA = 1


@dataclass(frozen=True)
class Cell:
    """One point of the grid. ``key`` names its result file."""

    encoder: str  # canonical spec, options sorted
    classifier: str  # canonical spec including the profile's options
    length: int  # window length L, frames
    seed: int
    key: str

    def label(self) -> str:
        """A short human name: ``raw × small-cnn-lstm L=5 seed=0``."""
        return (f"{self.encoder} × {self.classifier.split(':')[0]} L={self.length} "
                f"seed={self.seed}")


@dataclass
class Plan:
    """A checked scene: the dataset loaded, components resolved, cells expanded."""

    scene: Scene
    dataset: Any  # tactbench.data.recording.Dataset
    dataset_hash: str
    encoders: dict[str, Any]  # canonical spec → encoder instance
    encoder_versions: dict[str, str]
    classifier_specs: list[str]  # canonical, profile options resolved
    input_kind: dict[str, str]  # classifier spec → "images" | "vectors"
    cells: list[Cell]
    identities: dict[str, dict[str, Any]]  # cell key → identity
    registry: Any = None  # the tactbench.plugins.Registry the plan was checked with

    def classifier_component(self, spec: str):
        """The registered :class:`~tactbench.plugins.Component` of a classifier spec."""
        from tactbench.plugins import parse_spec

        return self.registry.get("classifier", parse_spec(spec)[0])


def digest(obj: Any, n: int = 16) -> str:
    """The first ``n`` hex digits of the SHA-256 of ``obj`` as sorted JSON."""
    text = json.dumps(obj, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def imaging_identity(scene: Scene, kind: str) -> dict[str, Any]:
    """What decides a classifier's input frames: vectors, or images at a pixel size."""
    if kind == "vectors":
        return {"kind": "vectors"}
    return {"kind": "images", "pixel_mm": scene.resolved_pixel_mm(), "method": scene.imaging}


def storage_identity(precision: str) -> dict[str, Any]:
    """What the storage precision adds to a cell identity or cache key: nothing for
    ``float32`` (so keys made before precisions existed stay valid), else ``precision``."""
    return {} if precision == "float32" else {"precision": precision}


def input_kind(frame_rank: int | None, has_layout: bool) -> str:
    """``"vectors"`` or ``"images"``: what a classifier of ``frame_rank`` is fed.

    ``frame_rank`` is the classifier contract's (3: images, 1: taxel vectors, None:
    either); one that takes either gets images when the dataset has a taxel layout to
    make them, and taxel vectors otherwise.
    """
    if frame_rank == 1 or (frame_rank is None and not has_layout):
        return "vectors"
    return "images"


def _canonical(spec: str, extra: dict[str, Any] | None = None) -> tuple[str, dict]:
    from tactbench.plugins import format_spec, parse_spec

    name, options = parse_spec(spec)
    merged = {**(extra or {}), **options}
    return format_spec(name, merged), merged


def _check_scene(scene: Scene) -> None:
    from tactbench.data.splits import SPLITS
    from tactbench.profiles import PRECISIONS, get_profile

    get_profile(scene.profile)
    check_choice(scene.resolved_precision(), "precision", PRECISIONS)
    check_choice(scene.split, "split", tuple(SPLITS))
    check_choice(scene.executor, "executor", EXECUTORS)
    if not scene.encoders or not scene.classifiers or not scene.lengths or not scene.seeds:
        raise InputError("a run needs at least one encoder, classifier, L and seed")
    bad_l = [n for n in scene.lengths if int(n) < 1]
    if bad_l:
        raise InputError(f"window length L must be ≥ 1, got {bad_l}")
    check_positive_int(scene.workers, "--workers")
    if scene.threads is not None:  # torch refuses 0 only inside the cell, after the work
        check_positive_int(scene.threads, "--threads")
    # the training memory settings come from the environment: read them now, not in a cell
    from tactbench.classifiers.base import bank_budget_bytes, loader_workers

    bank_budget_bytes()
    loader_workers(None)
    check_positive_float(scene.resolved_pixel_mm(), "pixel size (mm)")


def _check_inputs(clf: str, enc: str, kind: str, frame_rank: int | None, dataset) -> None:
    """Refuse an (encoder, classifier) pair whose classifier cannot be fed."""
    from tactbench.plugins import parse_spec

    is_raw = parse_spec(enc)[0] == "raw"
    if kind == "images" or is_raw:
        if kind == "images" and dataset.layout is None:
            raise InputError(f"classifier '{clf}' works on tactile images, and dataset "
                             f"'{dataset.name}' has no taxel layout to make them; use "
                             f"a taxel-vector classifier (e.g. taxel-lstm) with "
                             f"--encoder raw, or give the dataset a layout")
        return
    if frame_rank is None:  # could take images, but there is no layout to make them
        raise InputError(f"encoder '{enc}' works on tactile images, and dataset "
                         f"'{dataset.name}' has no taxel layout to make them; classifier "
                         f"'{clf}' can take taxel vectors with --encoder raw, or give the "
                         f"dataset a layout")
    raise InputError(f"classifier '{clf}' takes taxel vectors, which only the 'raw' "
                     f"encoder passes through; got encoder '{enc}'")


def plan(scene: Scene, registry=None, *, progress=None) -> Plan:
    """Check the whole grid before any work: names, options, L, layout needs, split.

    ``registry`` (default: every installed plugin) is the one the cells will use too.
    ``progress(done, total)`` hears from a dataset that takes a while to make (the
    simulator's first run).
    Raises a :class:`~tactbench.errors.TactbenchError` naming the problem; nothing is
    computed or written.
    """
    from tactbench.contracts import CLASSIFIER, ENCODER
    from tactbench.plugins import load_registry, parse_spec
    from tactbench.profiles import profile_options

    registry = registry or load_registry()
    _check_scene(scene)

    # Names and options first (cheap), so a typo fails before a dataset is loaded.
    encoders: dict[str, Any] = {}
    versions: dict[str, str] = {}
    for spec in dict.fromkeys(scene.encoders):
        canonical, _ = _canonical(spec)
        if canonical in encoders:
            continue
        encoder = registry.build("encoder", canonical)
        encoders[canonical] = encoder
        versions[canonical] = str(ENCODER.get(encoder, "version"))
    frame_ranks: dict[str, int | None] = {}  # canonical classifier spec → frame rank
    for spec in dict.fromkeys(scene.classifiers):
        name, _ = parse_spec(spec)
        canonical, _ = _canonical(spec, profile_options(scene.profile, name,
                                                        registry=registry))
        clf = registry.build("classifier", canonical)  # validates option names and values
        frame_ranks.setdefault(canonical, CLASSIFIER.get(clf, "frame_rank"))
    classifier_specs = list(frame_ranks)

    from tactbench.datasets.loading import load_dataset

    dataset = load_dataset(scene.dataset, registry=registry, progress=progress)
    has_layout = dataset.layout is not None
    kinds = {clf: input_kind(rank, has_layout) for clf, rank in frame_ranks.items()}
    for clf in classifier_specs:
        for enc in encoders:
            _check_inputs(clf, enc, kinds[clf], frame_ranks[clf], dataset)
    dataset_hash = dataset.content_hash()
    from tactbench.data.splits import make_split

    make_split(scene.split, labels=dataset.labels, users=dataset.users, seed=scene.seeds[0],
               test_per_class=scene.test_per_class)  # fails early on an impossible split

    cells: list[Cell] = []
    identities: dict[str, dict[str, Any]] = {}
    storage = storage_identity(scene.resolved_precision())
    for enc in encoders:
        for clf in classifier_specs:
            for length in scene.lengths:
                for seed in scene.seeds:
                    identity = {
                        "schema": ROW_SCHEMA,
                        "dataset": dataset.name,
                        "dataset_hash": dataset_hash,
                        "split": scene.split,
                        "test_per_class": scene.test_per_class,
                        "imaging": imaging_identity(scene, kinds[clf]),
                        "encoder": enc,
                        "encoder_version": versions[enc],
                        **storage,
                        "classifier": clf,
                        "profile": scene.profile,
                        "L": int(length),
                        "seed": int(seed),
                    }
                    key = digest(identity)
                    cells.append(Cell(enc, clf, int(length), int(seed), key))
                    identities[key] = identity
    return Plan(scene, dataset, dataset_hash, encoders, versions, classifier_specs,
                kinds, cells, identities, registry)
