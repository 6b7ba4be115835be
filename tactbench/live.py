"""Live classification: sweeps in, class probabilities out, one prediction per sweep.

The pipeline per sweep (raw taxel values ``(N,)``):

1. normalise to pressure in [0, 1] with the training data's offset and scale;
2. image it with the training layout and pixel size (``Imager``), clip to [0, 1];
3. encode it *once*, against the previous image (:class:`IncrementalEncoder`):
   every built-in encoder's frame ``k`` depends only on ``I_k`` and ``I_{k-1}``,
   so frame ``k`` of the full sequence equals frame 1 of the pair
   ``[I_{k-1}, I_k]`` (a test checks this for every registered encoder);
4. keep the last ``L`` encoded frames and ask the classifier for
   ``predict_proba`` on that window ``(1, L, C, H, W)``. For the built-in torch
   classifiers (per-frame CNN → LSTM) each frame's CNN features are also kept,
   so a prediction runs the CNN on the new frame only and the LSTM over the
   window — used only when a check at start shows it gives the same
   probabilities as ``predict_proba``.

Classifiers on taxel vectors (``frame_rank == 1``) skip steps 2–3 and see the
normalised vectors ``(L, N)`` (missing readings as 0, as in training).

What a model file must carry for this (its ``metadata``, see :func:`live_metadata`):
``classes``, ``encoder`` (spec), ``length`` (L), ``imaging`` (``pixel_mm``,
``method``), ``layout`` (``ids``, ``positions`` in mm, ``bounds``),
``normalisation`` (``offset`` scalar or per taxel, ``scale``) and ``taxel_ids``
(the order of the values the classifier was trained on).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from tactbench.errors import InputError


# ------------------------------------------------------------------ encoding
def encode_next(encoder: Any, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
    """Encode frame ``curr`` (H, W) against ``prev`` (H, W): float32 ``(C, H, W)``.

    Flow encoders (a public ``flow(prev, curr)`` and ``max_flow``/``min_magnitude``)
    compute one flow field for the pair; any other encoder encodes the two-frame
    sequence ``[prev, curr]`` and keeps frame 1.
    """
    flow = getattr(encoder, "flow", None)
    if callable(flow) and hasattr(encoder, "max_flow") and hasattr(encoder, "min_magnitude"):
        from tactbench.encoders.base import check_sequence

        pair = check_sequence(np.stack([prev, curr]))
        try:
            from tactbench.encoders.flow import flow_to_channels

            f = flow(pair[:1], pair[1:])
            return flow_to_channels(pair[1:], f, max_flow=encoder.max_flow,
                                    min_magnitude=encoder.min_magnitude)[0]
        except (ImportError, TypeError, AttributeError):
            pass  # the flow encoders' helpers changed shape: take the general path
    return encoder.encode(np.stack([prev, curr]))[1]


class IncrementalEncoder:
    """Encode a stream of images one at a time, each against the one before.

    The image before the first is all zeros, as in the encoders' contract, so the
    stream's encodings equal ``encoder.encode(all_images)`` frame by frame.
    """

    def __init__(self, encoder: Any) -> None:
        self.encoder = encoder
        self._prev: np.ndarray | None = None

    def push(self, image: np.ndarray) -> np.ndarray:
        """Encode ``image`` float32 ``(H, W)`` in [0, 1] → ``(C, H, W)``."""
        image = np.asarray(image, dtype=np.float32)
        prev = self._prev if self._prev is not None else np.zeros_like(image)
        if prev.shape != image.shape:
            raise InputError(f"image shape changed from {prev.shape} to {image.shape}")
        out = encode_next(self.encoder, prev, image)
        self._prev = image
        return out

    def reset(self) -> None:
        self._prev = None


# ------------------------------------------------------------------ the model
@dataclass
class LiveModel:
    """A trained classifier and everything needed to feed it raw sweeps.

    ``offset`` is a scalar or ``(N,)`` and ``scale`` a scalar: pressure is
    ``clip((raw - offset) / scale, 0, 1)``. ``imager`` is ``None`` for
    classifiers of taxel vectors (``encoder`` then too).
    """

    clf: Any
    classes: list[str]
    length: int
    taxel_ids: np.ndarray
    offset: Any = 0.0
    scale: float = 65535.0
    imager: Any = None
    encoder: Any = None
    encoder_spec: str = "raw"
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def uses_images(self) -> bool:
        return self.imager is not None

    def normalise(self, values: np.ndarray) -> np.ndarray:
        out = (np.asarray(values, dtype=np.float32) - self.offset) / np.float32(self.scale)
        return np.clip(out, 0.0, 1.0, out=out).astype(np.float32, copy=False)

    @classmethod
    def from_file(cls, path: str | Path, *, layout: Any = None, encoder: str | None = None,
                  length: int | None = None, pixel_mm: float | None = None,
                  registry: Any = None) -> "LiveModel":
        """Load a model file saved with :func:`live_metadata`'s metadata.

        Keyword arguments override what the metadata says (``layout`` is a
        :class:`~tactbench.data.layout.TaxelLayout` or a layout file).
        """
        from tactbench.classifiers.io import load_model

        if registry is None:
            from tactbench.plugins import load_registry

            registry = load_registry()
        clf, meta = load_model(path, registry=registry)
        return cls.from_parts(clf, meta, layout=layout, encoder=encoder, length=length,
                              pixel_mm=pixel_mm, registry=registry, where=str(path))

    @classmethod
    def from_parts(cls, clf: Any, meta: dict[str, Any], *, layout: Any = None,
                   encoder: str | None = None, length: int | None = None,
                   pixel_mm: float | None = None, registry: Any = None,
                   where: str = "model") -> "LiveModel":
        from tactbench.errors import TactbenchError

        def need(key: str, *alts: str) -> Any:
            for k in (key, *alts):
                if meta.get(k) is not None:
                    return meta[k]
            raise TactbenchError(f"{where}: the model's metadata has no '{key}'; live "
                                 f"classification needs it (see tactbench.live.live_metadata)")

        classes = [str(c) for c in need("classes")]
        L = int(length if length is not None else
                (meta.get("length") or meta.get("L") or getattr(clf, "length", None) or 0))
        if L < 1:
            raise TactbenchError(f"{where}: window length L unknown; give --length")
        norm = meta.get("normalisation") or {}
        offset = norm.get("offset", 0.0)
        offset = np.asarray(offset, np.float32) if isinstance(offset, list) else float(offset)
        scale = float(norm.get("scale", 65535.0))
        frame_rank = getattr(clf, "frame_rank", 3)
        lay = _layout(layout if layout is not None else meta.get("layout"), where)
        ids = meta.get("taxel_ids")
        ids = (np.asarray(ids, np.int64) if ids is not None
               else (lay.ids if lay is not None else None))
        if ids is None:
            raise TactbenchError(f"{where}: the model's metadata has neither 'taxel_ids' nor "
                                 f"a 'layout'; give --layout")
        if isinstance(offset, np.ndarray) and offset.shape != ids.shape:
            raise TactbenchError(f"{where}: normalisation offset has {offset.size} values for "
                                 f"{ids.size} taxels")
        model = cls(clf=clf, classes=classes, length=L, taxel_ids=ids, offset=offset,
                    scale=scale, info=dict(meta))
        if frame_rank == 1:
            return model
        if lay is None:
            raise TactbenchError(f"{where}: an image classifier needs the taxel layout; "
                                 f"the metadata has none: give --layout")
        from tactbench.data.imaging import Imager

        imaging = meta.get("imaging") or {}
        px = float(pixel_mm if pixel_mm is not None else imaging.get("pixel_mm", 1.0))
        if lay.n_taxels != ids.size or not np.array_equal(lay.ids, ids):
            lay = lay.subset(ids)
        model.imager = Imager(lay, pixel_mm=px, method=imaging.get("method", "linear"))
        model.encoder_spec = str(encoder or need("encoder"))
        if registry is None:
            from tactbench.plugins import load_registry

            registry = load_registry()
        model.encoder = registry.build("encoder", model.encoder_spec)
        shape = getattr(clf, "frame_shape", None)
        expected = (len(model.encoder.channels), *model.imager.shape)
        if shape is not None and tuple(shape) != expected:
            raise TactbenchError(f"{where}: the classifier expects frames {tuple(shape)}, "
                                 f"but encoder '{model.encoder_spec}' on this layout at "
                                 f"{px:g} mm gives {expected}")
        return model


def _layout(obj: Any, where: str) -> Any:
    if obj is None:
        return None
    from tactbench.data.layout import TaxelLayout, load_layout

    if isinstance(obj, TaxelLayout):
        return obj
    if isinstance(obj, (str, Path)):
        return load_layout(obj)
    if isinstance(obj, dict) and "ids" in obj and "positions" in obj:
        bounds = obj.get("bounds")
        return TaxelLayout(ids=np.asarray(obj["ids"], np.int64),
                           positions=np.asarray(obj["positions"], np.float64),
                           bounds=tuple(bounds) if bounds else None,
                           name=str(obj.get("name", "")))
    raise InputError(f"{where}: cannot read the layout from {type(obj).__name__}")


def live_metadata(dataset: Any, *, encoder: str, length: int, pixel_mm: float,
                  method: str = "linear") -> dict[str, Any]:
    """The metadata to save with a model so ``tactbench live`` can use it.

    ``dataset`` is the :class:`tactbench.data.recording.Dataset` the model was
    trained on (its classes, layout and normalisation are recorded).
    """
    offset, scale = dataset.normalisation_params()
    layout = dataset.layout
    meta: dict[str, Any] = {
        "classes": list(dataset.classes), "encoder": encoder, "length": int(length),
        "imaging": {"pixel_mm": float(pixel_mm), "method": method},
        "taxel_ids": [int(i) for i in dataset.taxel_ids],
        "normalisation": {"spec": dataset.normalisation.spec,
                          "offset": (np.asarray(offset).astype(float).tolist()
                                     if np.ndim(offset) else float(offset)),
                          "scale": float(scale)},
        "dataset": getattr(dataset, "name", ""),
    }
    if layout is not None:
        meta["layout"] = {"ids": [int(i) for i in layout.ids],
                          "positions": np.asarray(layout.positions).tolist(),
                          "bounds": list(layout.bounds), "name": layout.name}
    return meta


# ------------------------------------------------------------------ cached features
class _FeatureWindow:
    """Per-frame CNN features kept across predictions (each frame goes through the CNN once).

    The built-in torch classifiers are "frame encoder → LSTM over the window → head"
    (:class:`tactbench.classifiers.nets.SequenceNet`): only the LSTM and head need the
    whole window. This is used only after :meth:`check` has shown, on the loaded model,
    that it gives the same probabilities as ``predict_proba``; otherwise the live loop
    calls ``predict_proba`` on the whole window.
    """

    def __init__(self, clf: Any, length: int) -> None:
        self.clf = clf
        self.net = clf.net
        self.net.eval()  # a live model only predicts (batch norm, dropout in eval mode)
        self.feats: deque[Any] = deque(maxlen=length)
        self.length = length

    @staticmethod
    def supported(clf: Any) -> bool:
        net = getattr(clf, "net", None)
        return all(hasattr(net, a) for a in ("prepare", "normalize", "encoder", "lstm", "head"))

    def features(self, frame: np.ndarray) -> Any:
        import torch

        x = torch.from_numpy(np.ascontiguousarray(frame, dtype=np.float32))[None]
        dev = getattr(self.clf, "_device", None)
        if dev is not None:
            x = x.to(dev)
        net = self.net
        with torch.inference_mode():
            return net.encoder(net.normalize(net.prepare(x)))[0]

    def push(self, frame: np.ndarray) -> None:
        self.feats.append(self.features(frame))

    def clear(self) -> None:
        self.feats.clear()

    def proba(self, padded_blank: Any = None) -> np.ndarray:
        """Probabilities for the window (padded with blank-frame features to L)."""
        import torch

        feats = list(self.feats)
        if len(feats) < self.length:
            feats += [padded_blank] * (self.length - len(feats))
        net = self.net
        with torch.inference_mode():
            out, _ = net.lstm(torch.stack(feats)[None])
            logits = net.head(out[:, -1])
            return torch.softmax(logits.float(), dim=1)[0].cpu().numpy()

    def check(self, frame_shape: tuple[int, ...], seed: int = 0) -> bool:
        """Whether this path matches ``predict_proba`` on a random window (then use it)."""
        rng = np.random.default_rng(seed)
        window = rng.random((self.length, *frame_shape), dtype=np.float32)
        try:
            for f in window:
                self.push(f)
            ours = self.proba()
            theirs = np.asarray(self.clf.predict_proba(window[None]))[0]
        except Exception:
            return False
        finally:
            self.clear()
        return ours.shape == theirs.shape and bool(np.allclose(ours, theirs, atol=1e-5))


# ------------------------------------------------------------------ the loop
@dataclass(frozen=True)
class Prediction:
    """One prediction: after the sweep at ``timestamp`` (s, the sensor's clock)."""

    timestamp: float
    label: str
    confidence: float
    probabilities: np.ndarray  # (K,) float32
    frames: int  # sweeps seen so far
    latency_ms: float  # from receiving the sweep to the prediction, in this process
    missing: int = 0  # taxels missing from this sweep
    frame_ms: float = 0.0  # of latency_ms: normalising, imaging and encoding the sweep

    def to_dict(self, classes: list[str]) -> dict[str, Any]:
        return {"timestamp": self.timestamp, "label": self.label,
                "confidence": round(self.confidence, 6),
                "probabilities": {c: round(float(p), 6)
                                  for c, p in zip(classes, self.probabilities)},
                "frames": self.frames, "latency_ms": round(self.latency_ms, 3),
                "frame_ms": round(self.frame_ms, 3), "missing": self.missing}


class LiveClassifier:
    """Rolling window of the model's ``L`` frames over a stream of sweeps.

    Parameters
    ----------
    model : LiveModel
    warmup : {"wait", "pad"}
        Before ``L`` sweeps have arrived: ``wait`` predicts nothing, ``pad``
        predicts on the frames so far padded with blank frames at the end (as
        the study's test windows are).
    """

    def __init__(self, model: LiveModel, *, warmup: str = "wait",
                 cache_features: bool = True) -> None:
        if warmup not in ("wait", "pad"):
            raise InputError(f"warmup must be 'wait' or 'pad', got {warmup!r}")
        self.model = model
        self.warmup = warmup
        self.encoder = IncrementalEncoder(model.encoder) if model.uses_images else None
        self.window: deque[np.ndarray] = deque(maxlen=model.length)
        self.frames = 0
        self._features: _FeatureWindow | None = None
        self._blank: Any = None
        if cache_features and _FeatureWindow.supported(model.clf):
            shape = getattr(model.clf, "frame_shape", None)
            fw = _FeatureWindow(model.clf, model.length)
            if shape is not None and fw.check(tuple(shape)):
                self._features = fw
                self._blank = fw.features(np.zeros(shape, np.float32))

    @property
    def caches_features(self) -> bool:
        """Whether each frame's CNN features are computed once and kept (see ``_FeatureWindow``)."""
        return self._features is not None

    def reset(self) -> None:
        self.window.clear()
        if self.encoder is not None:
            self.encoder.reset()
        if self._features is not None:
            self._features.clear()
        self.frames = 0

    def frame(self, values: np.ndarray) -> np.ndarray:
        """One sweep's raw values ``(N,)`` → the classifier's frame (encoded image or vector)."""
        m = self.model
        values = np.asarray(values, dtype=np.float32)
        if values.shape != m.taxel_ids.shape:
            raise InputError(f"sweep has {values.size} values, the model {m.taxel_ids.size} "
                             f"taxels")
        pressure = m.normalise(values)
        if not m.uses_images:
            return np.nan_to_num(pressure, nan=0.0)
        image = m.imager.apply(pressure)
        np.clip(image, 0.0, 1.0, out=image)
        return self.encoder.push(image)

    def push(self, values: np.ndarray, timestamp: float = 0.0, *,
             received: float | None = None, missing: int = 0) -> Prediction | None:
        """Add one sweep; returns a prediction once the window allows one.

        ``received`` is the ``time.perf_counter()`` at which the sweep arrived
        (default: now); the prediction's ``latency_ms`` counts from there.
        """
        received = time.perf_counter() if received is None else received
        t0 = time.perf_counter()
        frame = self.frame(values)
        self.window.append(frame)
        frame_ms = 1e3 * (time.perf_counter() - t0)
        if self._features is not None:
            self._features.push(frame)
        self.frames += 1
        L = self.model.length
        if len(self.window) < L and self.warmup == "wait":
            return None
        if self._features is not None:
            probs = self._features.proba(self._blank)
        else:
            batch = np.zeros((1, L, *self.window[0].shape), dtype=np.float32)
            batch[0, :len(self.window)] = np.stack(self.window)
            probs = np.asarray(self.model.clf.predict_proba(batch))[0]
        k = int(np.argmax(probs))
        return Prediction(timestamp=float(timestamp), label=self.model.classes[k],
                          confidence=float(probs[k]), probabilities=probs,
                          frames=self.frames,
                          latency_ms=1e3 * (time.perf_counter() - received), missing=missing,
                          frame_ms=frame_ms)

    def run(self, frames: Iterable[Any], *,
            on_prediction: Callable[[Prediction], None] | None = None) -> Iterator[Prediction]:
        """Predictions for a sensor's frames (objects with ``timestamp`` and ``values``)."""
        for frame in frames:
            received = time.perf_counter()
            pred = self.push(frame.values, frame.timestamp, received=received,
                             missing=int(getattr(frame, "missing", 0)))
            if pred is not None:
                if on_prediction is not None:
                    on_prediction(pred)
                yield pred
