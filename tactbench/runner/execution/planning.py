"""Planning: check a whole scene before any work and expand it into cells.

A :class:`~tactbench.runner.execution.scene.Scene` checked its own fields when it was made; planning
checks, once, what needs the plugins, the dataset or the disk: every component's name and
options (encoders, classifiers, the split and the test window, built by the registry),
the inputs each classifier can be fed, L against the longest sequence, the memory of the
large steps, the split drawn once for the first seed, the out folder.

A cell is one point of the grid (encoder × classifier × L × seed). Its *identity* is
everything that decides its result (dataset content hash, split, imaging, encoder and
version, storage precision, classifier with all options, profile, L, seed, and the torch
threads and CPU kernels it computes with); the hash of
the identity is the cell's key, which names its result file, so a changed setting is a
new cell. The precision is written into the identity only when it is not ``float32``, and the
test window only when it is not the study's ``first``, the threads only when not 1 and the
kernels only when not pinned to AVX2 (:func:`compute_identity`), so cells keep the keys
they had before either existed.

(Named ``planning``, not ``plan``: the package re-exports the function :func:`plan`,
which would hide a submodule of the same name.)
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import Any, Mapping

from tactbench.contracts import CLASSIFIER, DATASET, ENCODER
from tactbench.data.imaging import image_shape, imager_build_bytes
from tactbench.data.splits import SplitData, build_split, draw_splits, split_spec
from tactbench.datasets.loading import check_informative, is_path_spec, load_dataset
from tactbench.encoders.encoding import CHUNK_BYTES
from tactbench.errors import BudgetError, InputError
from tactbench.paths import check_output_folder
from tactbench.plugins import load_registry
from tactbench.profiles import canonical_classifier
from tactbench.budget import check_budget, memory_budget_bytes
from tactbench.classifiers.batching import bank_budget_bytes, loader_workers
from tactbench.runner.execution.identity import (  # noqa: F401 — digest and the row's
    COMPUTE_FIELDS, IDENTITY_DEFAULTS, IDENTITY_FIELDS, INDEPENDENT_RUNS,  # identity: said
    compute_identity, digest, row_identity, row_keys, without_defaults)  # there, read here too
from tactbench.runner.execution.results import ROW_MAX_BYTES
from tactbench.runner.execution.questions import check_contrasts, parse_contrast, short_name
from tactbench.specs import format_spec, parse_spec
from tactbench.runner.execution.scene import Scene
from tactbench.runner.execution.record import Compute, resolve_compute
from tactbench.runner.execution.results import run_folder_entries  # what a run writes, said there

#: Part of every cell's identity: bump it when a row's meaning changes, so that old
#: rows are not taken for new ones.
ROW_SCHEMA = 1


@dataclass(frozen=True)
class Cell:
    """One point of the grid. ``key`` names its result file."""

    encoder: str  # canonical spec, options sorted
    classifier: str  # canonical spec including the profile's options
    L: int  # the window length, frames
    seed: int
    key: str
    init_seed: int | None = None  # the initialisation's seed when varied apart from the split's

    def label(self, labels: Mapping[str, str] | None = None) -> str:
        """A short human name: ``raw × small-cnn-lstm L=5 seed=0``; the classifier by its
        label in ``labels`` (:func:`tactbench.runner.execution.questions.spec_labels`) where that
        tells it from another spec of the same name: ``raw × small-cnn-lstm (width=8)``."""
        clf = (labels or {}).get(self.classifier, "")
        if not clf or clf == short_name(self.classifier):  # unique: its name, as ever
            clf = self.classifier.split(":")[0]
        return f"{self.encoder} × {clf} L={self.L} seed={self.seed}"


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
    split: Any = None  # the scene's split, built (a strategy: tactbench.contracts.SPLIT)
    test_window: Any = None  # the scene's test window, built (TEST_WINDOW)
    run_dataset: str | None = None  # the spec of the run's own data set (plan_runs)
    #: the sizes of a let-go data set (:class:`DatasetSizes`): what its cache entries take
    sizes: Any = None
    batch_bytes: int = 0  # the largest batch of windows a cell trains on (bytes)
    compute: Any = None  # the run's Compute (record.py): threads, kernels, device

    def classifier_component(self, spec: str):
        """The registered :class:`~tactbench.plugins.Component` of a classifier spec."""
        return self.registry.get("classifier", parse_spec(spec)[0])


@dataclass(frozen=True)
class DatasetSizes:
    """What a data set's cache entries take, kept when a run's own data set is let go
    (:func:`plan_runs`), so that a run's room check counts every run's entries before
    any is written: the frames of each sample, the taxels and the image shape at the
    scene's imaging (None where it has no layout), answered as the data set answers."""

    frames: tuple[int, ...]
    taxels: int
    image: tuple[int, int] | None

    @classmethod
    def of(cls, dataset: Any, scene: Scene) -> "DatasetSizes":
        try:
            image = tuple(dataset.image_shape(scene.resolved_pixel_mm(), scene.imaging))
        except Exception:  # noqa: BLE001 — no layout (vectors only): no image entries
            image = None
        return cls(tuple(int(n) for n in dataset.lengths()), int(dataset.n_taxels), image)

    def lengths(self) -> list[int]:
        return list(self.frames)

    @property
    def n_taxels(self) -> int:
        return self.taxels

    def image_shape(self, pixel_mm: float, method: str) -> tuple[int, int]:
        if self.image is None:
            raise InputError("this data set has no taxel layout: it has no tactile images")
        return self.image


