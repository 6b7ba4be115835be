"""Any scikit-learn classifier on pooled per-frame features: ``sklearn:estimator=NAME``.

The baselines researchers already know (gradient boosting, SVMs, random forests, k-NN)
beside the networks, on the same windows: ``sklearn:estimator=HistGradientBoostingClassifier``,
``sklearn:estimator=SVC,C=10``. ``estimator`` is a class name from
``sklearn.utils.all_estimators(type_filter="classifier")``; every other option except
``grid`` and ``classes`` is a parameter of that estimator (checked against its
``get_params()`` and its own validation when the classifier is built, so a typo is refused
before any data is encoded). scikit-learn is an optional extra (``pip install
"tactbench[sklearn]"``) and is imported only when this classifier is built.

Features (:func:`frame_features`), per frame, per channel, from the frame alone:

- images ``(C, H, W)``: mean, standard deviation, minimum and maximum of the values;
  centroid (row, column) and spread (standard deviation of row and column) of the
  ``|value|`` mass, coordinates in [0, 1] (zero for a blank channel); and the mean of each
  cell of a ``grid × grid`` partition of the image;
- taxel vectors ``(N,)``: mean, standard deviation, minimum, maximum, and the mean of
  ``grid²`` consecutive groups of taxels (no geometry without a layout).

A window's features are its ``L`` frames' features side by side (the trajectories of those
numbers over the window; blank padding frames give zeros), stored as float32. Every
estimator sees the same features, so the table compares estimators, not feature sets.

Seeding: ``random_state`` is set from the cell's seed when the estimator has one (an
explicit ``random_state`` option wins). Probabilities come from ``predict_proba``; an
estimator without one (``LinearSVC``, ``SVC`` without ``probability=True``, ...) gives the
softmax of its ``decision_function`` (scores, not calibrated probabilities), else a one-hot
of ``predict``. ``predict`` is always the argmax of those probabilities, as for every
tactbench classifier; classes missing from the training windows get probability 0.

Model files hold no pickle (see :mod:`tactbench.classifiers.io`): they keep the training
features and labels, and loading refits the estimator with the same parameters and seed,
then checks that it predicts what was saved on up to :data:`CHECK_ROWS` training windows
(a different scikit-learn or platform that changes the fit is refused, naming both
versions). The file grows with the training set (``windows × L × F × 4`` bytes) and loading
costs one fit.
"""

from __future__ import annotations

import difflib
import functools
import sys
import time
from contextlib import contextmanager
from typing import Any, ClassVar, Iterator

import numpy as np

from tactbench.budget import check_budget
from tactbench.classifiers.base import SequenceClassifier
from tactbench.classifiers.batching import frame_index, frames_per_chunk
from tactbench.classifiers.training import FitReport, ProgressFn
from tactbench.data.windows import Windows
from tactbench.errors import InputError, check_positive_int

#: Training windows whose saved probabilities a loaded model must reproduce.
CHECK_ROWS = 256
#: Options of this classifier itself; every other option goes to the estimator.
OWN_OPTIONS = ("estimator", "grid", "classes")
DEFAULT_ESTIMATOR = "HistGradientBoostingClassifier"


@functools.lru_cache(maxsize=1)
def estimator_classes() -> dict[str, type]:
    """Every scikit-learn classifier by class name (the first call imports every
    scikit-learn module: 5–6 s measured on a busy 2-core machine, once per process)."""
    from sklearn.utils import all_estimators

    return dict(all_estimators(type_filter="classifier"))


def find_estimator(name: Any) -> type:
    """The scikit-learn classifier class called ``name``; an unknown name is one line
    with the closest names."""
    known = estimator_classes()
    if isinstance(name, str) and name in known:
        return known[name]
    text = str(name)
    by_lower = {k.lower(): k for k in known}
    close = ([by_lower[text.lower()]] if text.lower() in by_lower
             else difflib.get_close_matches(text, list(known), n=3, cutoff=0.5))
    hint = (f"; did you mean {' or '.join(repr(c) for c in close)}?" if close
            else f". Known: {', '.join(sorted(known))}")
    raise InputError(f"scikit-learn has no classifier '{text}'{hint}")


