"""One cell: train a classifier on the cached encoding, test it, return its result row.

:func:`run_cell` runs in any process (this one, a worker process, a dask worker): a
:class:`CellJob` carries everything it needs, the registered
:class:`~tactbench.plugins.Component` of its classifier, split and test window included,
so a cell builds them from the plugins the run was planned with, not from whatever is
installed where it runs.

A cell draws its split (one train/test pair, or one per fold), checks what the split
returned (:func:`~tactbench.data.splits.draw_splits`: in range, deterministic, the data left as given) and what its test window gives (:func:`~tactbench.data.windows.check_windows`), and per fold makes the test
window's training and test windows, fits a model and lets the test window combine the
predictions of each test recording's windows. The row keeps, for every test recording,
its index, true and predicted class, the fold that tested it and the group it was left
out with (:data:`PREDICTION_LISTS`), and beside its test accuracy its accuracy on a sample
of its training windows and what guessing gives (:mod:`tactbench.runner.execution.learning`): a
cell whose model did not learn or did not transfer says so, and no verdict rests on it.

A cell that raises (a bug in a plugin, a classifier that fails in ``fit``, out of memory)
returns a *failed* row instead (see :mod:`tactbench.runner.execution.results`): no exception object
crosses a process boundary, and the rest of the grid goes on. Ctrl-C
(``KeyboardInterrupt``) is not a failure: it stops the run.
"""

from __future__ import annotations

import json
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

from tactbench.boundary import VIOLATION_FIELD, BoundaryError, check_labels, check_proba
from tactbench.classifiers.io import live_metadata, load_model, read_header
from tactbench.contracts import CLASSIFIER, TEST_WINDOW
from tactbench.data.splits import (
    Split,
    SplitData,
    build_split,
    dataset_groups,
    draw_splits,
    describe_splits,
    parse_split,
    split_design,
)
from tactbench.data.windows import UNNAMED_TEST_WINDOW, Windows, check_windows
from tactbench.errors import TactbenchError
from tactbench.plugins import Registry
from tactbench.runner.execution.devices import cell_device, check_device, device_label
from tactbench.runner.execution.entries import load_encoding
from tactbench.runner.execution.identity import DEFAULT_DEVICE
from tactbench.runner.execution.learning import TRAIN_SAMPLE, chance_level, learning_fields
from tactbench.runner.execution.planning import Cell, Plan
from tactbench.runner.execution.results import FAILED, OK
from tactbench.runner.execution.scene import Scene
from tactbench.kernels import DEFAULT_KERNELS, KERNELS_ENV, aten_level, torch_kernels
from tactbench.machine import host, machine, versions
from tactbench.runner.execution.system import MemoryTracker, now
from tactbench.seeds import derive_seed
from tactbench.specs import parse_spec

if TYPE_CHECKING:
    import numpy as np

#: How many of the innermost traceback frames a failed row keeps.
TRACEBACK_FRAMES = 5


@dataclass(frozen=True)
class DatasetFacts:
    """What a cell needs of the dataset besides its encoding, made once per run and shared
    by every job."""

    labels: tuple[int, ...]  # class index of every sample
    users: tuple[str, ...]  # user of every sample
    classes: tuple[str, ...]
    groups: dict[str, tuple[str, ...]] | None = None  # metadata of group:KEY splits
    prepared: tuple[Any, ...] | None = None  # the test window's value of every sample

    @classmethod
    def of(cls, dataset: Any, *, window: Any = None) -> "DatasetFacts":
        """The facts of ``dataset``; with the test window ``window``, what its
        ``prepare`` makes of every sample (a contact onset), made here once."""
        prepare = None if window is None else TEST_WINDOW.get(window, "prepare")
        return cls(labels=tuple(int(x) for x in dataset.labels),
                   users=tuple(str(u) for u in dataset.users),
                   classes=tuple(dataset.classes),
                   groups={k: tuple(v) for k, v in dataset_groups(dataset).items()},
                   prepared=None if prepare is None else tuple(prepare(dataset)))

    def split_data(self, test_per_class: int) -> SplitData:
        """What a split sees of these samples."""
        import numpy as np

        return SplitData(np.asarray(self.labels, dtype=np.int64),
                         {"user": self.users, **(self.groups or {})}, test_per_class)


