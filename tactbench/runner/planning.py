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
import tempfile
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

from tactbench.contracts import CLASSIFIER, ENCODER
from tactbench.data.imaging import image_shape, imager_build_bytes
from tactbench.data.splits import canonical_split, dataset_groups, make_splits, parse_split
from tactbench.data.windows import TEST_WINDOWS
from tactbench.datasets.loading import check_informative, load_dataset
from tactbench.encoders.encoding import CHUNK_BYTES
from tactbench.errors import (
    BudgetError,
    InputError,
    check_choice,
    check_positive_float,
    check_positive_int,
)
from tactbench.paths import check_not_in_cache
from tactbench.plugins import load_registry
from tactbench.profiles import PRECISIONS, get_profile, profile_options
from tactbench.budget import check_budget
from tactbench.runner.summaries import check_contrasts, parse_contrast, short_name
from tactbench.specs import format_spec, parse_spec
from tactbench.runner.scene import EXECUTORS, Scene, check_fields
from tactbench.runner.system import check_scheduler
from tactbench.runner.results import ROW_MAX_BYTES
from tactbench.runner.writers import OUT_FILES  # the out folder's files, listed there

#: At most this many cells in one run (encoders × classifiers × L × seeds): each trains a
#: model, and a larger grid is a typo (its plan alone would grow without bound).
MAX_CELLS = 10_000