def check_environment() -> None:
    """Read now every environment value a run reads later (a cell's memory budget, frame
    bank and loader workers, in a worker), so that a hostile one (``inf``, ``nan``, a
    negative, a word) is one line before anything is planned or written, not a
    traceback or a failed cell after."""
    memory_budget_bytes()
    bank_budget_bytes()
    loader_workers("cpu")


def imaging_identity(scene: Scene, kind: str) -> dict[str, Any]:
    """What decides a classifier's input frames: vectors, or images at a pixel size."""
    if kind == "vectors":
        return {"kind": "vectors"}
    return {"kind": "images", "pixel_mm": scene.resolved_pixel_mm(), "method": scene.imaging}


def storage_identity(precision: str) -> dict[str, Any]:
    """What the storage precision adds to a cell identity or cache key: nothing for
    ``float32`` (so keys made before precisions existed stay valid), else ``precision``."""
    return without_defaults({"precision": precision})


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
    name, options = parse_spec(spec)
    merged = {**(extra or {}), **options}
    return format_spec(name, merged), merged


def _check_statistics(scene: Scene) -> None:
    """The contrasts' syntax (see docs/statistics.md); the scene checked the rest."""
    for text in [*(scene.contrasts or ()), *scene.design.primary]:
        parse_contrast(text)


def _build_designs(scene: Scene, registry) -> tuple[Any, Any, str, str]:
    """The scene's split and test window built by ``registry`` (names and options
    checked, contracts too), with how cell identities record them: ``(split, test
    window, split spec, test window spec)``."""
    split = build_split(scene.split, registry)
    window = registry.build("test-window", scene.test_window)
    return split, window, split_spec(split, scene.split), \
        registry.resolve("test-window", scene.test_window)


def _check_split(scene: Scene, split: Any, dataset) -> None:
    """Draw the split once (seed: the first), so an impossible split, or a plugin's that
    breaks its contract, fails before any work; and refuse saving models of a split that
    trains one per fold."""
    data = SplitData.of(dataset, test_per_class=scene.test_per_class)
    splits = draw_splits(split, data, scene.seeds[0], f"split {scene.split!r}")
    if len(splits) > 1 and scene.save_models:
        raise InputError(f"--save-models keeps one model per cell, and split "
                         f"{scene.split!r} trains one per fold; save models with "
                         f"--split users, group:KEY or paper")