@dataclass(frozen=True)
class CellJob:
    """Everything a worker needs to run a cell, picklable and small: the cell, the scene
    it belongs to, the registered components it is built from (classifier, split, test
    window), the dataset's facts and where its encoding is."""

    cell: Cell
    identity: dict[str, Any]
    classifier: Any  # tactbench.plugins.Component of the cell's classifier (picklable)
    split: Any  # ... of the scene's split
    test_window: Any  # ... of the scene's test window
    encoding_dir: str
    scene: Scene
    data: DatasetFacts
    threads: int  # torch threads, as the planning machine resolved them
    model_path: str | None = None
    model_meta: dict[str, Any] | None = None


def make_jobs(p: Plan, cells: Sequence[Cell], folders: dict[tuple[str, str], str],
              models: Path | None = None) -> list[CellJob]:
    """The jobs of ``cells``: ``folders`` from
    :func:`~tactbench.runner.execution.cache.ensure_encodings`;
    with ``models``, each job also saves its model as ``models/<cell key>.safetensors``."""
    scene = p.scene
    data = DatasetFacts.of(p.dataset, window=p.test_window)  # shared by all
    split = p.registry.get("split", parse_split(scene.split)[0])
    window = p.registry.get("test-window", parse_spec(scene.test_window)[0])
    return [CellJob(cell=c, identity=p.identities[c.key],
                    classifier=p.classifier_component(c.classifier),
                    split=split, test_window=window,
                    encoding_dir=folders[(c.encoder, p.input_kind[c.classifier])],
                    scene=scene, data=data, threads=p.compute.threads,  # the record's
                    model_path=str(models / f"{c.key}.safetensors") if models else None,
                    model_meta=model_metadata(p, c) if models else None)
            for c in cells]


def model_metadata(p: Plan, cell: Cell) -> dict[str, Any]:
    """What `tactbench live` needs to use a cell's model: classes, layout, imaging, encoder."""
    return live_metadata(p.dataset, encoder=cell.encoder, L=cell.L,
                         pixel_mm=p.scene.resolved_pixel_mm(), method=p.scene.imaging)


def model_problem(path: str | Path, p: Plan, cell: Cell) -> str | None:
    """What is wrong with the saved model of ``cell`` at ``path``, or None when it is
    sound: it must load (:func:`~tactbench.classifiers.io.load_model`, whose errors
    name checksum, truncation and header problems), be this cell's (its metadata's
    ``cell``, ``encoder``, ``L``, ``classes``) and hold only finite weights."""
    import torch

    try:
        clf, meta = load_model(path, registry=p.registry)
        config = read_header(path).get("config", {})
    except TactbenchError as exc:  # ModelFileError is a CorruptArtefactError: a problem
        return getattr(exc, "problem", None) or str(exc)
    want = {"cell": cell.key, "encoder": cell.encoder, "L": cell.L,
            "classes": list(p.dataset.classes)}
    for field, value in want.items():
        if meta.get(field) != value:
            return f"its metadata records {field} = {str(meta.get(field))[:60]!r}, " \
                   f"this cell has {str(value)[:60]!r}"
    n_classes = config.get("n_classes") if isinstance(config, dict) else None
    if n_classes is not None and n_classes != len(want["classes"]):
        return f"a {n_classes}-class network for {len(want['classes'])} classes"
    export = CLASSIFIER.get(clf, "export")
    if export is None:  # a classifier without tensors to check
        return None
    try:
        _, tensors = export()
    except Exception:  # noqa: BLE001 — it cannot export its tensors: nothing to check
        return None
    for name, tensor in tensors.items():
        if isinstance(tensor, torch.Tensor) and tensor.is_floating_point() \
                and not bool(torch.isfinite(tensor).all()):
            return f"tensor {name!r} holds NaN or infinite values"
    return None


