"""A cheap classical reference: logistic regression on pooled per-frame statistics.

Every table needs a floor: what a linear model gets from a few numbers per frame.
Per frame, per channel: mean, standard deviation, maximum, and the mean over a
``grid × grid`` partition of the image (for taxel vectors: over ``grid²``
consecutive groups of taxels). A window's features are its ``L`` frames'
features side by side, standardised with the training statistics; a
multinomial logistic regression with an L2 penalty is fitted by full-batch
L-BFGS in float64 (deterministic; no extra dependency, and it saves like the
other classifiers).

Memory: frames are read from the sequences a chunk at a time and reduced to their
features at once (``F`` numbers per frame). The window features ``(B, L × F)`` float64
are held whole when they fit the frame-bank budget
(:func:`tactbench.classifiers.batching.bank_budget_bytes`), as before; above it the
statistics, the loss and its gradient are accumulated over chunks of
:data:`FEATURE_CHUNK` windows, gathered from a bank of per-frame features (or, when even
that exceeds the budget, read from the sequences for each chunk).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from tactbench.classifiers.base import SequenceClassifier
from tactbench.classifiers.batching import (
    FrameBank,
    bank_budget_bytes,
    read_windows,
    streamed_mean_std,
)
from tactbench.classifiers.training import FitReport, ProgressFn, TrainingInterrupted, select_device
from tactbench.data.windows import Windows
from tactbench.errors import InputError, check_positive_float, check_positive_int

#: Windows per chunk when the window features are not held whole.
FEATURE_CHUNK = 4096


def frame_features(frames, grid: int):
    """``(N, C, H, W)`` or ``(N, n)`` float32 → ``(N, F)`` float32 pooled statistics.

    ``F = C × (3 + grid²)`` for images, ``3 + grid²`` for vectors. A blank frame
    gives all zeros.
    """
    import torch
    import torch.nn.functional as F

    x = frames if frames.ndim == 4 else frames[:, None, None, :]
    flat = x.flatten(2)
    stats = [flat.mean(2), flat.std(2, unbiased=False), flat.amax(2)]
    if frames.ndim == 4:
        pooled = F.adaptive_avg_pool2d(x, grid).flatten(1)
    else:
        pooled = F.adaptive_avg_pool1d(frames[:, None, :], grid * grid).flatten(1)
    return torch.cat(stats + [pooled], dim=1)


def _standardised(chunks: list[tuple[slice, Callable[[], Any]]]):
    """``(mean, std, z)`` of the window features in ``chunks`` (see
    ``PooledLogReg._feature_chunks``): per-feature mean and standard deviation (1 where
    a feature is constant), and ``z``, the standardised features, when they are one chunk
    held whole (None otherwise)."""
    import torch

    feats = None
    if len(chunks) == 1:
        feats = chunks[0][1]()
        mean, std = feats.mean(0), feats.std(0)
    else:
        mean, std = streamed_mean_std(read() for _, read in chunks)
    std = torch.where(std < 1e-9, torch.ones_like(std), std)
    return mean, std, None if feats is None else (feats - mean) / std

@dataclass(eq=False, repr=False, kw_only=True)
class PooledLogReg(SequenceClassifier):
    """Multinomial logistic regression on pooled per-frame features (images or taxel vectors)."""

    name = "logreg"
    frame_rank = None
    grid: int = 4  # image partition grid × grid (vectors: grid² taxel groups)
    l2: float = 1e-3  # penalty on the weights (not the biases), per training window
    max_iter: int = 200  # L-BFGS iterations

    def __post_init__(self) -> None:
        super().__post_init__()
        check_positive_int(self.grid, "grid")
        check_positive_float(self.l2, "l2", allow_zero=True)
        check_positive_int(self.max_iter, "max_iter")
        self.weight = None  # (K, D) float64 torch tensor
        self.bias = None
        self.feat_mean = None
        self.feat_std = None

    def _window_features(self, x: Windows | np.ndarray):
        """All window features ``(B, L × F)`` float64 at once."""
        import torch

        prepare = lambda t: frame_features(t, self.grid)  # noqa: E731
        with torch.no_grad():
            if isinstance(x, Windows):
                bank = FrameBank(x, prepare)
                feats = bank.frames[bank.index]
            else:
                t = torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))
                b, length = t.shape[:2]
                feats = prepare(t.reshape(b * length, *t.shape[2:])).reshape(b, length, -1)
        return feats.flatten(1).double()

    def _feature_chunks(self, x: Windows | np.ndarray) -> list[tuple[slice, Callable[[], Any]]]:
        """The window features as ``[(rows, read)]``: ``read()`` gives the features of
        ``rows``, ``(b, L × F)`` float64. One chunk of every window (exactly the
        features of :meth:`_window_features`) when they fit the frame-bank budget, else
        chunks of :data:`FEATURE_CHUNK` windows."""
        import torch

        n = len(x)
        frame_shape = x.frame_shape if isinstance(x, Windows) else tuple(x.shape[2:])
        length = x.L if isinstance(x, Windows) else x.shape[1]
        prepare = lambda t: frame_features(t, self.grid)  # noqa: E731
        n_feat = int(prepare(torch.zeros((1, *frame_shape))).shape[1])
        budget = bank_budget_bytes()
        if n * length * n_feat * 8 <= budget:
            return [(slice(0, n), lambda: self._window_features(x))]
        if isinstance(x, Windows) and FrameBank.nbytes(x, (n_feat,)) <= budget:
            with torch.no_grad():
                bank = FrameBank(x, prepare)

            def read(rows):
                return bank.frames[bank.index[rows]].flatten(1).double()
        else:
            def read(rows):
                with torch.no_grad():
                    return read_windows(x, rows, prepare).flatten(1).double()
        return [(slice(lo, min(n, lo + FEATURE_CHUNK)),
                 lambda rows=slice(lo, min(n, lo + FEATURE_CHUNK)): read(rows))
                for lo in range(0, n, FEATURE_CHUNK)]

    def fit(self, train: Windows, val: Windows | None = None, *, seed: int,
            device: str = "cpu", progress: ProgressFn | None = None,
            n_classes: int | None = None) -> dict[str, Any]:
        """Fit on all training windows (CPU; ``seed`` is recorded, the solver is
        deterministic). ``progress(done, max_iter, loss=...)`` per L-BFGS evaluation."""
        import torch
        import torch.nn.functional as F

        self._check_windows(train, "train")
        select_device(device)  # validate; the solve is small and runs on the CPU
        k = self._resolve_classes(train, val, n_classes)
        report = FitReport(classifier=self.name, seed=int(seed), device="cpu", amp=False,
                           n_classes=k, options=self.options(), train_windows=len(train))
        start = time.perf_counter()
        chunks = self._feature_chunks(train)
        y = torch.from_numpy(np.asarray(train.labels, dtype=np.int64))
        mean, std, z = _standardised(chunks)
        weight = torch.zeros((k, mean.shape[0]), dtype=torch.float64, requires_grad=True)
        bias = torch.zeros(k, dtype=torch.float64, requires_grad=True)
        opt = torch.optim.LBFGS([weight, bias], lr=1.0, max_iter=self.max_iter,
                                line_search_fn="strong_wolfe")
        calls = [0]
        n = len(train)

        def data_loss(w, b):
            """Mean cross-entropy over the training windows (backward done per chunk
            when they are not held whole; returns a float then)."""
            if z is not None:
                return F.cross_entropy(z @ w.T + b, y)
            total = 0.0
            for rows, read in chunks:
                part = F.cross_entropy(((read() - mean) / std) @ w.T + b, y[rows],
                                       reduction="sum") / n
                if part.requires_grad:
                    part.backward()
                total += float(part.detach())
            return total

        def closure():
            opt.zero_grad()
            penalty = 0.5 * self.l2 * (weight ** 2).sum()
            if z is not None:
                loss = data_loss(weight, bias) + penalty
                loss.backward()
            else:
                penalty.backward()
                loss = torch.tensor(data_loss(weight, bias) + float(penalty.detach()),
                                    dtype=torch.float64)
            calls[0] += 1
            if progress is not None:
                progress(min(calls[0], self.max_iter), self.max_iter, epoch=1, epochs=1,
                         loss=float(loss.detach()))
            return loss

        self.n_classes, self.frame_shape, self.L = k, tuple(train.frame_shape), train.L
        self.feat_mean, self.feat_std = mean, std
        try:
            opt.step(closure)
        except KeyboardInterrupt:
            self.weight, self.bias = weight.detach(), bias.detach()
            report.interrupted = True
            report.train_seconds = time.perf_counter() - start
            self.fit_report = report.as_dict()
            raise TrainingInterrupted(report) from None
        self.weight, self.bias = weight.detach(), bias.detach()
        with torch.no_grad():
            final = data_loss(self.weight, self.bias)
        report.epochs, report.steps, report.windows_seen = 1, calls[0], len(train)
        report.final_loss = float(final)
        report.epoch_losses = [report.final_loss]
        if val is not None and len(val):
            report.val_accuracy = [float((self.predict(val) == val.labels).mean())]
        report.train_seconds = time.perf_counter() - start
        report.windows_per_second = len(train) / max(report.train_seconds, 1e-9)
        self.fit_report = report.as_dict()
        return dict(self.fit_report)

    def predict_proba(self, x: Windows | np.ndarray) -> np.ndarray:
        import torch

        x = self._check_input(x)
        if isinstance(x, np.ndarray) and len(x) == 0:
            return np.zeros((0, self.n_classes), dtype=np.float32)
        if isinstance(x, np.ndarray) and x.shape[2:] != self.frame_shape:
            raise InputError(f"logreg needs frames of the trained shape {self.frame_shape}, "
                             f"got {x.shape[2:]}")
        if isinstance(x, Windows) and x.frame_shape != self.frame_shape:
            raise InputError(f"logreg needs frames of the trained shape {self.frame_shape}, "
                             f"got {x.frame_shape}")
        with torch.no_grad():
            parts = []
            for _, read in self._feature_chunks(x):
                z = (read() - self.feat_mean) / self.feat_std
                parts.append(torch.softmax(z @ self.weight.T + self.bias, dim=1))
            p = parts[0] if len(parts) == 1 else torch.cat(parts)
        return p.float().numpy()

    def export(self):
        if self.weight is None:
            raise RuntimeError("logreg is not fitted: nothing to save")
        tensors = {"weight": self.weight, "bias": self.bias, "feat_mean": self.feat_mean,
                   "feat_std": self.feat_std}
        return self._base_config(), tensors

    @classmethod
    def _restore(cls, config, tensors):
        clf = cls(**config["options"])
        clf.n_classes = int(config["n_classes"])
        clf.frame_shape = tuple(int(s) for s in config["frame_shape"])
        clf.L = config.get("L")
        clf.fit_report = config.get("fit_report")
        need = {"weight", "bias", "feat_mean", "feat_std"}
        if set(tensors) != need:
            raise InputError(f"expected tensors {sorted(need)}, found {sorted(tensors)}")
        w = tensors["weight"]
        if w.ndim != 2 or w.shape[0] != clf.n_classes or tensors["bias"].shape != (clf.n_classes,) \
                or tensors["feat_mean"].shape != (w.shape[1],):
            raise InputError(f"tensor shapes do not fit {clf.n_classes} classes: weight "
                             f"{tuple(w.shape)}, bias {tuple(tensors['bias'].shape)}")
        clf.weight, clf.bias = w.double(), tensors["bias"].double()
        clf.feat_mean, clf.feat_std = tensors["feat_mean"].double(), tensors["feat_std"].double()
        return clf