def _check_inputs(clf: str, enc: str, kind: str, frame_rank: int | None, dataset, *,
                  vectors_ok: bool = False) -> None:
    """Refuse an (encoder, classifier) pair whose classifier cannot be fed.

    ``vectors_ok``: the encoder encodes taxel vectors too (``encode_vectors``: raw,
    frame-diff), so it can feed a taxel-vector classifier."""
    if kind == "images" or vectors_ok:
        if kind == "images" and dataset.layout is None:
            raise InputError(f"classifier '{clf}' works on tactile images, and dataset "
                             f"'{dataset.name}' has no taxel layout to make them; use "
                             f"a taxel-vector classifier (e.g. taxel-lstm) with "
                             f"--encoder raw, or give the dataset a layout")
        return
    if frame_rank is None:  # could take images, but there is no layout to make them
        raise InputError(f"encoder '{enc}' works on tactile images, and dataset "
                         f"'{dataset.name}' has no taxel layout to make them; classifier "
                         f"'{clf}' can take taxel vectors with --encoder raw (or "
                         f"frame-diff), or give the "
                         f"dataset a layout")
    raise InputError(f"classifier '{clf}' takes taxel vectors, and encoder '{enc}' only "
                     f"encodes images; use an encoder of taxel vectors (raw, frame-diff)")


def _check_lengths(scene: Scene, dataset) -> None:
    """Refuse window lengths longer than every sequence (all windows would be padding)."""
    lengths = dataset.lengths()
    if not len(lengths):
        raise InputError(f"dataset '{dataset.name}' has no samples")
    longest = int(lengths.max())
    too_long = sorted({int(n) for n in scene.L if int(n) > longest})
    if too_long:
        shown = ", ".join(map(str, too_long[:5])) + (", …" if len(too_long) > 5 else "")
        raise InputError(f"window length L = {shown} is longer than every sequence of "
                         f"dataset '{dataset.name}': the longest (sample "
                         f"{int(lengths.argmax())}) has {longest} frames; use L ≤ {longest}")