def run_cell(job: CellJob, progress: Callable[..., None] | None = None) -> dict[str, Any]:
    """Train and test one cell; its ``ok`` row, or a ``failed`` row if anything raised.

    ``progress(done, total, **info)`` follows training (see
    :func:`tactbench.classifiers.training.train_loop`).
    """
    memory = MemoryTracker()
    try:
        return train_and_test(job, progress, memory=memory)
    except Exception as exc:  # noqa: BLE001 — any failure is this cell's, recorded in its row
        return failed_row(job, exc, memory=memory)


def failed_row(job: CellJob, exc: BaseException,
               memory: MemoryTracker | None = None) -> dict[str, Any]:
    """The row of a cell that raised ``exc``: identity, error type, message, last frames,
    and (with ``memory``) the peak memory of the steps it got through."""
    frames = traceback.format_exception(type(exc), exc, exc.__traceback__,
                                        limit=-TRACEBACK_FRAMES, chain=False)
    memory = memory or MemoryTracker()
    return {
        "key": job.cell.key,
        **job.identity,
        "status": FAILED,
        "error": {"type": type(exc).__name__, "message": str(exc) or repr(exc),
                  "traceback": "".join(frames)},
        "classes": list(job.data.classes),
        "device": job.identity.get("device", DEFAULT_DEVICE),  # its kind, in its identity
        "threads": job.threads,
        "peak_rss_mb": memory.peak_mb,
        "peak_step": memory.peak_step,
        "memory": memory.as_dict(),
        "versions": versions(),
        "host": host(),
        "machine": machine(),
        "finished": now(),
    }


def train_and_test(job: CellJob, progress: Callable[..., None] | None = None, *,
                   memory: MemoryTracker | None = None) -> dict[str, Any]:
    """Train and test one cell and return its ``ok`` row; raises what the cell raises.

    ``memory`` (made here when not given) records the peak resident memory after each
    step: ``load encoding``, ``windows``, ``fit``, ``predict``, ``save model``; the row's
    ``peak_step`` names the step that set ``peak_rss_mb`` (see
    :class:`~tactbench.runner.execution.system.MemoryTracker`).
    """
    import torch

    memory = memory if memory is not None else MemoryTracker()
    check_kernels(job.identity)
    device = check_device(job.identity, cell_device(job.identity, job.scene.device))
    torch.set_num_threads(job.threads)
    cell, scene = job.cell, job.scene
    with memory.track("load encoding"):
        sequences, meta = load_encoding(job.encoding_dir)
    if meta.get(VIOLATION_FIELD):  # the encoder's output broke its contract: no score
        raise BoundaryError(str(meta[VIOLATION_FIELD]))
    # The planned components, not a fresh plugin lookup: see the module docstring.
    registry = Registry([job.classifier, job.split, job.test_window])
    data = job.data.split_data(scene.test_per_class)
    strategy = build_split(scene.split, registry)
    splits = draw_splits(strategy, data, cell.seed, f"split {scene.split!r}")
    tested = _train_and_predict(job, registry, sequences, data.labels, splits, progress,
                                memory, device)
    truth, predicted = tested["labels"], tested["predictions"]
    if job.model_path:  # planning allows saving only with one split (one model per cell)
        with memory.track("save model"):
            tested["model"].save(job.model_path, {
                **(job.model_meta or {}), "classifier": cell.classifier, "seed": cell.seed,
                "cell": cell.key, "test_accuracy": float((predicted == truth).mean())})
    confusion, per_class = _confusion(job.data.classes, truth, predicted)
    frames = max(1, int(meta.get("frames", 1)))
    return {
        "key": cell.key,
        **job.identity,
        "status": OK,
        **describe_splits(job.identity["split"], cell.seed, splits,
                          design=split_design(strategy, splits)),
        "test_window": job.identity.get("test_window", UNNAMED_TEST_WINDOW),
        "classes": list(job.data.classes),
        "accuracy": float((predicted == truth).mean()),
        "per_class_accuracy": per_class,
        "confusion": confusion.tolist(),
        # per test recording, for paired comparisons between cells (runner.summaries):
        # the fold that tested it and the group it was left out with
        "test_predictions": {k: tested[k].tolist() for k in PREDICTION_LISTS},
        # cost on one core: wall time × workers that shared the encoding, per frame
        "encode_ms_per_frame": 1e3 * float(meta.get("encode_seconds", 0.0))
        * int(meta.get("workers", 1)) / frames,
        "train_s": tested["train_s"],
        "inference_ms_per_sequence": 1e3 * tested["infer_s"] / max(1, len(truth)),
        "peak_rss_mb": memory.peak_mb,
        "peak_step": memory.peak_step,
        "memory": memory.as_dict(),
        "rss_before_fit_mb": tested["rss0"],
        "n_train_windows": tested["n_train_windows"],
        "n_test": len(truth),
        # beside the test accuracy: the training windows' and what guessing gives
        **learning_fields(train_right=tested["train_right"],
                          train_scored=tested["train_scored"],
                          train_chance=tested["train_chance"] / max(1, tested["train_scored"]),
                          train_recordings=min(len(s.train) for s in splits),
                          truth=truth, predicted=predicted, k=len(job.data.classes)),
        "fit": _jsonable(tested["fits"][0] if len(splits) == 1 else tested["fits"]),
        "device": job.identity.get("device", DEFAULT_DEVICE),  # its kind, in its identity
        "device_used": device_label(device),  # the one it trained on, a GPU's model too
        "threads": job.threads,
        "versions": versions(),
        "host": host(),
        "machine": machine(),
        "finished": now(),
    }


