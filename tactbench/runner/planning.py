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
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tactbench.errors import (
    InputError,
    check_choice,
    check_positive_float,
    check_positive_int,
)
from tactbench.runner.scene import EXECUTORS, Scene, check_scene

#: At most this many cells in one run (encoders × classifiers × L × seeds): each trains a
#: model, and a larger grid is a typo (its plan alone would grow without bound).
MAX_CELLS = 10_000

#: What tactbench writes at the top of an out folder (see :func:`check_out_folder`).
OUT_FOLDERS = ("cells", "models")
OUT_FILES = ("results.json", "results.csv", "report.md", "accuracy_vs_L.png",
             "cost_vs_accuracy.png", "per_class_vs_L.png")
_OUT_PATTERNS = (re.compile(r"confusion_.+\.png"),)
#: What file managers leave in any folder they show (tactbench neither reads nor writes it).
OUT_LITTER = (".DS_Store", "Thumbs.db", "desktop.ini")
_TEMPORARY = re.compile(r"^\.(.+)\.(?:tmp|bad)-")  # tactbench.paths.temp_name
#: report.md begins with this line; a report.md without it is not tactbench's.
REPORT_HEADER = "# tactbench report"

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


def _is_ours(name: str) -> bool:
    """Whether ``name`` at the top of an out folder is one tactbench writes (temporary
    files of an interrupted write included: ``.NAME.tmp-...``, ``.NAME.bad-...``)."""
    temporary = _TEMPORARY.match(name)
    if temporary:
        name = temporary.group(1)
    return (name in OUT_FOLDERS or name in OUT_FILES or name in OUT_LITTER
            or any(p.fullmatch(name) for p in _OUT_PATTERNS))