def _check_memory(scene: Scene, dataset, encoders: dict[str, Any], kinds: dict[str, str],
                  batch_sizes: dict[str, int]) -> int:
    """Estimate the large steps' memory from the inputs and refuse, before any work, one
    above the budget (:func:`tactbench.budget.check_budget`): building the imaging
    operator, a chunk of images and its encodings (two in flight), and a batch of windows
    of the longest L. The same estimates guard the allocations themselves
    (:class:`~tactbench.data.imaging.Imager`, :meth:`~tactbench.data.windows.Windows.batch`).
    Returns the largest batch's bytes (a worker's memory forecast reads it).
    """
    channels = {enc: len(tuple(ENCODER.get(obj, "channels"))) for enc, obj in encoders.items()}
    k = len(dataset.classes)  # a row holds a k × k confusion: ≥ 2 bytes a count as JSON
    if 2 * k * k > ROW_MAX_BYTES:
        raise BudgetError(f"dataset '{dataset.name}' has {k} classes: each cell's row "
                          f"would hold a {k} × {k} confusion, more than the "
                          f"{ROW_MAX_BYTES >> 20} MiB a row may be; at most "
                          f"{math.isqrt(ROW_MAX_BYTES // 2)} classes")
    longest = int(dataset.lengths().max())
    length = max(int(n) for n in scene.L)
    frame_shape = {"vectors": (dataset.n_taxels,)}
    if "images" in kinds.values():
        pixel_mm, method = scene.resolved_pixel_mm(), scene.imaging
        h, w = image_shape(dataset.layout, pixel_mm)
        frame_shape["images"] = (h, w)
        for obj in encoders.values():  # windows larger than the image: before any work
            if hasattr(obj, "check_image_size"):
                obj.check_image_size(h, w)
        what = f"tactile images at {pixel_mm:g} mm ({h}×{w} px)"
        check_budget(imager_build_bytes(dataset.layout, pixel_mm, method),
                     f"the imaging operator for {what}")
        frames = max(CHUNK_BYTES // (4 * h * w), longest)  # a chunk holds ≥ 1 sample
        c = sum(channels.values())
        check_budget(2 * frames * 4 * h * w * (2 + c),
                     f"imaging and encoding {what}, chunks of {frames} frames into {c} "
                     f"channels")
    largest = 0
    for clf, kind in kinds.items():
        for enc in encoders:
            shape = (channels[enc], *frame_shape["images"]) if kind == "images" \
                else frame_shape["vectors"]
            per_frame = 4 * math.prod(shape)
            batch = batch_sizes[clf]
            check_budget(batch * length * per_frame,
                         f"a batch of {batch} windows of L={length} frames {shape} "
                         f"({enc} × {clf.split(':')[0]})")
            largest = max(largest, batch * length * per_frame)
    return largest


def _build_encoders(scene: Scene, registry) -> tuple[dict[str, Any], dict[str, str]]:
    """Every encoder of the scene built once: ``(canonical spec → encoder, canonical spec
    → version)``."""
    encoders: dict[str, Any] = {}
    versions: dict[str, str] = {}
    for spec in dict.fromkeys(scene.encoders):
        canonical, _ = _canonical(registry.resolve("encoder", spec))
        if canonical in encoders:
            continue
        encoder = registry.build("encoder", canonical)
        encoders[canonical] = encoder
        versions[canonical] = str(ENCODER.get(encoder, "version"))
    return encoders, versions


def _build_classifiers(scene: Scene, registry) -> tuple[dict[str, int | None], dict[str, int]]:
    """Every classifier of the scene built once with its profile's options (which checks
    option names and values) and preflighted: ``(canonical spec → frame rank, canonical
    spec → windows per batch)``."""
    frame_ranks: dict[str, int | None] = {}
    batch_sizes: dict[str, int] = {}
    for spec in dict.fromkeys(scene.classifiers):  # "sklearn:SVC" → estimator=SVC
        canonical = canonical_classifier(spec, scene.profile, registry=registry)
        clf = registry.build("classifier", canonical)  # validates option names and values
        frame_ranks.setdefault(canonical, CLASSIFIER.get(clf, "frame_rank"))
        batch_sizes[canonical] = CLASSIFIER.get(clf, "batch_size")
        preflight = CLASSIFIER.get(clf, "preflight")
        if preflight is not None:  # a device this machine lacks would fail every cell
            preflight(scene.device if scene.executor == "local" else "cpu")
    return frame_ranks, batch_sizes


def cell_identity(scene: Scene, dataset, dataset_hash: str, kind: str, encoder: str,
                  encoder_version: str, classifier: str, L: int,
                  seed: int, init_seed: int | None = None, *, split: str,
                  test_window: str, compute: Mapping[str, Any], either_input: bool = False,
                  run_dataset: str | None = None) -> dict[str, Any]:
    """Everything that decides a cell's result; its :func:`digest` is the cell's key.

    ``split`` and ``test_window`` are the specs :func:`plan` recorded them by.
    ``init_seed`` (``--init-seed``) and the input kind of a classifier taking either
    (``either_input``, when ``--input`` is given) enter only where asked for, so every
    other cell keeps its key. ``run_dataset``: the spec of the run's own data set, where
    every run draws one (:func:`plan_runs`); such a cell's identity records it and
    :data:`INDEPENDENT_RUNS`, every other cell's neither. ``compute``: what the run's
    computation adds (:meth:`~tactbench.runner.execution.record.Compute.identity`)."""
    return without_defaults({  # each field left out at its default (identity.py)
        "schema": ROW_SCHEMA,
        "dataset": dataset.name,
        "dataset_hash": dataset_hash,
        "split": split,
        "test_window": test_window,
        "test_per_class": scene.test_per_class,
        "imaging": imaging_identity(scene, kind),
        "encoder": encoder,
        "encoder_version": encoder_version,
        "precision": scene.resolved_precision(),
        "classifier": classifier,
        "profile": scene.profile,
        "L": int(L),
        "seed": int(seed),
        "init_seed": None if init_seed is None else int(init_seed),
        "input": kind if scene.input and either_input else None,
        "run_dataset": run_dataset, INDEPENDENT_RUNS: True if run_dataset else None,
        **compute,
    })


def row_key_problem(row: Mapping[str, Any]) -> str | None:
    """Why ``row`` is not the row of the cell its ``key`` names (its identity hashes to
    another key: a row copied under another name, or edited and re-sealed), or None.
    A row keyed before threads, kernels or the device entered identities (an earlier
    form of :func:`~tactbench.runner.execution.identity.row_keys`) is its cell's."""
    key = row.get("key")
    found, *earlier = row_keys(row)
    if key == found or key in earlier:
        return None
    return (f"is keyed {str(key)[:40]!r}, and the identity it holds is cell {found}'s "
            f"(copied under another name, or edited and re-sealed)")


#: The cell's place in the grid: the axes along which one grid's cells differ.
GRID_AXES = ("encoder", "classifier", "L", "seed", "init_seed")


def _scope(field: str, row: Mapping[str, Any]) -> Any:
    """Among which rows ``field`` must have one value in one grid: all of them (None),
    or those of one encoder, one classifier, one imaging kind, or one run (a run that
    draws its own data set)."""
    if field == "encoder_version":
        return row.get("encoder")
    if field == "input":
        return row.get("classifier")
    if field == "imaging":
        return str((row.get("imaging") or {}).get("kind") if isinstance(
            row.get("imaging"), dict) else row.get("imaging"))
    if field in ("dataset_hash", "run_dataset") and row.get(INDEPENDENT_RUNS):
        return row.get("seed")
    return None


def mixed_grids(rows: list[Mapping[str, Any]]) -> str | None:
    """How the stored ``rows`` of one folder hold cells of more than one grid (two
    identities that no run plans together: another pixel size, split, profile, thread
    count, data set ...), said as the first field found with two values; None when
    they are one grid. Every run of a folder plans every cell already there
    (:meth:`~tactbench.runner.execution.results.ResultStore.claim`), so only cells copied in
    from elsewhere mix grids; a report would merge them."""
    fields = [f for f in IDENTITY_FIELDS + COMPUTE_FIELDS if f not in GRID_AXES]
    seen: dict[tuple[str, str], tuple[Any, Mapping[str, Any]]] = {}
    for row in rows:
        identity = row_identity(row)
        for field in fields:
            value = identity.get(field, IDENTITY_DEFAULTS.get(field))
            scope = (field, json.dumps(_scope(field, row), sort_keys=True, default=str))
            first = seen.setdefault(scope, (value, row))
            if first[0] != value:
                return (f"{_row_label(first[1])} has {field} {first[0]!r}, "
                        f"{_row_label(row)} {value!r}")
    return None


def grid_identity(row: Mapping[str, Any]) -> dict[str, Any]:
    """What every cell of the grid of ``row`` shares, read from that one row: its identity
    fields that are no grid axis (:data:`GRID_AXES`) and take one value across a whole
    grid (:func:`mixed_grids`; not those of one encoder, classifier, imaging kind or run),
    each at its default where the row leaves it out. Two grids that one folder held one
    after the other (its cells removed between them) differ in it unless they differ only
    in an encoder's version, an input or the imaging."""
    identity = row_identity(row)
    return {f: identity.get(f, IDENTITY_DEFAULTS.get(f)) for f in IDENTITY_FIELDS
            + COMPUTE_FIELDS if f not in GRID_AXES and _scope(f, row) is None}


def _row_label(row: Mapping[str, Any]) -> str:
    return (f"{row.get('encoder')} × {str(row.get('classifier')).split(':')[0]} "
            f"L={row.get('L')} seed={row.get('seed')}")


def plan(scene: Scene, registry=None, *, progress=None,
         run_dataset: str | None = None, compute: Compute | None = None) -> Plan:
    """Check the whole grid before any work: names, options, L, layout needs, split.

    ``registry`` (default: every installed plugin) is the one the cells will use too.
    ``progress(done, total)`` hears from a dataset that takes a while to make (the
    simulator's first run).
    Raises a :class:`~tactbench.errors.TactbenchError` naming the problem; nothing is
    computed or written. ``run_dataset``: the data set of the scene's one run where each
    run draws its own (see :func:`plan_runs`), loaded in place of ``scene.dataset``.
    ``compute``: the run's resolved computation (its record's); None: resolved here
    (:func:`~tactbench.runner.execution.record.resolve_compute`), the kernels pinned.
    """
    registry = registry or load_registry()
    compute = compute or resolve_compute(scene)  # in every cell's identity
    check_environment()  # what cells read later, before anything is written
    # The scene checked itself when it was made; here what needs the plugins and the disk.
    check_output_folder(scene.out, option="out folder", ours=run_folder_entries(scene.out))
    _check_statistics(scene)
    # Names and options first (cheap), so a typo fails before a dataset is loaded.
    split, window, *designs = _build_designs(scene, registry)
    encoders, versions = _build_encoders(scene, registry)
    frame_ranks, batch_sizes = _build_classifiers(scene, registry)
    classifier_specs = list(frame_ranks)

    dataset = load_dataset(run_dataset or scene.dataset, registry=registry,
                           progress=progress)
    check_informative(dataset)  # all-NaN or constant: nothing to score
    has_layout = dataset.layout is not None
    if scene.input == "images" and not has_layout:
        raise InputError(f"--input images: dataset '{dataset.name}' has no taxel layout to "
                         f"make images; use --input vectors, or give the dataset a layout")
    kinds = {clf: (scene.input if scene.input and rank is None else input_kind(rank, has_layout))
             for clf, rank in frame_ranks.items()}
    for clf in classifier_specs:
        for enc in encoders:
            _check_inputs(clf, enc, kinds[clf], frame_ranks[clf], dataset,
                          vectors_ok=ENCODER.get(encoders[enc], "encode_vectors") is not None)
    _check_lengths(scene, dataset)
    batch_bytes = _check_memory(scene, dataset, encoders, kinds, batch_sizes)
    dataset_hash = dataset.content_hash()
    _check_split(scene, split, dataset)

    cells: list[Cell] = []
    identities: dict[str, dict[str, Any]] = {}
    for enc in encoders:
        for clf in classifier_specs:
            for length in scene.L:
                for seed, init in ((s, i) for s in dict.fromkeys(scene.seeds)
                                   for i in dict.fromkeys(scene.init_seeds or [None])):
                    identity = cell_identity(scene, dataset, dataset_hash, kinds[clf], enc,
                                             versions[enc], clf, length, seed, init,
                                             split=designs[0], test_window=designs[1],
                                             compute=compute.identity(),
                                             either_input=frame_ranks[clf] is None,
                                             run_dataset=run_dataset)
                    key = digest(identity)
                    cells.append(Cell(enc, clf, int(length), int(seed), key,
                                      None if init is None else int(init)))
                    identities[key] = identity
    named = [*(scene.contrasts or ()), *scene.design.primary]
    if named:
        check_contrasts(named, [{"encoder": c.encoder, "classifier": c.classifier,
                                 "L": c.L} for c in cells])
    return Plan(scene, dataset, dataset_hash, encoders, versions, classifier_specs,
                kinds, cells, identities, registry, split, window, run_dataset,
                batch_bytes=batch_bytes, compute=compute)


def run_datasets(scene: Scene, registry) -> dict[int, str] | None:
    """``seed → the spec of that run's data set`` when ``scene.dataset`` draws a new data
    set for every run (its ``run_spec``, :data:`tactbench.contracts.DATASET`); None when
    every run re-splits one data set (a path, or a dataset without ``run_spec``)."""
    text = str(scene.dataset)
    name = text.split(":", 1)[0].strip()
    if is_path_spec(text) or name not in registry.names("dataset"):
        return None
    factory = registry.get("dataset", name).load()
    if isinstance(factory, type) and DATASET.get(factory, "run_spec") is None:
        return None  # a class without run_spec: nothing built here
    run_spec = DATASET.get(registry.build("dataset", text), "run_spec")
    if run_spec is None:
        return None
    specs = {int(s): run_spec(int(s)) for s in dict.fromkeys(scene.seeds)}
    return None if all(v is None for v in specs.values()) else specs


def plan_runs(scene: Scene, registry=None, *, progress=None,
              first_only: bool = False, compute: Compute | None = None) -> list[Plan]:
    """The plans of ``scene``: one (:func:`plan`) when its runs share one data set; one per
    seed when every run draws its own (:func:`run_datasets`), each with that seed alone
    and that run's data set, so each is loaded, encoded and cached on its own. Cells of
    the plans differ by seed; their rows keep the scene's dataset name (runs pair across
    seeds) and record the run's data set (``run_dataset``, ``dataset_hash``).

    ``first_only``: of runs that draw their own data sets, plan the first seed's alone,
    its data set kept (one data set made, not one per seed: ``tactbench plan``, which
    derives the other runs' cells from it, :func:`other_run_identity`). ``compute``: the
    run's resolved computation, one for every plan (None: resolved once here)."""
    registry = registry or load_registry()
    compute = compute or resolve_compute(scene)
    specs = run_datasets(scene, registry)
    if specs is None:
        return [plan(scene, registry, progress=progress, compute=compute)]
    if first_only:
        seed, spec = next(iter(specs.items()))
        return [plan(dataclasses.replace(scene, seeds=[seed]), registry, progress=progress,
                     run_dataset=spec, compute=compute)]
    # each run's data set is let go once planned (a run's may be hundreds of MB): the
    # step that needs it loads it again from the simulator's cache (with_dataset)
    plans = []
    for seed, spec in specs.items():
        p = plan(dataclasses.replace(scene, seeds=[seed]), registry, progress=progress,
                 run_dataset=spec, compute=compute)
        plans.append(dataclasses.replace(p, dataset=None,
                                         sizes=DatasetSizes.of(p.dataset, p.scene)))
    return plans


def other_run_identity(identity: dict[str, Any], seed: int, run_dataset: str,
                       dataset_hash: str) -> dict[str, Any]:
    """The identity of a cell of one run (``identity``, made by :func:`plan` with its
    ``run_dataset``) in run ``seed`` instead, on that run's data set ``run_dataset`` of
    content hash ``dataset_hash``: what :func:`plan` gives that run, without loading its
    data set when the hash is known otherwise (a stored row's)."""
    return {**identity, "seed": int(seed), "run_dataset": run_dataset,
            "dataset_hash": dataset_hash}


def with_dataset(p: Plan, *, progress=None) -> Plan:
    """``p`` with its data set loaded: ``p`` itself when it holds it, else a copy holding
    the run's data set (``p.run_dataset``), checked to be the one planned."""
    if p.dataset is not None:
        return p
    dataset = load_dataset(p.run_dataset, registry=p.registry, progress=progress)
    if dataset.content_hash() != p.dataset_hash:
        raise InputError(f"dataset {p.run_dataset} changed since it was planned (content "
                         f"hash {dataset.content_hash()[:16]}, planned {p.dataset_hash[:16]})")
    return dataclasses.replace(p, dataset=dataset)