def check_kernels(identity: dict[str, Any]) -> None:
    """Refuse to train a cell whose identity names CPU kernels this process does not
    compute with (a dask worker started without the pin, torch imported before it): its
    numbers would be stored under a key that promises others."""
    wanted = identity.get("cpu_kernels", DEFAULT_KERNELS)
    level = aten_level(wanted)  # a level, a custom ATEN_CPU_CAPABILITY, native's widest
    here = torch_kernels()
    if level is not None and here is not None and here.lower() != level.lower():
        raise RuntimeError(f"this worker's torch computes with {here} kernels, the cell's "
                           f"identity says {wanted}: start the worker with "
                           f"{KERNELS_ENV}={wanted} in its environment (docs/reliability.md)")


#: The lists of a row's ``test_predictions``, one entry per test recording in the same
#: order: its index, true class, predicted class, fold and group (rows made before folds
#: and groups were stored lack the last two).
PREDICTION_LISTS = ("indices", "labels", "predictions", "folds", "groups")


def _train_and_predict(job: CellJob, registry: Registry, sequences: Sequence[Any],
                       labels: "np.ndarray", splits: Sequence[Split],
                       progress: Callable[..., None] | None,
                       memory: MemoryTracker, device: str) -> dict[str, Any]:
    """Fit a model on each split's training windows (on ``device``) and predict its test
    recordings:
    the :data:`PREDICTION_LISTS` pooled over folds (arrays), the last model, each fit's
    report, times and the memory before the first fit."""
    import numpy as np

    cell, scene = job.cell, job.scene
    window = registry.build("test-window", scene.test_window)
    prepared = job.data.prepared
    out: dict[str, Any] = {k: [] for k in PREDICTION_LISTS}
    out.update(fits=[], train_s=0.0, infer_s=0.0, n_train_windows=0, rss0=0.0,
               train_right=0, train_scored=0, train_chance=0.0)
    for split in splits:
        with memory.track("windows"):
            train = check_windows(window.training(
                *_recordings(sequences, labels, split.train), cell.L,
                prepared=_prepared(prepared, split.train)),
                f"test window {scene.test_window!r} (its training windows)")
            test = check_windows(window.test(*_recordings(sequences, labels, split.test),
                                             cell.L, prepared=_prepared(prepared, split.test)),
                                 f"test window {scene.test_window!r}", every=True)
            clf = registry.build("classifier", cell.classifier, classes=len(job.data.classes))
        if split.fold == 0:
            out["rss0"] = memory.peak_mb
        # one split keeps the seed it always had; the folds of a k-fold split differ
        seed = derive_seed(cell.seed, cell.encoder, cell.classifier, cell.L,
                           *(() if len(splits) == 1 else (f"fold {split.fold}",)),
                           *(() if cell.init_seed is None else (f"init {cell.init_seed}",)))
        with memory.track("fit"):
            t0 = time.perf_counter()
            out["fits"].append(clf.fit(train, None, seed=seed, device=device,
                                       progress=progress))
            out["train_s"] += time.perf_counter() - t0
        with memory.track("predict"):
            t0 = time.perf_counter()
            checked = _Checked(clf, len(job.data.classes), cell.classifier,
                               job.classifier.plugin)
            predicted = np.asarray(window.combine(checked, test, len(split.test)))
            out["infer_s"] += time.perf_counter() - t0
            _score_training(out, checked, train, seed, len(job.data.classes))
        if predicted.shape != (len(split.test),):
            raise ValueError(f"test window {scene.test_window!r} combined {predicted.shape} "
                             f"predictions for {len(split.test)} test recordings")
        for key, values in zip(PREDICTION_LISTS, (split.test, labels[split.test], predicted,
                                                  [split.fold] * len(split.test),
                                                  split.groups)):
            out[key].append(np.asarray(values))
        out["n_train_windows"] += len(train)
    out.update({k: np.concatenate(out[k]) for k in PREDICTION_LISTS}, model=clf)
    return out


