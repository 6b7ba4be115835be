"""The base of the built-in classifiers: the shared fit, predict, save and checks.

How a fit's batches of windows are read (the frame bank, per-batch reading, frames shared
between overlapping windows) is :mod:`tactbench.classifiers.batching`.

The classifier contract (what the runner, ``live`` and the model files rely on, which
members are optional and their defaults) is :data:`tactbench.contracts.CLASSIFIER`;
:meth:`tactbench.plugins.Registry.build` checks it. In short, a classifier is built
with keyword options (every option has a default)::

    clf = registry.build("classifier", "small-cnn-lstm:epochs=3,input_size=32")
    report = clf.fit(train, val, seed=0, device="cpu", progress=None)   # → dict
    clf.predict(test)        # (B,) int64 class indices
    clf.predict_proba(test)  # (B, K) float32, rows sum to 1
    clf.save("model.safetensors", {"encoder": "farneback", "classes": [...]})

``train``/``val``/``test`` are :class:`tactbench.data.windows.Windows`; ``predict``
also takes an array ``(B, L, *frame_shape)``. Frames are images ``(C, H, W)``
or taxel vectors ``(N,)``, depending on the classifier's ``frame_rank``.
Labels are ``0 .. K-1``; ``K`` comes from the ``classes`` option, else from
``fit(..., n_classes=K)``, else from the largest label seen plus one.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar, Sequence

import numpy as np

from tactbench.classifiers.batching import (
    bank_budget_bytes,
    frames_per_chunk,
    loader_workers,
    read_windows,
    share_frames,
    shares_at_inference,
    streamed_mean_std,
    training_batches,
    window_runs,
)
from tactbench.classifiers.costs import estimate_seconds
from tactbench.classifiers.io import save_model
from tactbench.classifiers.training import (
    FitReport,
    ProgressFn,
    TrainingInterrupted,
    precision_for,
    select_device,
    train_loop,
)
from tactbench.data.windows import Windows
from tactbench.errors import InputError, check_choice, check_positive_float, check_positive_int
from tactbench.seeds import derive_seed

#: The normalisation sample (at most NORM_SAMPLE_FRAMES prepared frames, a size that
#: does not grow with the dataset) is held whole below this many bytes, giving the exact
#: float32 statistics; above it (e.g. 4096 frames at 224 px, 2.4 GB) its statistics are
#: merged chunk by chunk in float64, equal up to rounding.
NORM_SAMPLE_BYTES = 512 * 2 ** 20
#: Prepared input of one forward pass at prediction, at most (the quick profile's 256
#: windows of 5 × 3 × 32 × 32 floats are 16 MB; at 224 px the step shrinks to ~21 windows).
EVAL_INPUT_BYTES = 64 * 2 ** 20
#: Frames sampled to estimate the normalisation statistics.
NORM_SAMPLE_FRAMES = 4096
#: The ``optimizer`` and ``schedule`` options :func:`.training.train_loop` accepts.
OPTIMIZERS = ("adam", "adamw", "sgd")
SCHEDULES = ("cosine", "constant", "onecycle")


@dataclass(eq=False, repr=False, kw_only=True)
class SequenceClassifier:
    """Base of every built-in classifier: options are the dataclass fields.

    Fills in the members of :data:`tactbench.contracts.CLASSIFIER` (``predict`` from
    ``predict_proba``, ``save`` through :mod:`tactbench.classifiers.io`) and checks
    the options when the classifier is built, so a bad value is refused before any
    data is encoded.
    """

    name: ClassVar[str] = ""
    #: See ``frame_rank`` in :data:`tactbench.contracts.CLASSIFIER`.
    frame_rank: ClassVar[int | None] = 3

    classes: int | None = None  # number of classes K; None: from fit

    def __post_init__(self) -> None:
        if self.classes is not None:
            check_positive_int(self.classes, "classes", minimum=2)
        self.n_classes: int | None = None
        self.frame_shape: tuple[int, ...] | None = None
        self.L: int | None = None
        self.fit_report: dict[str, Any] | None = None

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"

    def options(self) -> dict[str, Any]:
        """The options this classifier was built with (JSON-ready)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def fitted(self) -> bool:
        return self.n_classes is not None

    # -- checks shared by fit and predict --------------------------------------------

    def _check_windows(self, windows: Windows, what: str) -> None:
        if not isinstance(windows, Windows):
            raise TypeError(f"{what} must be tactbench.data.windows.Windows, "
                            f"got {type(windows).__name__}")
        if len(windows) == 0:
            raise InputError(f"{what} has no windows")
        shape = windows.frame_shape
        if self.frame_rank is None:
            if len(shape) not in (1, 3):
                raise InputError(f"{what} has frames of shape {shape}; expected images "
                                 f"(C, H, W) or taxel vectors (N,)")
        elif len(shape) != self.frame_rank:
            kind = "images (C, H, W)" if self.frame_rank == 3 else "taxel vectors (N,)"
            raise InputError(f"{self.name} classifies {kind}; {what} has frames of shape "
                             f"{shape}")

    def _resolve_classes(self, train: Windows, val: Windows | None,
                         n_classes: int | None) -> int:
        seen = int(train.labels.max()) + 1
        if val is not None and len(val):
            seen = max(seen, int(val.labels.max()) + 1)
        if int(train.labels.min()) < 0:
            raise InputError("labels must be 0 .. K-1; found a negative label")
        k = self.classes if self.classes is not None else n_classes
        if k is None:
            k = seen
        if k < 2:
            raise InputError(f"need at least 2 classes, got K = {k}")
        if seen > k:
            raise InputError(f"labels go up to {seen - 1} but only {k} classes were declared")
        return int(k)

    def _check_input(self, x: Any) -> Windows | np.ndarray:
        if not self.fitted:
            raise RuntimeError(f"{self.name} is not fitted: call fit() or load a model first")
        assert self.frame_shape is not None
        rank = len(self.frame_shape)
        if isinstance(x, Windows):
            shape = x.frame_shape
        else:
            x = np.asarray(x, dtype=np.float32)
            if x.ndim != 2 + rank:
                raise InputError(f"expected windows (B, L, *frame) of rank {2 + rank}, "
                                 f"got shape {x.shape}")
            shape = x.shape[2:]
        # Images may come at any size (the network resizes); channels/taxels must match.
        fixed = self.frame_shape if rank == 1 else self.frame_shape[:1]
        if tuple(shape[:len(fixed)]) != tuple(fixed) or len(shape) != rank:
            raise InputError(f"frames of shape {tuple(shape)} do not match the trained "
                             f"frame shape {self.frame_shape}")
        return x

    # -- the public interface ----------------------------------------------------------

    def fit(self, train: Windows, val: Windows | None = None, *, seed: int,
            device: str = "cpu", progress: ProgressFn | None = None,
            n_classes: int | None = None) -> dict[str, Any]:
        raise NotImplementedError

    def predict_proba(self, x: Windows | np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def predict(self, x: Windows | np.ndarray) -> np.ndarray:
        """Class indices ``(B,)`` int64 (the most probable class of each window)."""
        return self.predict_proba(x).argmax(axis=1).astype(np.int64)

    def save(self, path, metadata: dict[str, Any] | None = None):
        """Write weights and metadata to ``path`` (safetensors; see :mod:`.io`)."""
        return save_model(self, path, metadata or {})

    def preflight(self, device: str) -> None:
        """Refuse, before any work, a ``device`` this machine lacks and bad training
        memory settings in the environment (see ``preflight`` in
        :data:`tactbench.contracts.CLASSIFIER`)."""
        bank_budget_bytes()
        loader_workers(None)
        if device.strip().lower() != "cpu":
            select_device(device)

    # -- what io needs -----------------------------------------------------------------

    def export(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """``(config, tensors)``: JSON-ready configuration and named torch tensors."""
        raise NotImplementedError

    @classmethod
    def _restore(cls, config: dict[str, Any], tensors: dict[str, Any]) -> "SequenceClassifier":
        raise NotImplementedError

    def _base_config(self) -> dict[str, Any]:
        return {"options": self.options(), "n_classes": self.n_classes,
                "frame_shape": list(self.frame_shape or ()), "L": self.L,
                "fit_report": self.fit_report}


#: Upper bounds of the training options, checked when a classifier is built (at planning,
#: before any encoding): beyond them a run is a typo (``epochs=1e9``), not a study.
MAX_EPOCHS = 100_000
MAX_BATCH = 10_000_000


@dataclass(eq=False, repr=False, kw_only=True)
class TorchSequenceClassifier(SequenceClassifier):
    """A torch network trained with :func:`tactbench.classifiers.training.train_loop`.

    Subclasses write :meth:`_build_net` (and may add options).
    """

    epochs: int = 4
    batch_size: int = 64
    windows_per_epoch: int = 8000  # windows sampled per epoch; 0 = every window
    optimizer: str = "adam"  # adam, adamw or sgd
    lr: float = 3e-3
    momentum: float = 0.0  # SGD only
    weight_decay: float = 0.0
    schedule: str = "cosine"  # cosine or constant
    hidden: int = 64  # LSTM hidden units
    fc: int = 256  # the fully connected layer after the LSTM
    dropout: float = 0.3
    amp: bool | None = None  # mixed precision; None: on for CUDA only
    eval_batch_size: int = 256
    #: After training, re-estimate BatchNorm running statistics on this many training
    #: batches with the final weights (0: off). Needed when BN's momentum is small and
    #: training short (EfficientNet's 0.01 over ~100 steps leaves the running statistics
    #: near their initial values, and every test window lands in one class).
    bn_recalibration_batches: int = 0
    #: Windows drawn in runs that share frames, each distinct frame of a batch encoded
    #: once (the LSTM still sees every window). ``K ≥ 2``: runs of up to K consecutive
    #: windows of one sequence (starts in ``[jK, jK + K)``: K windows over ``K + L - 1``
    #: frames instead of ``K·L``); ``1``: runs of up to L windows; 0 (default): windows
    #: drawn independently, every frame of every window encoded. At L = 1 windows share
    #: no frame and nothing changes. It changes the sampling (a batch holds fewer, longer
    #: stretches of sequences), so it is part of a cell's identity. See
    #: docs/classifiers.md for what it does to accuracy.
    shared_features: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        # Checked, not converted: options() goes into cache keys and result rows as given.
        # epochs=0 would train nothing and report an untrained model's guesses as a cell
        check_positive_int(self.epochs, "epochs", maximum=MAX_EPOCHS)
        check_positive_int(self.batch_size, "batch_size", maximum=MAX_BATCH)
        check_positive_int(self.windows_per_epoch, "windows_per_epoch (0: every window)",
                           minimum=0, maximum=MAX_BATCH)
        check_choice(str(self.optimizer).lower(), "optimizer", OPTIMIZERS)
        check_positive_float(self.lr, "lr")
        check_positive_float(self.momentum, "momentum", allow_zero=True)
        check_positive_float(self.weight_decay, "weight_decay", allow_zero=True)
        check_choice(self.schedule, "schedule", SCHEDULES)
        check_positive_int(self.hidden, "hidden")
        check_positive_int(self.fc, "fc")
        if check_positive_float(self.dropout, "dropout", allow_zero=True) >= 1:
            raise InputError(f"dropout must lie in [0, 1), got {self.dropout}")
        if self.amp is not None and not isinstance(self.amp, bool):
            raise InputError(f"amp must be true, false or none, got {self.amp!r}")
        check_positive_int(self.eval_batch_size, "eval_batch_size")
        check_positive_int(self.bn_recalibration_batches, "bn_recalibration_batches (0: off)",
                           minimum=0)
        check_positive_int(self.shared_features,
                           "shared_features (0: off, 1: runs of L windows, K: runs of K)",
                           minimum=0, maximum=MAX_BATCH)
        self.net = None
        self._device = None
        self._precision = None

    # -- for subclasses ----------------------------------------------------------------

    def _build_net(self, frame_shape: tuple[int, ...], n_classes: int, *,
                   pretrained: bool) -> Any:
        raise NotImplementedError

    def _normalization(self, frames) -> tuple[Any, Any]:
        """Per-channel (images) or per-taxel (vectors) mean and std of prepared frames."""
        dims = [0] + list(range(2, frames.ndim))
        return frames.mean(dim=dims), frames.std(dim=dims)

    # -- fit ---------------------------------------------------------------------------

    def fit(self, train: Windows, val: Windows | None = None, *, seed: int,
            device: str = "cpu", progress: ProgressFn | None = None,
            n_classes: int | None = None) -> dict[str, Any]:
        """Train on ``train`` (optionally reporting accuracy on ``val`` every epoch).

        Returns the fit report (:class:`tactbench.classifiers.training.FitReport` as a dict, plus
        anything the classifier adds). A keyboard interrupt raises
        :class:`tactbench.classifiers.training.TrainingInterrupted` with the model usable.
        """
        import torch

        self._check_windows(train, "train")
        if val is not None:
            self._check_windows(val, "val")
            if val.frame_shape[:1] != train.frame_shape[:1]:
                raise InputError(f"val frames {val.frame_shape} do not match train frames "
                                 f"{train.frame_shape}")
        k = self._resolve_classes(train, val, n_classes)
        dev = select_device(device)
        precision = precision_for(dev, self.amp)
        report = FitReport(classifier=self.name, seed=int(seed), device=str(dev),
                           amp=precision.enabled, n_classes=k, options=self.options())
        forked = [dev.index or 0] if dev.type == "cuda" else []
        with torch.random.fork_rng(devices=forked):
            torch.manual_seed(derive_seed(seed, self.name, "init"))
            self.L = train.L  # a head over a fixed window length (concat) is built for it
            net = self._build_net(tuple(train.frame_shape), k, pretrained=True)
            with torch.no_grad():
                self._set_normalization(net, train, seed)
            get_batch, load_batches = self._batches(net, train, dev, report)
            evaluate = None
            if val is not None:
                def evaluate() -> float:
                    return float((self.predict(val) == val.labels).mean())
            net.to(dev)
            self.net = net
            self.n_classes, self.frame_shape = k, tuple(train.frame_shape)
            self._device, self._precision = dev, precision
            try:
                train_loop(net, get_batch, load_batches=load_batches,
                           n_windows=len(train), report=report,
                           epochs=self.epochs, batch_size=self.batch_size,
                           windows_per_epoch=self.windows_per_epoch, optimizer=self.optimizer,
                           lr=self.lr, momentum=self.momentum, weight_decay=self.weight_decay,
                           schedule=self.schedule, device=dev, precision=precision,
                           progress=progress, evaluate=evaluate,
                           groups=self._runs(train), **self._loop_options())
            except TrainingInterrupted as exc:
                self.fit_report = self._finish_report(exc.report)
                raise
            except BaseException:
                # A failed fit leaves no half-trained model that looks fitted.
                self.net, self.n_classes = None, None
                raise
            if self.bn_recalibration_batches > 0:
                self._recalibrate_batchnorm(net, get_batch, len(train), seed)
        self.fit_report = self._finish_report(report)
        return dict(self.fit_report)

    def estimate_seconds(self, **shapes: Any) -> float:
        """Seconds one cell takes on one thread, timed here on a few steps
        (:func:`tactbench.classifiers.costs.estimate_seconds`: its keyword arguments)."""
        return estimate_seconds(self, **shapes)

    def _sharing(self, L: int) -> bool:
        """Whether training shares frames between windows (only overlapping ones can)."""
        return bool(self.shared_features) and L >= 2

    def _runs(self, train: Windows) -> np.ndarray | None:
        """The run number per training window that ``shared_features`` draws by, or None."""
        if not self._sharing(train.L):
            return None
        return window_runs(train, None if self.shared_features == 1 else self.shared_features)

    def _batches(self, net, train: Windows, dev, report: FitReport):
        """``(get_batch, load_batches)`` of a fit (:func:`training_batches`): the hook a
        subclass overrides to train on something else (cached frozen features)."""
        return training_batches(train, net.prepare, dev, report,
                                share=self._sharing(train.L))

    def _recalibrate_batchnorm(self, net, get_batch, n_windows: int, seed: int) -> None:
        """BatchNorm statistics from the final weights, on seeded training batches
        (torch's ``update_bn``: cumulative average, momentum restored after)."""
        from torch.optim.swa_utils import update_bn

        rng = np.random.default_rng(derive_seed(seed, self.name, "batchnorm"))
        order = rng.permutation(n_windows)[:self.bn_recalibration_batches * self.batch_size]
        batches = (get_batch(np.sort(order[i:i + self.batch_size]))[0]
                   for i in range(0, len(order), self.batch_size))
        update_bn(batches, net)

    def _finish_report(self, report: FitReport) -> dict[str, Any]:
        out = report.as_dict()
        out.update(self._extra_report())
        return out

    def _extra_report(self) -> dict[str, Any]:
        return {}

    def _loop_options(self) -> dict[str, Any]:
        """Further keyword arguments of :func:`.training.train_loop` (label smoothing,
        augmentation, early stopping) that a subclass's options ask for."""
        return {}

    def _set_normalization(self, net, train: Windows, seed: int) -> None:
        """Mean and std of up to :data:`NORM_SAMPLE_FRAMES` seeded training frames after
        ``net.prepare``. The sampled frames are read a few sequences at a time and
        prepared as they come; the prepared sample is kept whole when it fits
        :data:`NORM_SAMPLE_BYTES`, else its statistics are merged chunk by chunk."""
        import torch

        rng = np.random.default_rng(derive_seed(seed, self.name, "normalize"))
        seqs = train.sequences
        lengths = np.array([s.shape[0] for s in seqs])
        total = int(lengths.sum())
        flat = np.sort(rng.choice(total, size=min(total, NORM_SAMPLE_FRAMES), replace=False))
        offsets = np.concatenate([[0], np.cumsum(lengths)])
        which = np.searchsorted(offsets, flat, side="right") - 1
        step = frames_per_chunk(train.frame_shape)

        def prepared_chunks():
            for lo in range(0, len(flat), step):
                frames = []
                w, t = which[lo:lo + step], flat[lo:lo + step] - offsets[which[lo:lo + step]]
                for i in np.unique(w):
                    ts = t[w == i]
                    if 2 * len(ts) >= ts[-1] - ts[0] + 1:  # dense: one read of the span
                        span = np.asarray(seqs[i][int(ts[0]):int(ts[-1]) + 1],
                                          dtype=np.float32)
                        frames.append(span[ts - ts[0]])
                    else:  # sparse: frame by frame
                        frames += [np.asarray(seqs[i][int(j):int(j) + 1], dtype=np.float32)
                                   for j in ts]
                yield net.prepare(torch.from_numpy(np.concatenate(frames)))

        probe = net.prepare(torch.zeros((1, *train.frame_shape)))
        if len(flat) * probe[0].numel() * 4 <= NORM_SAMPLE_BYTES:
            mean, std = self._normalization(torch.cat(list(prepared_chunks())))
        else:
            mean, std = streamed_mean_std(prepared_chunks())
        net.normalize.set(mean, std)

    # -- predict -----------------------------------------------------------------------

    def predict_proba(self, x: Windows | np.ndarray) -> np.ndarray:
        """Class probabilities ``(B, K)`` float32, in batches, without gradients.

        Overlapping windows of one sequence (every window of it, as the ``vote`` test
        window classifies) send each distinct frame of a batch through the frame encoder
        once (:func:`shares_at_inference`): in evaluation mode a frame's features do not
        depend on the other frames of its batch, so this is the same arithmetic up to
        float rounding, with up to ``L``× less CNN work.
        """
        import torch

        x = self._check_input(x)
        net, dev = self.net, self._device
        precision = self._precision or precision_for(dev, self.amp)
        share = shares_at_inference(x, net)
        was_training = net.training
        net.eval()
        out = []
        try:
            with torch.inference_mode():
                step = self._eval_step(x, net)
                for lo in range(0, len(x), step):
                    # read and resized in sub-batches: the raw batch is never whole
                    xb = read_windows(x, slice(lo, lo + step), net.prepare)
                    if share:
                        xb = share_frames(x, np.arange(lo, min(lo + step, len(x))), xb)
                    xb = xb.to(dev)
                    with precision.autocast(dev):
                        logits = net(xb)
                    out.append(torch.softmax(logits.float(), dim=1).cpu().numpy())
        finally:
            net.train(was_training)
        if not out:
            return np.zeros((0, self.n_classes), dtype=np.float32)
        return np.concatenate(out).astype(np.float32, copy=False)

    def _eval_step(self, x: Windows | np.ndarray, net) -> int:
        """Windows per forward pass: ``eval_batch_size``, fewer when that many prepared
        windows would exceed :data:`EVAL_INPUT_BYTES` (224-px inputs: ~3 MB a window,
        and the network's activations grow with them)."""
        if len(x) == 0:
            return self.eval_batch_size
        probe = read_windows(x, slice(0, 1), net.prepare)
        per_window = max(1, probe.numel() * probe.element_size())
        return max(1, min(self.eval_batch_size, EVAL_INPUT_BYTES // per_window))

    # -- save / load -------------------------------------------------------------------

    def export(self) -> tuple[dict[str, Any], dict[str, Any]]:
        if self.net is None:
            raise RuntimeError(f"{self.name} is not fitted: nothing to save")
        tensors = {k: v.detach().cpu() for k, v in self.net.state_dict().items()}
        return self._base_config(), tensors

    @classmethod
    def _restore(cls, config: dict[str, Any], tensors: dict[str, Any]) -> "TorchSequenceClassifier":
        import torch

        clf = cls(**config["options"])
        clf.n_classes = int(config["n_classes"])
        clf.frame_shape = tuple(int(s) for s in config["frame_shape"])
        clf.L = config.get("L")
        clf.fit_report = config.get("fit_report")
        net = clf._build_net(clf.frame_shape, clf.n_classes, pretrained=False)
        expected = net.state_dict()
        missing = sorted(set(expected) - set(tensors))
        unexpected = sorted(set(tensors) - set(expected))
        bad_shapes = [f"{k} {tuple(v.shape)} vs {tuple(expected[k].shape)}"
                      for k, v in tensors.items()
                      if k in expected and tuple(expected[k].shape) != tuple(v.shape)]
        if missing or unexpected or bad_shapes:
            raise InputError(f"weights do not fit a {cls.name} network with these options: "
                             f"missing {missing[:5]}, unexpected {unexpected[:5]}, "
                             f"other shape {bad_shapes[:5]}")
        net.load_state_dict(tensors, strict=True)
        net.eval()
        clf.net = net
        clf._device = torch.device("cpu")
        return clf

    def to(self, device: str) -> "TorchSequenceClassifier":
        """Move a fitted (or loaded) model to ``device`` for prediction."""
        dev = select_device(device)
        if self.net is not None:
            self.net.to(dev)
        self._device = dev
        self._precision = precision_for(dev, self.amp)
        return self

    # -- live classification: one frame at a time (see tactbench.contracts.CLASSIFIER) ---

    def frame_features(self, frame: np.ndarray):
        """One frame's features (a tensor on the model's device), from the frame encoder
        of the :class:`~tactbench.classifiers.nets.SequenceNet`; the network is put in
        evaluation mode (a live model only predicts)."""
        import torch

        net = self.net
        if net.training:
            net.eval()
        x = torch.from_numpy(np.ascontiguousarray(frame, dtype=np.float32))[None]
        if self._device is not None:
            x = x.to(self._device)
        with torch.inference_mode():
            return net.encoder(net.normalize(net.prepare(x)))[0]

    def window_proba(self, features: Sequence[Any]) -> np.ndarray:
        """Probabilities ``(n_classes,)`` of the window whose frames have ``features``
        (:meth:`frame_features`): the LSTM and head over them."""
        import torch

        net = self.net
        with torch.inference_mode():
            logits = net.classify(torch.stack(list(features))[None])
            return torch.softmax(logits.float(), dim=1)[0].cpu().numpy()


def n_params(module) -> int:
    return int(sum(p.numel() for p in module.parameters()))

