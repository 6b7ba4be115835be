"""One cell: train a classifier on the cached encoding, test it, return its result row.

:func:`run_cell` runs in any process (this one, a worker process, a dask worker): a
:class:`CellJob` carries everything it needs, the classifier's registered
:class:`~tactbench.plugins.Component` included, so a cell builds its classifier from the
plugins the run was planned with, not from whatever is installed where it runs.

A cell that raises (a bug in a plugin, a classifier that fails in ``fit``, out of memory)
returns a *failed* row instead (see :mod:`tactbench.runner.results`): no exception object
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
from tactbench.contracts import CLASSIFIER
from tactbench.data.splits import dataset_groups, describe_splits, make_splits
from tactbench.data.windows import dataset_onsets, test_windows_for, training_windows_for
from tactbench.errors import TactbenchError
from tactbench.plugins import Registry
from tactbench.runner.entries import load_encoding
from tactbench.runner.planning import Cell, Plan
from tactbench.runner.results import FAILED, OK
from tactbench.runner.scene import Scene
from tactbench.machine import machine
from tactbench.runner.system import MemoryTracker, host, now, versions
from tactbench.seeds import derive_seed

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
    onsets: tuple[int, ...] | None = None  # contact onset frame of every sample (onset)
    groups: dict[str, tuple[str, ...]] | None = None  # metadata of group:KEY splits

    @classmethod
    def of(cls, dataset: Any, *, onsets: bool = False) -> "DatasetFacts":
        """The facts of ``dataset`` (its samples' onsets too, with ``onsets``)."""
        return cls(labels=tuple(int(x) for x in dataset.labels),
                   users=tuple(str(u) for u in dataset.users),
                   classes=tuple(dataset.classes),
                   onsets=dataset_onsets(dataset) if onsets else None,
                   groups={k: tuple(v) for k, v in dataset_groups(dataset).items()})


@dataclass(frozen=True)
class CellJob:
    """Everything a worker needs to run a cell, picklable and small: the cell, the scene
    it belongs to, the dataset's facts and where its encoding is."""

    cell: Cell
    identity: dict[str, Any]
    classifier: Any  # tactbench.plugins.Component of the cell's classifier (picklable)
    encoding_dir: str
    scene: Scene
    data: DatasetFacts
    threads: int  # torch threads, as the planning machine resolved them
    model_path: str | None = None
    model_meta: dict[str, Any] | None = None


def make_jobs(p: Plan, cells: Sequence[Cell], folders: dict[tuple[str, str], str],
              models: Path | None = None) -> list[CellJob]:
    """The jobs of ``cells``: ``folders`` from :func:`~tactbench.runner.cache.ensure_encodings`;
    with ``models``, each job also saves its model as ``models/<cell key>.safetensors``."""
    scene = p.scene
    data = DatasetFacts.of(p.dataset, onsets=scene.test_window == "onset")  # shared by all
    return [CellJob(cell=c, identity=p.identities[c.key],
                    classifier=p.classifier_component(c.classifier),
                    encoding_dir=folders[(c.encoder, p.input_kind[c.classifier])],
                    scene=scene, data=data, threads=scene.resolved_threads(),
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
        "device": job.scene.device,
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
    :class:`~tactbench.runner.system.MemoryTracker`).
    """
    import numpy as np
    import torch

    memory = memory if memory is not None else MemoryTracker()
    torch.set_num_threads(job.threads)
    cell = job.cell
    with memory.track("load encoding"):
        sequences, meta = load_encoding(job.encoding_dir)
    if meta.get(VIOLATION_FIELD):  # the encoder's output broke its contract: no score
        raise BoundaryError(str(meta[VIOLATION_FIELD]))
    scene, data = job.scene, job.data
    labels = np.asarray(data.labels, dtype=np.int64)
    splits = make_splits(scene.split, labels=labels, users=data.users, seed=cell.seed,
                         test_per_class=scene.test_per_class,
                         groups=data.groups)
    rss0 = 0.0
    train_s = infer_s = 0.0
    n_train = n_test = 0
    indices, truths, predictions, fits = [], [], [], []
    for fold, split in enumerate(splits):
        with memory.track("windows"):
            train, test = _windows(job, sequences, labels, split)
            # The planned component, not a fresh plugin lookup: see the module docstring.
            clf = Registry([job.classifier]).build("classifier", cell.classifier,
                                                   classes=len(data.classes))
        if fold == 0:
            rss0 = memory.peak_mb
        # one split keeps the seed it always had; the folds of a k-fold split differ
        seed = derive_seed(cell.seed, cell.encoder, cell.classifier, cell.L,
                           *(() if len(splits) == 1 else (f"fold {fold}",)),
                           *(() if cell.init_seed is None else (f"init {cell.init_seed}",)))
        with memory.track("fit"):
            t0 = time.perf_counter()
            fits.append(clf.fit(train, None, seed=seed, device=scene.device,
                                progress=progress))
            train_s += time.perf_counter() - t0
        with memory.track("predict"):
            t0 = time.perf_counter()
            predicted = _predict(clf, test, scene.test_window, len(split.test),
                                 (cell.classifier, job.classifier.plugin, len(data.classes)))
            infer_s += time.perf_counter() - t0
        indices.append(np.asarray(split.test))
        truths.append(labels[split.test])
        predictions.append(predicted)
        n_train += len(train)
        n_test += len(split.test)
    test_index = np.concatenate(indices)
    truth = np.concatenate(truths)
    predicted = np.concatenate(predictions)
    if job.model_path:  # planning allows saving only with one split (one model per cell)
        with memory.track("save model"):
            clf.save(job.model_path, {**(job.model_meta or {}), "classifier": cell.classifier,
                                      "seed": cell.seed, "cell": cell.key,
                                      "test_accuracy": float((predicted == truth).mean())})

    confusion, per_class = _confusion(data.classes, truth, predicted)
    frames = max(1, int(meta.get("frames", 1)))
    return {
        "key": cell.key,
        **job.identity,
        "status": OK,
        **describe_splits(splits),
        "test_window": scene.test_window,
        "classes": list(data.classes),
        "accuracy": float((predicted == truth).mean()),
        "per_class_accuracy": per_class,
        "confusion": confusion.tolist(),
        # per test sequence, for paired comparisons between cells (runner.summaries)
        "test_predictions": {"indices": test_index.tolist(),
                             "labels": truth.tolist(), "predictions": predicted.tolist()},
        # cost on one core: wall time × workers that shared the encoding, per frame
        "encode_ms_per_frame": 1e3 * float(meta.get("encode_seconds", 0.0))
        * int(meta.get("workers", 1)) / frames,
        "train_s": train_s,
        "inference_ms_per_sequence": 1e3 * infer_s / max(1, n_test),
        "peak_rss_mb": memory.peak_mb,
        "peak_step": memory.peak_step,
        "memory": memory.as_dict(),
        "rss_before_fit_mb": rss0,
        "n_train_windows": n_train,
        "n_test": n_test,
        "fit": _jsonable(fits[0] if len(fits) == 1 else fits),
        "device": scene.device,
        "threads": job.threads,
        "versions": versions(),
        "host": host(),
        "machine": machine(),
        "finished": now(),
    }


def _windows(job: CellJob, sequences: Sequence[Any], labels: "np.ndarray",
             split: Any) -> tuple[Any, Any]:
    """The training and test windows of one split, as the scene's test window says."""
    mode, onsets, length = job.scene.test_window, job.data.onsets, job.cell.L

    def onsets_of(indices: Any) -> list[int] | None:
        return None if onsets is None else [onsets[i] for i in indices]

    train = training_windows_for(mode, [sequences[i] for i in split.train],
                                 labels[split.train], length, onsets=onsets_of(split.train))
    test = test_windows_for(mode, [sequences[i] for i in split.test], labels[split.test],
                            length, onsets=onsets_of(split.test))
    return train, test


def _predict(clf: Any, test: Any, mode: str, n_sequences: int,
             who: tuple[str, str, int]) -> "np.ndarray":
    """The predicted class of each test sequence: of its one window, or with ``mode``
    ``"vote"`` of every window of it (probabilities averaged). ``who``: the classifier's
    spec, plugin and class count K, for the run-time checks of what it returns
    (:mod:`tactbench.boundary`: a violation fails the cell)."""
    import numpy as np

    component, plugin, k = who
    if mode != "vote":
        return check_labels(clf.predict(test), len(test), k, component=component,
                            plugin=plugin)
    proba = check_proba(clf.predict_proba(test), len(test), k, component=component,
                        plugin=plugin)
    summed = np.zeros((n_sequences, proba.shape[1]))
    np.add.at(summed, test.seq_index, proba)
    return summed.argmax(axis=1)


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