def _score_training(out: dict[str, Any], checked: "_Checked", train: Windows, seed: int,
                    k: int) -> None:
    """Add to ``out`` the right answers on a seeded sample of at most
    :data:`~tactbench.runner.execution.learning.TRAIN_SAMPLE` of a fold's training windows, their
    count and what guessing gives on them (weighted by the windows scored)."""
    import numpy as np

    rng = np.random.default_rng(derive_seed(seed, "training accuracy"))
    n = min(TRAIN_SAMPLE, len(train))
    pick = np.sort(rng.choice(len(train), size=n, replace=False))
    sample = Windows(train.sequences, train.seq_index[pick], train.starts[pick],
                     train.labels[pick], train.L)
    out["train_right"] += int((checked.predict(sample) == sample.labels).sum()) if n else 0
    out["train_chance"] += chance_level(sample.labels, k) * n
    out["train_scored"] += n


def _recordings(sequences: Sequence[Any], labels: "np.ndarray", indices: "np.ndarray",
                ) -> tuple[list[Any], "np.ndarray"]:
    """The sequences and labels of the recordings ``indices``."""
    return [sequences[i] for i in indices], labels[indices]


def _prepared(prepared: Sequence[Any] | None, indices: "np.ndarray") -> list[Any] | None:
    """The test window's prepared values of the recordings ``indices`` (None: none)."""
    return None if prepared is None else [prepared[i] for i in indices]


class _Checked:
    """A fitted classifier as a test window sees it: what ``predict`` and
    ``predict_proba`` return is checked at the boundary (:mod:`tactbench.boundary`), so
    a plugin's NaN, negative or wrongly shaped output fails the cell instead of being
    scored."""

    def __init__(self, clf: Any, k: int, component: str, plugin: str) -> None:
        self._clf, self._k, self._who = clf, k, {"component": component, "plugin": plugin}

    def predict(self, windows: Any) -> "np.ndarray":
        return check_labels(self._clf.predict(windows), len(windows), self._k, **self._who)

    def predict_proba(self, windows: Any) -> "np.ndarray":
        return check_proba(self._clf.predict_proba(windows), len(windows), self._k,
                           **self._who)


def _confusion(classes: Sequence[str], truth: "np.ndarray", predicted: "np.ndarray",
               ) -> tuple["np.ndarray", dict[str, float | None]]:
    """The confusion matrix (rows: true class) and each class's accuracy (None for a
    class without test sequences)."""
    import numpy as np

    k = len(classes)
    confusion = np.zeros((k, k), dtype=np.int64)
    np.add.at(confusion, (truth, predicted), 1)
    support = confusion.sum(axis=1)
    per_class = {classes[i]: (float(confusion[i, i] / support[i]) if support[i] else None)
                 for i in range(k)}
    return confusion, per_class


def _jsonable(obj: Any) -> Any:
    return json.loads(json.dumps(obj, default=str))