def _probe_writable(folder: Path, out: Path) -> None:
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(prefix=".tactbench-probe-", dir=folder)
    except OSError as exc:
        where = "" if folder == out else f" ({folder})"
        raise InputError(f"out folder {out} cannot be written{where}: "
                         f"{exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)


def check_out_folder(out: str | Path, *, models: bool = False) -> None:
    """Refuse an out folder the run could not write, before any work.

    ``out`` must be a folder (or not exist yet, under a folder), writable (a probe file
    is created and removed: permissions alone do not tell, e.g. for root or a read-only
    mount), and, when it exists, *tactbench's*: empty, or holding only what a run writes
    (:data:`OUT_FOLDERS`, :data:`OUT_FILES`, ``confusion_*.png``, temporary
    ``.NAME.tmp-*`` / ``.NAME.bad-*`` names of those; and :data:`OUT_LITTER`), with a
    ``report.md`` that starts with :data:`REPORT_HEADER`. A folder with anything else is
    refused, never overwritten.
    """
    out = Path(out)
    try:
        if out.exists():
            if not out.is_dir():
                raise InputError(f"out folder {out} is a file, not a folder; give a folder")
            foreign = []
            with os.scandir(out) as entries:
                for entry in entries:
                    if not _is_ours(entry.name):
                        foreign.append(entry.name)
                        if len(foreign) == 3:
                            break
                    elif entry.name in OUT_FOLDERS and not entry.is_dir():
                        foreign.append(entry.name)
            report = out / "report.md"
            if report.is_file():
                with open(report, "rb") as fh:
                    if not fh.read(len(REPORT_HEADER)).startswith(REPORT_HEADER.encode()):
                        foreign.append("report.md")
            if foreign:
                names = ", ".join(repr(n) for n in foreign[:3])
                raise InputError(f"out folder {out} holds files tactbench did not write "
                                 f"({names}); give a new or empty folder, or one an earlier "
                                 f"run wrote")
            _probe_writable(out, out)
            for sub in ("cells", "models") if models else ("cells",):
                if (out / sub).is_dir():
                    _probe_writable(out / sub, out)
            return
        parent = out.absolute().parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise InputError(f"out folder {out} cannot be made: {parent} is a file, not a "
                             f"folder")
        _probe_writable(parent, out)
    except ValueError as exc:  # InputError is one too
        if isinstance(exc, InputError):
            raise
        raise InputError(f"out folder {out!r} is not a usable path: {exc}") from None
    except OSError as exc:  # a name too long, a loop of links, no permission to look
        raise InputError(f"out folder {out} cannot be used: {exc.strerror or exc}") from None


def _check_scene(scene: Scene) -> None:
    from tactbench.data.splits import parse_split
    from tactbench.profiles import PRECISIONS, get_profile

    check_scene(scene)  # every field's type, first
    get_profile(scene.profile)
    check_choice(scene.resolved_precision(), "precision", PRECISIONS)
    from tactbench.data.windows import TEST_WINDOWS

    check_choice(scene.test_window, "test window", TEST_WINDOWS)
    if parse_split(scene.split)[1] is not None and scene.save_models:
        raise InputError(f"--save-models keeps one model per cell, and split "
                         f"{scene.split!r} trains one per fold; save models with "
                         f"--split users, group:KEY or paper")
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
    n_cells = (len(set(scene.encoders)) * len(set(scene.classifiers))
               * len(set(scene.lengths)) * len(set(scene.seeds)))
    if n_cells > MAX_CELLS:
        raise InputError(f"the grid has {n_cells} cells (encoders × classifiers × L × "
                         f"seeds); a run takes at most {MAX_CELLS}")
    if scene.executor == "local" and scene.device.strip().lower() != "cpu":
        # a device this machine lacks would fail every cell, after the encoding
        from tactbench.classifiers.training import select_device

        select_device(scene.device)
    check_out_folder(scene.out, models=scene.save_models)


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
    too_long = sorted({int(n) for n in scene.lengths if int(n) > longest})
    if too_long:
        shown = ", ".join(map(str, too_long[:5])) + (", …" if len(too_long) > 5 else "")
        raise InputError(f"window length L = {shown} is longer than every sequence of "
                         f"dataset '{dataset.name}': the longest (sample "
                         f"{int(lengths.argmax())}) has {longest} frames; use L ≤ {longest}")


def _check_memory(scene: Scene, dataset, encoders: dict[str, Any], kinds: dict[str, str],
                  batch_sizes: dict[str, int]) -> None:
    """Estimate the large steps' memory from the inputs and refuse, before any work, one
    above the budget (:func:`tactbench.integrity.check_budget`): building the imaging
    operator, a chunk of images and its encodings (two in flight), and a batch of windows
    of the longest L. The same estimates guard the allocations themselves
    (:class:`~tactbench.data.imaging.Imager`, :meth:`~tactbench.data.windows.Windows.batch`).
    """
    from tactbench.contracts import ENCODER
    from tactbench.integrity import check_budget

    channels = {enc: len(tuple(ENCODER.get(obj, "channels"))) for enc, obj in encoders.items()}
    longest = int(dataset.lengths().max())
    length = max(int(n) for n in scene.lengths)
    frame_shape = {"vectors": (dataset.n_taxels,)}
    if "images" in kinds.values():
        from tactbench.data.imaging import image_shape, imager_build_bytes
        from tactbench.runner.cache import CHUNK_BYTES

        pixel_mm, method = scene.resolved_pixel_mm(), scene.imaging
        h, w = image_shape(dataset.layout, pixel_mm)
        frame_shape["images"] = (h, w)
        what = f"tactile images at {pixel_mm:g} mm ({h}×{w} px)"
        check_budget(imager_build_bytes(dataset.layout, pixel_mm, method),
                     f"the imaging operator for {what}")
        frames = max(CHUNK_BYTES // (4 * h * w), longest)  # a chunk holds ≥ 1 sample
        c = sum(channels.values())
        check_budget(2 * frames * 4 * h * w * (2 + c),
                     f"imaging and encoding {what}, chunks of {frames} frames into {c} "
                     f"channels")
    for clf, kind in kinds.items():
        for enc in encoders:
            shape = (channels[enc], *frame_shape["images"]) if kind == "images" \
                else frame_shape["vectors"]
            per_frame = 4 * math.prod(shape)
            batch = batch_sizes[clf]
            check_budget(batch * length * per_frame,
                         f"a batch of {batch} windows of L={length} frames {shape} "
                         f"({enc} × {clf.split(':')[0]})")


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
        canonical, _ = _canonical(registry.resolve("encoder", spec))
        if canonical in encoders:
            continue
        encoder = registry.build("encoder", canonical)
        encoders[canonical] = encoder
        versions[canonical] = str(ENCODER.get(encoder, "version"))
    frame_ranks: dict[str, int | None] = {}  # canonical classifier spec → frame rank
    batch_sizes: dict[str, int] = {}  # canonical classifier spec → windows per batch
    for spec in dict.fromkeys(scene.classifiers):
        spec = registry.resolve("classifier", spec)  # "sklearn:SVC" → estimator=SVC
        name, _ = parse_spec(spec)
        canonical, _ = _canonical(spec, profile_options(scene.profile, name,
                                                        registry=registry))
        clf = registry.build("classifier", canonical)  # validates option names and values
        frame_ranks.setdefault(canonical, CLASSIFIER.get(clf, "frame_rank"))
        size = getattr(clf, "batch_size", 1)
        batch_sizes[canonical] = size if isinstance(size, int) and size > 0 else 1
    classifier_specs = list(frame_ranks)

    from tactbench.datasets.loading import load_dataset

    dataset = load_dataset(scene.dataset, registry=registry, progress=progress)
    has_layout = dataset.layout is not None
    kinds = {clf: input_kind(rank, has_layout) for clf, rank in frame_ranks.items()}
    for clf in classifier_specs:
        for enc in encoders:
            _check_inputs(clf, enc, kinds[clf], frame_ranks[clf], dataset,
                          vectors_ok=ENCODER.get(encoders[enc], "encode_vectors") is not None)
    _check_lengths(scene, dataset)
    _check_memory(scene, dataset, encoders, kinds, batch_sizes)
    dataset_hash = dataset.content_hash()
    from tactbench.data.splits import canonical_split, dataset_groups, make_splits

    make_splits(scene.split, labels=dataset.labels, users=dataset.users, seed=scene.seeds[0],
                test_per_class=scene.test_per_class,
                groups=dataset_groups(dataset))  # fails early on an impossible split
    split_spec = canonical_split(scene.split)

    cells: list[Cell] = []
    identities: dict[str, dict[str, Any]] = {}
    storage = storage_identity(scene.resolved_precision())
    for enc in encoders:
        for clf in classifier_specs:
            for length in scene.lengths:
                for seed in dict.fromkeys(scene.seeds):  # a seed listed twice is one cell
                    identity = {
                        "schema": ROW_SCHEMA,
                        "dataset": dataset.name,
                        "dataset_hash": dataset_hash,
                        "split": split_spec,
                        # the study's test window keeps the keys cells always had
                        **({} if scene.test_window == "first"
                           else {"test_window": scene.test_window}),
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
