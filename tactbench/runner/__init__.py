"""The benchmark runner: a grid of cells, cached encodings, resumable results.

A *scene* names a dataset, encoders, classifiers, window lengths L, seeds, a split
and a profile. It expands into *cells*, one per (encoder, classifier, L, seed); each
cell trains one classifier and writes one result row.

Nothing is computed twice:

- encoded datasets are cached on disk (:class:`EncodingCache`), keyed by the
  dataset's content hash, the imaging parameters and the encoder's name, options and
  version, so each encoding is computed once across runs;
- each finished cell is written at once, atomically, to ``OUT/cells/<key>.json``
  (:class:`ResultStore`); running the same scene again skips finished cells, and a
  run killed mid-cell loses only that cell.

Cells run in turn (``executor="local"``), in worker processes (``workers > 1``), or on
a ``dask.distributed`` cluster (``executor="dask"``); a cell's result depends only on
its identity and seed, never on where it ran.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from tactbench.errors import InputError, MissingFileError
from tactbench.paths import atomic_write_text, cache_dir
from tactbench.ui import Progress

EXECUTORS = ("local", "dask")

#: Imaging and split settings of each profile; classifier options come from
#: :func:`tactbench.classifiers.training.profile_options`.
RUN_PROFILES: dict[str, dict[str, Any]] = {
    # 5 mm pixels: taxels are 7.5 mm apart, so little is lost, and flow is ~25× cheaper
    # than on the study's 1 mm grid.
    "quick": {"pixel_mm": 5.0},
    "paper": {"pixel_mm": 1.0},
}

SCENE_SCHEMA = 1
ROW_SCHEMA = 1


# ----------------------------------------------------------------------------- scene


@dataclass
class Scene:
    """Everything a run needs to know; a scene file holds the same fields (TOML)."""

    dataset: str = "synthetic-forearm"
    encoders: list[str] = field(default_factory=lambda: ["raw", "farneback"])
    classifiers: list[str] = field(default_factory=lambda: ["small-cnn-lstm"])
    lengths: list[int] = field(default_factory=lambda: [5])
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    split: str = "paper"
    test_per_class: int = 30
    profile: str = "quick"
    pixel_mm: float | None = None  # None: the profile's
    imaging: str = "linear"
    device: str = "cpu"
    threads: int | None = None  # torch threads per cell; None: cores / workers
    executor: str = "local"
    workers: int = 1
    scheduler: str | None = None
    out: str = "tactbench-out"
    rerun: bool = False
    save_models: bool = False  # OUT/models/<cell key>.safetensors, usable by `tactbench live`

    def resolved_pixel_mm(self) -> float:
        return float(self.pixel_mm if self.pixel_mm is not None
                     else RUN_PROFILES[self.profile]["pixel_mm"])

    def resolved_threads(self) -> int:
        if self.threads is not None:
            return int(self.threads)
        return max(1, (os.cpu_count() or 1) // max(1, self.workers))


def parse_lengths(values: Iterable[str | int]) -> list[int]:
    """``["5"]``, ``["1-6"]``, ``["2", "4-5"]`` → sorted unique window lengths."""
    out: set[int] = set()
    for value in values:
        text = str(value).strip()
        try:
            if "-" in text.lstrip("-"):
                lo, hi = text.split("-", 1)
                start, stop = int(lo), int(hi)
                if stop < start:
                    raise ValueError
                out.update(range(start, stop + 1))
            else:
                out.add(int(text))
        except ValueError:
            raise InputError(f"bad window length '{value}': use a number (5) or a range "
                             f"(1-6)") from None
    return sorted(out)


def load_scene_file(path: str | Path) -> dict[str, Any]:
    """Read a TOML scene file into a dict of :class:`Scene` fields (validated names)."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise MissingFileError(f"scene file not found: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    aliases = {"encoder": "encoders", "classifier": "classifiers", "L": "lengths",
               "seed": "seeds"}
    known = {f.name for f in fields(Scene)}
    scene: dict[str, Any] = {}
    for key, value in data.items():
        name = aliases.get(key, key)
        if name not in known:
            import difflib

            close = difflib.get_close_matches(name, sorted(known), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise InputError(f"{path}: unknown field '{key}'{hint}")
        if name in ("encoders", "classifiers", "seeds") and not isinstance(value, list):
            value = [value]
        if name == "lengths":
            value = parse_lengths(value if isinstance(value, list) else [value])
        scene[name] = value
    return scene


# ----------------------------------------------------------------------------- cells


@dataclass(frozen=True)
class Cell:
    """One point of the grid. ``key`` names its result file."""

    encoder: str  # canonical spec, options sorted
    classifier: str  # canonical spec including the profile's options
    length: int
    seed: int
    key: str


@dataclass(frozen=True)
class CellJob:
    """Everything a worker needs to run a cell, picklable and small."""

    cell: Cell
    identity: dict[str, Any]
    encoding_dir: str
    labels: tuple[int, ...]
    users: tuple[str, ...]
    classes: tuple[str, ...]
    split: str
    test_per_class: int
    device: str
    threads: int
    model_path: str | None = None
    model_meta: dict[str, Any] | None = None


@dataclass
class Plan:
    """A checked scene: the dataset loaded, components resolved, cells expanded."""

    scene: Scene
    dataset: Any
    dataset_hash: str
    encoders: dict[str, Any]  # canonical spec → encoder instance
    encoder_versions: dict[str, str]
    classifier_specs: list[str]  # canonical, profile options resolved
    input_kind: dict[str, str]  # classifier spec → "images" | "vectors"
    cells: list[Cell]
    identities: dict[str, dict[str, Any]]


def _canonical(spec: str, extra: dict[str, Any] | None = None) -> tuple[str, dict]:
    from tactbench.plugins import format_spec, parse_spec

    name, options = parse_spec(spec)
    merged = {**(extra or {}), **options}
    return format_spec(name, merged), merged


def _digest(obj: Any, n: int = 16) -> str:
    text = json.dumps(obj, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def plan(scene: Scene, registry=None) -> Plan:
    """Check the whole grid before any work: names, options, L, layout needs, split.

    Raises ``ValueError`` / :class:`~tactbench.errors.TactbenchError` naming the
    problem; nothing is computed or written.
    """
    from tactbench.classifiers.training import PROFILE_NAMES, profile_options
    from tactbench.data.splits import SPLITS
    from tactbench.plugins import load_registry, parse_spec

    registry = registry or load_registry()
    if scene.profile not in PROFILE_NAMES:
        raise InputError(f"unknown profile '{scene.profile}'; profiles: "
                         f"{', '.join(PROFILE_NAMES)}")
    if scene.split not in SPLITS:
        raise InputError(f"unknown split '{scene.split}'; splits: {', '.join(SPLITS)}")
    if scene.executor not in EXECUTORS:
        raise InputError(f"unknown executor '{scene.executor}'; executors: "
                         f"{', '.join(EXECUTORS)}")
    if not scene.encoders or not scene.classifiers or not scene.lengths or not scene.seeds:
        raise InputError("a run needs at least one encoder, classifier, L and seed")
    bad_l = [n for n in scene.lengths if int(n) < 1]
    if bad_l:
        raise InputError(f"window length L must be ≥ 1, got {bad_l}")
    if scene.workers < 1:
        raise InputError(f"--workers must be ≥ 1, got {scene.workers}")
    if scene.resolved_pixel_mm() <= 0:
        raise InputError(f"pixel size must be > 0 mm, got {scene.pixel_mm}")

    # Names and options first (cheap), so a typo fails before a dataset is loaded.
    encoders: dict[str, Any] = {}
    versions: dict[str, str] = {}
    for spec in dict.fromkeys(scene.encoders):
        canonical, options = _canonical(spec)
        if canonical in encoders:
            continue
        encoder = registry.build("encoder", canonical)
        encoders[canonical] = encoder
        versions[canonical] = str(getattr(encoder, "version", "1"))
    classifier_specs: list[str] = []
    input_kind: dict[str, str] = {}
    for spec in dict.fromkeys(scene.classifiers):
        name, _ = parse_spec(spec)
        canonical, options = _canonical(spec, profile_options(scene.profile, name))
        registry.build("classifier", canonical)  # validates option names and values
        cls = registry.get("classifier", name).load()
        kind = "vectors" if getattr(cls, "frame_rank", 3) == 1 else "images"
        if canonical not in classifier_specs:
            classifier_specs.append(canonical)
            input_kind[canonical] = kind

    from tactbench.datasets.loading import load_dataset

    dataset = load_dataset(scene.dataset, registry=registry)
    for clf in classifier_specs:
        for enc in encoders:
            if input_kind[clf] == "vectors" and parse_spec(enc)[0] != "raw":
                raise InputError(f"classifier '{clf}' takes taxel vectors, which only the "
                                 f"'raw' encoder passes through; got encoder '{enc}'")
            if input_kind[clf] == "images" and dataset.layout is None:
                raise InputError(f"encoder '{enc}' works on tactile images, and dataset "
                                 f"'{dataset.name}' has no taxel layout to make them; use "
                                 f"a taxel-vector classifier (e.g. taxel-lstm) with "
                                 f"--encoder raw, or give the dataset a layout")
    dataset_hash = dataset.content_hash()
    from tactbench.data.splits import make_split

    make_split(scene.split, labels=dataset.labels, users=dataset.users, seed=scene.seeds[0],
               test_per_class=scene.test_per_class)  # fails early on an impossible split

    cells: list[Cell] = []
    identities: dict[str, dict[str, Any]] = {}
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
                        "imaging": _imaging_identity(scene, input_kind[clf]),
                        "encoder": enc,
                        "encoder_version": versions[enc],
                        "classifier": clf,
                        "profile": scene.profile,
                        "L": int(length),
                        "seed": int(seed),
                    }
                    key = _digest(identity)
                    cells.append(Cell(enc, clf, int(length), int(seed), key))
                    identities[key] = identity
    return Plan(scene, dataset, dataset_hash, encoders, versions, classifier_specs,
                input_kind, cells, identities)


def _model_metadata(p: Plan, cell: Cell) -> dict[str, Any]:
    """What `tactbench live` needs to use a cell's model: classes, layout, imaging, encoder."""
    from tactbench.live import live_metadata

    return live_metadata(p.dataset, encoder=cell.encoder, length=cell.length,
                         pixel_mm=p.scene.resolved_pixel_mm(), method=p.scene.imaging)


def _imaging_identity(scene: Scene, kind: str) -> dict[str, Any]:
    if kind == "vectors":
        return {"kind": "vectors"}
    return {"kind": "images", "pixel_mm": scene.resolved_pixel_mm(), "method": scene.imaging}


# ----------------------------------------------------------------------------- caches


class EncodingCache:
    """Encoded datasets on disk: one folder per (dataset, imaging, encoder, version).

    A folder holds ``frames.npy`` (all frames stacked, float32 ``(ΣT, C, H, W)`` or
    ``(ΣT, N)``), ``offsets.npy`` (``(n + 1,)``: sample i is ``frames[o[i]:o[i+1]]``)
    and ``meta.json``. It is written to a temporary folder and renamed into place, so
    a folder that exists is complete.
    """

    def __init__(self, root: str | Path | None = None) -> None:
        self.root = Path(root) if root is not None else cache_dir("encodings")
        self.root.mkdir(parents=True, exist_ok=True)

    def key(self, dataset_hash: str, imaging: dict[str, Any], encoder: str,
            version: str) -> str:
        return _digest({"dataset": dataset_hash, "imaging": imaging, "encoder": encoder,
                        "version": version}, 24)

    def path(self, key: str) -> Path:
        return self.root / key

    def has(self, key: str) -> bool:
        return (self.path(key) / "meta.json").is_file()

    def write(self, key: str, sequences: Sequence[Any], meta: dict[str, Any]) -> Path:
        import numpy as np

        final = self.path(key)
        tmp = self.root / f".{key}.tmp-{os.getpid()}"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        lengths = [len(s) for s in sequences]
        offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        frames = np.lib.format.open_memmap(
            tmp / "frames.npy", mode="w+", dtype=np.float32,
            shape=(int(offsets[-1]), *sequences[0].shape[1:]))
        for seq, start in zip(sequences, offsets[:-1]):
            frames[start:start + len(seq)] = seq
        frames.flush()
        del frames
        np.save(tmp / "offsets.npy", offsets)
        (tmp / "meta.json").write_text(json.dumps({**meta, "created": _now()}, indent=2))
        if final.exists():  # another process finished first: keep theirs
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            os.replace(tmp, final)
        return final

    def entries(self) -> list[dict[str, Any]]:
        out = []
        for meta_path in sorted(self.root.glob("*/meta.json")):
            meta = json.loads(meta_path.read_text())
            size = sum(f.stat().st_size for f in meta_path.parent.iterdir())
            out.append({"key": meta_path.parent.name, "bytes": size, **meta})
        return out

    def clear(self) -> int:
        n = 0
        for child in self.root.iterdir():
            if child.is_dir():
                shutil.rmtree(child)
                n += 1
        return n


_LOADED: dict[str, tuple[list[Any], dict[str, Any]]] = {}


def load_encoding(folder: str | Path) -> tuple[list[Any], dict[str, Any]]:
    """The cached sequences (memory-mapped views) and metadata; memoised per process."""
    import numpy as np

    folder = str(folder)
    if folder not in _LOADED:
        frames = np.load(Path(folder) / "frames.npy", mmap_mode="c")  # copy-on-write: writable views, file untouched
        offsets = np.load(Path(folder) / "offsets.npy")
        meta = json.loads((Path(folder) / "meta.json").read_text())
        seqs = [frames[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
        _LOADED[folder] = (seqs, meta)
    return _LOADED[folder]


class ResultStore:
    """One JSON file per finished cell under ``OUT/cells``, written atomically."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.cells = self.out / "cells"

    def _path(self, key: str) -> Path:
        return self.cells / f"{key}.json"

    def get(self, key: str) -> dict[str, Any] | None:
        path = self._path(key)
        try:
            return json.loads(path.read_text())
        except FileNotFoundError:
            return None
        except (json.JSONDecodeError, UnicodeDecodeError):
            return None  # cannot happen with atomic writes; recompute if it does

    def put(self, row: dict[str, Any]) -> None:
        atomic_write_text(self._path(row["key"]), json.dumps(row, indent=2))

    def rows(self, keys: Iterable[str]) -> list[dict[str, Any]]:
        return [row for key in keys if (row := self.get(key)) is not None]


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


# ----------------------------------------------------------------------------- encoding


def ensure_encodings(plan_: Plan, cache: EncodingCache, pending: Sequence[Cell],
                     progress: "Progress | None" = None) -> dict[tuple[str, str], str]:
    """Make sure every (encoder, input kind) the pending cells need is cached.

    Returns ``(encoder spec, input kind) → cache folder`` for every pair the *plan*
    uses; images are made from the dataset once, and only if some encoding is missing.
    """
    scene = plan_.scene
    needed = {(c.encoder, plan_.input_kind[c.classifier]) for c in plan_.cells}
    pending_pairs = {(c.encoder, plan_.input_kind[c.classifier]) for c in pending}
    folders: dict[tuple[str, str], str] = {}
    images = vectors = None
    for enc, kind in sorted(needed):
        imaging = _imaging_identity(scene, kind)
        key = cache.key(plan_.dataset_hash, imaging, enc, plan_.encoder_versions[enc])
        folders[(enc, kind)] = str(cache.path(key))
        if cache.has(key) or (enc, kind) not in pending_pairs:
            continue
        if kind == "vectors":
            if vectors is None:
                vectors = plan_.dataset.vectors()
            # The taxel-vector path has no image encoder: raw passes vectors through.
            cache.write(key, vectors, {"encoder": enc, "imaging": imaging,
                                       "dataset_hash": plan_.dataset_hash,
                                       "encode_seconds": 0.0, "workers": 1,
                                       "frames": int(sum(len(v) for v in vectors))})
            continue
        if images is None:
            task = progress.add(f"tactile images at {scene.resolved_pixel_mm():g} mm",
                                total=1) if progress else None
            t0 = time.perf_counter()
            images = plan_.dataset.images(pixel_mm=scene.resolved_pixel_mm(),
                                          method=scene.imaging)
            image_s = time.perf_counter() - t0
            if progress:
                progress.update(task, 1)
        from tactbench.encoders.parallel import encode_all

        workers = max(1, os.cpu_count() or 1)
        task = progress.add(f"encode {enc}", total=len(images)) if progress else None
        t0 = time.perf_counter()
        encoded = encode_all(plan_.encoders[enc], images, workers=workers,
                             progress=(lambda done, total: progress.update(task, done))
                             if progress else None)
        seconds = time.perf_counter() - t0
        n_frames = int(sum(len(s) for s in images))
        cache.write(key, encoded, {
            "encoder": enc, "encoder_version": plan_.encoder_versions[enc],
            "channels": list(getattr(plan_.encoders[enc], "channels", ())),
            "imaging": imaging, "imaging_seconds": image_s,
            "dataset": plan_.dataset.name, "dataset_hash": plan_.dataset_hash,
            "encode_seconds": seconds, "workers": workers, "frames": n_frames,
            "frame_shape": list(encoded[0].shape[1:]),
        })
        del encoded
    return folders


# ----------------------------------------------------------------------------- cells


def run_cell(job: CellJob, progress: Callable[..., None] | None = None) -> dict[str, Any]:
    """Train and test one cell; returns its result row. Runs in any process."""
    import numpy as np
    import torch

    from tactbench.classifiers.training import derive_seed
    from tactbench.data.splits import make_split
    from tactbench.data.windows import test_windows, training_windows
    from tactbench.plugins import load_registry

    torch.set_num_threads(job.threads)
    cell = job.cell
    sequences, meta = load_encoding(job.encoding_dir)
    labels = np.asarray(job.labels, dtype=np.int64)
    split = make_split(job.split, labels=labels, users=job.users, seed=cell.seed,
                       test_per_class=job.test_per_class)
    train = training_windows([sequences[i] for i in split.train], labels[split.train],
                             cell.length)
    test = test_windows([sequences[i] for i in split.test], labels[split.test], cell.length)

    clf = load_registry().build("classifier", cell.classifier, classes=len(job.classes))
    seed = derive_seed(cell.seed, cell.encoder, cell.classifier, cell.length)
    rss0 = _peak_rss_mb()
    t0 = time.perf_counter()
    fit_report = clf.fit(train, None, seed=seed, device=job.device, progress=progress)
    train_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    predicted = clf.predict(test)
    infer_s = time.perf_counter() - t0
    if job.model_path:
        clf.save(job.model_path, {**(job.model_meta or {}), "classifier": cell.classifier,
                                  "seed": cell.seed, "cell": cell.key,
                                  "test_accuracy": float((predicted == test.labels).mean())})

    k = len(job.classes)
    truth = test.labels
    confusion = np.zeros((k, k), dtype=np.int64)
    np.add.at(confusion, (truth, predicted), 1)
    support = confusion.sum(axis=1)
    per_class = {job.classes[i]: (float(confusion[i, i] / support[i]) if support[i] else None)
                 for i in range(k)}
    frames = max(1, int(meta.get("frames", 1)))
    return {
        "key": cell.key,
        **job.identity,
        **split.describe(),
        "classes": list(job.classes),
        "accuracy": float((predicted == truth).mean()),
        "per_class_accuracy": per_class,
        "confusion": confusion.tolist(),
        # cost on one core: wall time × workers that shared the encoding, per frame
        "encode_ms_per_frame": 1e3 * float(meta.get("encode_seconds", 0.0))
        * int(meta.get("workers", 1)) / frames,
        "train_s": train_s,
        "inference_ms_per_sequence": 1e3 * infer_s / max(1, len(test)),
        "peak_rss_mb": _peak_rss_mb(),
        "rss_before_fit_mb": rss0,
        "n_train_windows": len(train),
        "n_test": len(test),
        "fit": _jsonable(fit_report),
        "device": job.device,
        "threads": job.threads,
        "versions": _versions(),
        "host": os.uname().nodename if hasattr(os, "uname") else "",
        "finished": _now(),
    }


def _peak_rss_mb() -> float:
    try:
        import resource

        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return rss / 1024.0 if sys.platform != "darwin" else rss / 2 ** 20
    except ImportError:  # Windows
        return float("nan")


def _jsonable(obj: Any) -> Any:
    return json.loads(json.dumps(obj, default=str))


def _versions() -> dict[str, str]:
    import numpy

    import tactbench

    out = {"tactbench": tactbench.__version__, "python": sys.version.split()[0],
           "numpy": numpy.__version__}
    for name in ("torch", "cv2", "kornia"):
        module = sys.modules.get(name)
        if module is not None:
            out[name] = getattr(module, "__version__", "?")
    return out


def git_revision() -> str | None:
    """The checkout's commit (with ``+dirty``), when tactbench runs from one."""
    import subprocess

    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return None
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"],
                             capture_output=True, text=True, timeout=5).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain",
                                "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return (rev + ("+dirty" if dirty else "")) or None


# ----------------------------------------------------------------------------- run


@dataclass
class RunResult:
    plan: Plan
    rows: list[dict[str, Any]]
    computed: int
    skipped: int
    seconds: float
    encode_cached: bool


def run(scene: Scene, *, registry=None, progress: bool = True,
        cache: EncodingCache | None = None,
        on_row: Callable[[dict[str, Any]], None] | None = None) -> RunResult:
    """Run ``scene``: plan, encode what is missing, run unfinished cells, collect rows."""
    start = time.perf_counter()
    with Progress(enabled=progress) as bars:
        task = bars.add(f"check grid, load dataset {scene.dataset}", total=1)
        p = plan(scene, registry)
        bars.update(task, 1)
        store = ResultStore(scene.out)
        models = Path(scene.out) / "models"
        pending = [c for c in p.cells if scene.rerun or store.get(c.key) is None
                   or (scene.save_models and not (models / f"{c.key}.safetensors").exists())]
        cache = cache or EncodingCache()
        folders = ensure_encodings(p, cache, pending, bars)
        labels = tuple(int(x) for x in p.dataset.labels)  # once, shared by every job
        users = tuple(str(u) for u in p.dataset.users)
        jobs = [CellJob(cell=c, identity=p.identities[c.key],
                        encoding_dir=folders[(c.encoder, p.input_kind[c.classifier])],
                        labels=labels, users=users,
                        classes=tuple(p.dataset.classes), split=scene.split,
                        test_per_class=scene.test_per_class, device=scene.device,
                        threads=scene.resolved_threads(),
                        model_path=str(models / f"{c.key}.safetensors")
                        if scene.save_models else None,
                        model_meta=_model_metadata(p, c) if scene.save_models else None)
                    for c in pending]
        run_meta = {"command": " ".join(sys.argv), "git": git_revision(),
                    "scene": asdict(scene)}

        def finish(row: dict[str, Any]) -> None:
            row["run"] = run_meta
            store.put(row)
            if on_row is not None:
                on_row(row)

        if jobs:
            _execute(scene, jobs, finish, bars)
    rows = store.rows(c.key for c in p.cells)
    return RunResult(p, rows, computed=len(pending), skipped=len(p.cells) - len(pending),
                     seconds=time.perf_counter() - start, encode_cached=not pending)


def _execute(scene: Scene, jobs: list[CellJob], finish: Callable[[dict], None],
             bars: Progress) -> None:
    overall = bars.add("cells", total=len(jobs))
    done = 0
    if scene.executor == "local" and scene.workers == 1:
        for job in jobs:
            task = bars.add(f"train {_cell_label(job.cell)}", total=None)

            def report(completed: int, total: int, task=task, **info: Any) -> None:
                text = " ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                                for k, v in info.items())
                bars.update(task, completed, total, text)

            finish(run_cell(job, report if bars.enabled else None))
            done += 1
            bars.update(overall, done)
        return
    if scene.executor == "local":
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = multiprocessing.get_context("spawn")  # torch and fork do not mix
        with ProcessPoolExecutor(max_workers=scene.workers, mp_context=ctx) as pool:
            futures = {pool.submit(run_cell, job): job for job in jobs}
            for fut in as_completed(futures):
                finish(fut.result())
                done += 1
                bars.update(overall, done)
        return
    from distributed import Client, LocalCluster
    from distributed import as_completed as dask_completed

    if scene.scheduler:
        client = Client(scene.scheduler)
        cluster = None
    else:
        cluster = LocalCluster(n_workers=scene.workers, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None)
        client = Client(cluster)
    try:
        futures = client.map(run_cell, jobs, pure=False)
        for fut in dask_completed(futures):
            finish(fut.result())
            done += 1
            bars.update(overall, done)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _cell_label(cell: Cell) -> str:
    return f"{cell.encoder} × {cell.classifier.split(':')[0]} L={cell.length} seed={cell.seed}"