def frame_features(frames: np.ndarray, grid: int) -> np.ndarray:
    """``(n, C, H, W)`` or ``(n, N)`` frames → ``(n, F)`` float64 features (module
    docstring): ``F = C × (8 + grid²)`` for images, ``4 + grid²`` for vectors."""
    x = np.asarray(frames, dtype=np.float64)
    n = x.shape[0]
    if x.ndim == 2:
        groups = np.array_split(np.arange(x.shape[1]), grid * grid)
        pooled = [x[:, g].mean(1) if len(g) else np.zeros(n) for g in groups]
        return np.stack([x.mean(1), x.std(1), x.min(1), x.max(1), *pooled], axis=1)
    if x.ndim != 4:
        raise InputError(f"frames must be images (n, C, H, W) or taxel vectors (n, N), "
                         f"got shape {x.shape}")
    _, c, h, w = x.shape
    flat = x.reshape(n, c, h * w)
    stats = [flat.mean(2), flat.std(2), flat.min(2), flat.max(2)]
    mass = np.abs(x)
    total = mass.sum((2, 3))
    safe = np.where(total > 0, total, 1.0)
    for axis, size in ((3, h), (2, w)):  # rows (sum over columns), then columns
        profile = mass.sum(axis)  # (n, c, size)
        pos = np.linspace(0.0, 1.0, size) if size > 1 else np.full(1, 0.5)
        centre = (profile @ pos) / safe
        spread = np.sqrt(np.maximum((profile @ pos ** 2) / safe - centre ** 2, 0.0))
        stats += [np.where(total > 0, centre, 0.0), np.where(total > 0, spread, 0.0)]
    rows = np.array_split(np.arange(h), grid)
    cols = np.array_split(np.arange(w), grid)
    for r in rows:
        for q in cols:
            cell = x[:, :, r[0]:r[-1] + 1, q[0]:q[-1] + 1] if len(r) and len(q) else None
            stats.append(cell.mean((2, 3)) if cell is not None else np.zeros((n, c)))
    return np.stack(stats, axis=2).reshape(n, -1)


@contextmanager
def _threads() -> Iterator[None]:
    """scikit-learn's OpenMP/BLAS threads follow torch's setting when the runner has set
    it (``--threads``); otherwise they are left alone."""
    torch = sys.modules.get("torch")
    if torch is None:
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=max(1, int(torch.get_num_threads()))):
        yield