#: What tactbench writes at the top of an out folder (see :func:`check_out_folder`).
OUT_FOLDERS = ("cells", "models")
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
    L: int  # the window length, frames
    seed: int
    key: str
    init_seed: int | None = None  # the initialisation's seed when varied apart from the split's

    def label(self, labels: Mapping[str, str] | None = None) -> str:
        """A short human name: ``raw × small-cnn-lstm L=5 seed=0``; the classifier by its
        label in ``labels`` (:func:`tactbench.runner.summaries.spec_labels`) where that
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

    def classifier_component(self, spec: str):
        """The registered :class:`~tactbench.plugins.Component` of a classifier spec."""
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

    check_not_in_cache(out)  # 'cache clear' would delete the results
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
            elif report.is_symlink() or report.exists():  # a FIFO, a device: not ours
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


def check_scene(scene: Scene) -> None:
    """Check ``scene`` before any work: every field's type first
    (:func:`~tactbench.runner.scene.check_fields`), then each value's range and what the
    values need together (a profile, split and test window that exist, one model per
    cell when models are saved, a grid of at most :data:`MAX_CELLS`, a usable out
    folder). Raises :class:`InputError` naming the field or option."""
    check_fields({f.name: getattr(scene, f.name) for f in fields(Scene)}, ranges=False)
    get_profile(scene.profile)
    check_choice(scene.resolved_precision(), "precision", PRECISIONS)
    check_choice(scene.test_window, "test window", TEST_WINDOWS)
    if parse_split(scene.split)[1] is not None and scene.save_models:
        raise InputError(f"--save-models keeps one model per cell, and split "
                         f"{scene.split!r} trains one per fold; save models with "
                         f"--split users, group:KEY or paper")
    check_choice(scene.executor, "executor", EXECUTORS)
    if scene.scheduler:
        check_scheduler(scene.scheduler)
    if not scene.encoders or not scene.classifiers or not scene.L or not scene.seeds:
        raise InputError("a run needs at least one encoder, classifier, L and seed")
    bad_l = [n for n in scene.L if int(n) < 1]
    if bad_l:
        raise InputError(f"window length L must be ≥ 1, got {bad_l}")
    check_positive_int(scene.workers, "--workers")
    if scene.threads is not None:  # torch refuses 0 only inside the cell, after the work
        check_positive_int(scene.threads, "--threads")
    check_positive_float(scene.resolved_pixel_mm(), "pixel size (mm)")
    n_cells = (len(set(scene.encoders)) * len(set(scene.classifiers))
               * len(set(scene.L)) * len(set(scene.seeds))
               * len(set(scene.init_seeds or [None])))
    if n_cells > MAX_CELLS:
        raise InputError(f"the grid has {n_cells} cells (encoders × classifiers × L × "
                         f"seeds); a run takes at most {MAX_CELLS}")
    check_out_folder(scene.out, models=scene.save_models)
    _check_statistics(scene)


#: What ``--input`` may ask a classifier that takes either input for.
INPUT_KINDS = ("images", "vectors")


def _check_statistics(scene: Scene) -> None:
    """The margin, contrasts' syntax and input kind of a scene (see docs/statistics.md)."""
    if scene.margin is not None:
        check_positive_float(scene.margin, "--margin (points)")
    for text in scene.contrasts or ():
        parse_contrast(text)
    if scene.input is not None:
        check_choice(scene.input, "--input", INPUT_KINDS)


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
                  batch_sizes: dict[str, int]) -> None:
    """Estimate the large steps' memory from the inputs and refuse, before any work, one
    above the budget (:func:`tactbench.budget.check_budget`): building the imaging
    operator, a chunk of images and its encodings (two in flight), and a batch of windows
    of the longest L. The same estimates guard the allocations themselves
    (:class:`~tactbench.data.imaging.Imager`, :meth:`~tactbench.data.windows.Windows.batch`).
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
    for clf, kind in kinds.items():
        for enc in encoders:
            shape = (channels[enc], *frame_shape["images"]) if kind == "images" \
                else frame_shape["vectors"]
            per_frame = 4 * math.prod(shape)
            batch = batch_sizes[clf]
            check_budget(batch * length * per_frame,
                         f"a batch of {batch} windows of L={length} frames {shape} "
                         f"({enc} × {clf.split(':')[0]})")


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
    for spec in dict.fromkeys(scene.classifiers):
        spec = registry.resolve("classifier", spec)  # "sklearn:SVC" → estimator=SVC
        name, _ = parse_spec(spec)
        canonical, _ = _canonical(spec, profile_options(scene.profile, name,
                                                        registry=registry))
        clf = registry.build("classifier", canonical)  # validates option names and values
        frame_ranks.setdefault(canonical, CLASSIFIER.get(clf, "frame_rank"))
        batch_sizes[canonical] = CLASSIFIER.get(clf, "batch_size")
        preflight = CLASSIFIER.get(clf, "preflight")
        if preflight is not None:  # a device this machine lacks would fail every cell
            preflight(scene.device if scene.executor == "local" else "cpu")
    return frame_ranks, batch_sizes


def cell_identity(scene: Scene, dataset, dataset_hash: str, kind: str, encoder: str,
                  encoder_version: str, classifier: str, L: int,
                  seed: int, init_seed: int | None = None, *,
                  either_input: bool = False) -> dict[str, Any]:
    """Everything that decides a cell's result; its :func:`digest` is the cell's key.

    ``init_seed`` (``--init-seed``) and the input kind of a classifier taking either
    (``either_input``, when ``--input`` is given) enter only where asked for, so every
    other cell keeps its key."""
    return {
        "schema": ROW_SCHEMA,
        "dataset": dataset.name,
        "dataset_hash": dataset_hash,
        "split": canonical_split(scene.split),
        # the study's test window keeps the keys cells always had
        **({} if scene.test_window == "first" else {"test_window": scene.test_window}),
        "test_per_class": scene.test_per_class,
        "imaging": imaging_identity(scene, kind),
        "encoder": encoder,
        "encoder_version": encoder_version,
        **storage_identity(scene.resolved_precision()),
        "classifier": classifier,
        "profile": scene.profile,
        "L": int(L),
        "seed": int(seed),
        **({} if init_seed is None else {"init_seed": int(init_seed)}),
        **({"input": kind} if scene.input and either_input else {}),
    }


def plan(scene: Scene, registry=None, *, progress=None) -> Plan:
    """Check the whole grid before any work: names, options, L, layout needs, split.

    ``registry`` (default: every installed plugin) is the one the cells will use too.
    ``progress(done, total)`` hears from a dataset that takes a while to make (the
    simulator's first run).
    Raises a :class:`~tactbench.errors.TactbenchError` naming the problem; nothing is
    computed or written.
    """
    registry = registry or load_registry()
    check_scene(scene)
    # Names and options first (cheap), so a typo fails before a dataset is loaded.
    encoders, versions = _build_encoders(scene, registry)
    frame_ranks, batch_sizes = _build_classifiers(scene, registry)
    classifier_specs = list(frame_ranks)

    dataset = load_dataset(scene.dataset, registry=registry, progress=progress)
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
    _check_memory(scene, dataset, encoders, kinds, batch_sizes)
    dataset_hash = dataset.content_hash()
    make_splits(scene.split, labels=dataset.labels, users=dataset.users, seed=scene.seeds[0],
                test_per_class=scene.test_per_class,
                groups=dataset_groups(dataset))  # fails early on an impossible split

    cells: list[Cell] = []
    identities: dict[str, dict[str, Any]] = {}
    for enc in encoders:
        for clf in classifier_specs:
            for length in scene.L:
                for seed, init in ((s, i) for s in dict.fromkeys(scene.seeds)
                                   for i in dict.fromkeys(scene.init_seeds or [None])):
                    identity = cell_identity(scene, dataset, dataset_hash, kinds[clf], enc,
                                             versions[enc], clf, length, seed, init,
                                             either_input=frame_ranks[clf] is None)
                    key = digest(identity)
                    cells.append(Cell(enc, clf, int(length), int(seed), key,
                                      None if init is None else int(init)))
                    identities[key] = identity
    if scene.contrasts:
        check_contrasts(scene.contrasts, [{"encoder": c.encoder, "classifier": c.classifier,
                                           "L": c.L} for c in cells])
    return Plan(scene, dataset, dataset_hash, encoders, versions, classifier_specs,
                kinds, cells, identities, registry)