class SklearnClassifier(SequenceClassifier):
    """A scikit-learn estimator on pooled per-frame features (module docstring)."""

    name: ClassVar[str] = "sklearn"
    frame_rank: ClassVar[int | None] = None
    #: ``sklearn:SVC,C=10`` means ``sklearn:estimator=SVC,C=10`` (tactbench.plugins).
    positional_option: ClassVar[str] = "estimator"

    def __init__(self, estimator: str = DEFAULT_ESTIMATOR, grid: int = 3,
                 classes: int | None = None, **params: Any) -> None:
        self.classes = classes
        super().__post_init__()
        self.grid = check_positive_int(grid, "grid")
        self.estimator_name = find_estimator(estimator).__name__
        self.params = dict(params)
        self._make(seed=None)  # refuses unknown parameters and bad values now
        self.model = None
        self.class_index: np.ndarray | None = None  # the estimator's classes_ → columns
        self._train: tuple[np.ndarray, np.ndarray] | None = None  # features, labels
        self._seed: int | None = None

    def options(self) -> dict[str, Any]:
        return {"estimator": self.estimator_name, "grid": self.grid, "classes": self.classes,
                **self.params}

    def _make(self, seed: int | None):
        cls = find_estimator(self.estimator_name)
        try:
            est = cls()
        except TypeError as exc:  # meta-estimators need an estimator object
            raise InputError(f"{self.estimator_name} cannot be built from text options "
                             f"alone ({exc})") from None
        accepted = est.get_params(deep=False)
        for key in self.params:
            if key not in accepted:
                close = difflib.get_close_matches(key, list(accepted), n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise InputError(f"{self.estimator_name} has no parameter '{key}'{hint}; "
                                 f"its parameters: {', '.join(sorted(accepted))}; "
                                 f"this classifier's own options: {', '.join(OWN_OPTIONS)}")
        values = dict(self.params)
        if seed is not None and "random_state" in accepted and "random_state" not in values:
            values["random_state"] = int(seed) % 2 ** 32
        est.set_params(**values)
        validate = getattr(est, "_validate_params", None)  # scikit-learn ≥ 1.2
        if validate is not None and hasattr(est, "_parameter_constraints"):
            try:
                validate()
            except (ValueError, TypeError) as exc:
                raise InputError(f"{self.estimator_name}: {_one_line(exc)}") from None
        return est

    # -- features ----------------------------------------------------------------------

    def _n_features(self, frame_shape: tuple[int, ...]) -> int:
        return frame_features(np.zeros((1, *frame_shape), np.float32), self.grid).shape[1]

    def _window_features(self, x: Windows | np.ndarray) -> np.ndarray:
        """``(B, L × F)`` float32: each sequence's frames reduced to features once."""
        if not isinstance(x, Windows):
            b, length = x.shape[:2]
            feats = frame_features(x.reshape(b * length, *x.shape[2:]), self.grid)
            return feats.reshape(b, -1).astype(np.float32)
        n_feat = self._n_features(x.frame_shape)
        total = sum(int(s.shape[0]) for s in x.sequences)
        check_budget((total + len(x) * x.L) * n_feat * 4,
                     f"{self.estimator_name} features of {len(x)} windows")
        bank = np.zeros((total + 1, n_feat), dtype=np.float32)  # last row: blank frame
        lengths, offsets, index = frame_index(x)
        step = frames_per_chunk(x.frame_shape)
        for i, seq in enumerate(x.sequences):
            for a in range(0, int(lengths[i]), step):
                b = min(int(lengths[i]), a + step)
                bank[offsets[i] + a:offsets[i] + b] = frame_features(seq[a:b], self.grid)
        return bank[index].reshape(len(x), -1)

    # -- fit and predict ---------------------------------------------------------------

    def _fit_estimator(self, feats: np.ndarray, labels: np.ndarray, seed: int) -> None:
        est = self._make(seed)
        try:
            with _threads():
                est.fit(feats, labels)
        except ValueError as exc:  # e.g. an estimator that needs two classes, or more rows
            raise InputError(f"{self.estimator_name} could not be fitted: "
                             f"{_one_line(exc)}") from None
        self.model = est
        self.class_index = np.asarray(est.classes_, dtype=np.int64)

    def fit(self, train: Windows, val: Windows | None = None, *, seed: int,
            device: str = "cpu", progress: ProgressFn | None = None,
            n_classes: int | None = None) -> dict[str, Any]:
        """Fit the estimator on every training window's features (CPU only: ``device``
        must be "cpu" or "auto")."""
        self._check_windows(train, "train")
        if str(device).strip().lower() not in ("cpu", "auto"):
            raise InputError(f"the sklearn classifier runs on the CPU; device '{device}' "
                             f"was asked for")
        k = self._resolve_classes(train, val, n_classes)
        report = FitReport(classifier=self.name, seed=int(seed), device="cpu", amp=False,
                           n_classes=k, options=self.options(), train_windows=len(train),
                           batches="pooled features")
        start, cpu0 = time.perf_counter(), time.process_time()
        if progress is not None:
            progress(0, 1, epoch=1, epochs=1)
        feats = self._window_features(train)
        labels = np.asarray(train.labels, dtype=np.int64)
        self.n_classes, self.frame_shape, self.L = k, tuple(train.frame_shape), train.L
        self._fit_estimator(feats, labels, seed)
        self._train, self._seed = (feats, labels), int(seed)
        proba = self._proba_of(feats)
        loss = float(-np.mean(np.log(np.clip(proba[np.arange(len(labels)), labels],
                                             1e-12, 1.0))))
        report.epochs, report.steps, report.windows_seen = 1, 1, len(train)
        report.final_loss = loss
        report.epoch_losses = [loss]
        report.bank_mb = feats.nbytes / 2 ** 20
        if val is not None and len(val):
            report.val_accuracy = [float((self.predict(val) == val.labels).mean())]
        report.train_seconds = time.perf_counter() - start
        report.train_cpu_seconds = time.process_time() - cpu0
        report.windows_per_second = len(train) / max(report.train_seconds, 1e-9)
        self.fit_report = report.as_dict()
        if progress is not None:
            progress(1, 1, epoch=1, epochs=1, loss=loss)
        return dict(self.fit_report)

    def _proba_of(self, feats: np.ndarray) -> np.ndarray:
        """``(B, n_classes)`` float32 from the estimator, columns put in class order."""
        est = self.model
        with _threads():
            if hasattr(est, "predict_proba"):
                p = np.asarray(est.predict_proba(feats), dtype=np.float64)
            elif hasattr(est, "decision_function"):
                s = np.asarray(est.decision_function(feats), dtype=np.float64)
                if s.ndim == 1:  # two classes: the score of the second
                    s = np.stack([-s, s], axis=1) / 2
                s = s - s.max(1, keepdims=True)
                p = np.exp(s)
                p /= p.sum(1, keepdims=True)
            else:
                pred = np.asarray(est.predict(feats))
                p = (pred[:, None] == est.classes_[None, :]).astype(np.float64)
        out = np.zeros((len(feats), self.n_classes), dtype=np.float64)
        out[:, self.class_index] = p
        return out.astype(np.float32)

    def predict_proba(self, x: Windows | np.ndarray) -> np.ndarray:
        x = self._check_input(x)
        shape = x.frame_shape if isinstance(x, Windows) else tuple(x.shape[2:])
        if tuple(shape) != tuple(self.frame_shape):
            raise InputError(f"sklearn:{self.estimator_name} needs frames of the trained "
                             f"shape {self.frame_shape}, got {tuple(shape)}")
        length = x.L if isinstance(x, Windows) else x.shape[1]
        if length != self.L:
            raise InputError(f"sklearn:{self.estimator_name} was fitted on windows of "
                             f"L = {self.L} frames, got L = {length}")
        if len(x) == 0:
            return np.zeros((0, self.n_classes), dtype=np.float32)
        return self._proba_of(self._window_features(x))

    # -- model files -------------------------------------------------------------------

    def export(self):
        import sklearn
        import torch

        if self._train is None:
            raise RuntimeError("sklearn classifier is not fitted: nothing to save")
        feats, labels = self._train
        rows = np.unique(np.linspace(0, len(labels) - 1, min(CHECK_ROWS, len(labels)))
                         .round().astype(np.int64))
        config = {**self._base_config(), "seed": self._seed, "sklearn": sklearn.__version__}
        tensors = {"features": torch.from_numpy(np.ascontiguousarray(feats)),
                   "labels": torch.from_numpy(labels),
                   "check_rows": torch.from_numpy(rows),
                   "check_proba": torch.from_numpy(self._proba_of(feats[rows]))}
        return config, tensors

    @classmethod
    def _restore(cls, config, tensors):
        import sklearn

        need = {"features", "labels", "check_rows", "check_proba"}
        if set(tensors) != need:
            raise InputError(f"expected tensors {sorted(need)}, found {sorted(tensors)}")
        clf = cls(**config["options"])
        clf.n_classes = int(config["n_classes"])
        clf.frame_shape = tuple(int(s) for s in config["frame_shape"])
        clf.L = config.get("L")
        clf.fit_report = config.get("fit_report")
        feats = tensors["features"].numpy()
        labels = tensors["labels"].numpy().astype(np.int64)
        rows = tensors["check_rows"].numpy().astype(np.int64)
        saved = tensors["check_proba"].numpy()
        width = clf._n_features(clf.frame_shape) * int(clf.L or 0)
        if feats.ndim != 2 or feats.shape != (len(labels), width) or labels.ndim != 1 \
                or (len(rows) and (rows.min() < 0 or rows.max() >= len(labels))) \
                or saved.shape != (len(rows), clf.n_classes):
            raise InputError(f"stored features {tuple(feats.shape)}, labels "
                             f"{tuple(labels.shape)} and checks {tuple(saved.shape)} do not "
                             f"fit {clf.n_classes} classes and windows of {clf.L} "
                             f"frames {clf.frame_shape}")
        clf._fit_estimator(feats, labels, int(config["seed"]))
        clf._train, clf._seed = (feats, labels), int(config["seed"])
        again = clf._proba_of(feats[rows])
        if not (np.array_equal(again.argmax(1), saved.argmax(1))
                and np.allclose(again, saved, atol=1e-5)):
            raise ValueError(f"refitting {clf.estimator_name} does not reproduce the saved "
                             f"predictions (saved with scikit-learn {config.get('sklearn')}, "
                             f"this is {sklearn.__version__}); retrain the model here")
        return clf


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())
