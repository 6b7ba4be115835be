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

What a model file must carry for this (its ``metadata``, see
:func:`tactbench.classifiers.io.live_metadata`):
``classes``, ``encoder`` (spec), ``L`` (the window length), ``imaging`` (``pixel_mm``,
``method``), ``layout`` (``ids``, ``positions`` in mm, ``bounds``),
``normalisation`` (``offset`` scalar or per taxel, ``scale``) and ``taxel_ids``
(the order of the values the classifier was trained on).

A sensor whose taxels come in another order is re-indexed to the model's
(:meth:`LiveClassifier.run` with the sensor's ``taxel_ids``, :func:`reorder_index`).
"""

from __future__ import annotations

import itertools
import math
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np

from tactbench.budget import check_budget
from tactbench.classifiers.io import load_model
from tactbench.contracts import CLASSIFIER, FRAME, SENSOR
from tactbench.data.imaging import Imager
from tactbench.data.layout import TaxelLayout
from tactbench.data.layout_io import layout_from_dict, load_layout
from tactbench.encoders.base import check_sequence
from tactbench.encoders.flow import flow_to_channels, is_flow_encoder
from tactbench.errors import (
    InputError,
    TactbenchError,
    check_positive_float,
    check_positive_int,
)
from tactbench.plugins import load_registry


# ------------------------------------------------------------------ encoding
def encode_next(encoder: Any, prev: np.ndarray, curr: np.ndarray) -> np.ndarray:
    """Encode frame ``curr`` (H, W) against ``prev`` (H, W): float32 ``(C, H, W)``.

    Flow encoders (:func:`~tactbench.encoders.flow.is_flow_encoder`) compute one flow
    field for the pair; any other encoder encodes the two-frame sequence
    ``[prev, curr]`` and keeps frame 1.
    """
    if is_flow_encoder(encoder):
        pair = check_sequence(np.stack([prev, curr]))
        flow = encoder.flow(pair[:1], pair[1:])
        return flow_to_channels(pair[1:], flow, max_flow=encoder.max_flow,
                                min_magnitude=encoder.min_magnitude)[0]
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
    L: int
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
                  L: int | None = None, pixel_mm: float | None = None,
                  registry: Any = None) -> "LiveModel":
        """Load a model file saved with :func:`~tactbench.classifiers.io.live_metadata`'s
        metadata.

        Keyword arguments override what the metadata says (``layout`` is a
        :class:`~tactbench.data.layout.TaxelLayout` or a layout file).
        """
        if registry is None:
            registry = load_registry()
        clf, meta = load_model(path, registry=registry)
        return cls.from_parts(clf, meta, layout=layout, encoder=encoder, L=L,
                              pixel_mm=pixel_mm, registry=registry, where=str(path))

    @classmethod
    def from_parts(cls, clf: Any, meta: dict[str, Any], *, layout: Any = None,
                   encoder: str | None = None, L: int | None = None,
                   pixel_mm: float | None = None, registry: Any = None,
                   where: str = "model") -> "LiveModel":
        """The live model of a loaded classifier and its metadata (see the module
        docstring for the keys); keyword arguments override the metadata, ``where``
        (the file) starts every error message."""
        def need(key: str, *alts: str) -> Any:
            for k in (key, *alts):
                if meta.get(k) is not None:
                    return meta[k]
            raise TactbenchError(f"{where}: the model's metadata has no '{key}'; live "
                                 f"classification needs it (see "
                                 f"tactbench.classifiers.io.live_metadata)")

        classes = need("classes")
        if not isinstance(classes, list) or not classes:
            raise TactbenchError(f"{where}: the metadata's 'classes' must be a list of names")
        classes = [str(c) for c in classes]
        outputs = CLASSIFIER.get(clf, "n_classes")
        if outputs is not None and len(classes) != outputs:
            raise TactbenchError(f"{where}: the metadata lists {len(classes)} classes, but "
                                 f"the classifier has {outputs} outputs")
        L = (L if L is not None else
             (meta.get("L") or CLASSIFIER.get(clf, "L") or 0))
        if L == 0:
            raise TactbenchError(f"{where}: window length L unknown; give -L")
        L = check_positive_int(L, f"{where}: window length L")
        offset, scale = _normalisation(meta, where)
        frame_rank = CLASSIFIER.get(clf, "frame_rank")
        if frame_rank is None:  # images or vectors: what it was fitted on decides
            shape = CLASSIFIER.get(clf, "frame_shape")
            frame_rank = 3 if shape is None else len(shape)
        lay = _layout(layout if layout is not None else meta.get("layout"), where)
        ids = meta.get("taxel_ids")
        ids = (_numbers(ids, f"{where}: metadata 'taxel_ids'", np.int64) if ids is not None
               else (lay.ids if lay is not None else None))
        if ids is None:
            raise TactbenchError(f"{where}: the model's metadata has neither 'taxel_ids' nor "
                                 f"a 'layout'; give --layout")
        if isinstance(offset, np.ndarray) and offset.shape != ids.shape:
            raise TactbenchError(f"{where}: normalisation offset has {offset.size} values for "
                                 f"{ids.size} taxels")
        model = cls(clf=clf, classes=classes, L=L, taxel_ids=ids, offset=offset,
                    scale=scale, info=dict(meta))
        if frame_rank == 1:
            shape = CLASSIFIER.get(clf, "frame_shape")
            if shape is not None and tuple(shape) != (ids.size,):
                raise TactbenchError(f"{where}: the classifier expects taxel vectors "
                                     f"{tuple(shape)}, the metadata names {ids.size} taxels")
            _check_window_budget(L, ids.size, where)
            return model
        if lay is None:
            raise TactbenchError(f"{where}: an image classifier needs the taxel layout; "
                                 f"the metadata has none: give --layout")

        imaging = _dict_field(meta, "imaging", where)
        px = check_positive_float(pixel_mm if pixel_mm is not None
                                  else imaging.get("pixel_mm", 1.0),
                                  f"{where}: imaging pixel_mm")
        if not isinstance(imaging.get("method", "linear"), str):
            raise TactbenchError(f"{where}: metadata 'imaging.method' must be a name")
        if lay.n_taxels != ids.size or not np.array_equal(lay.ids, ids):
            lay = lay.subset(ids)
        model.imager = Imager(lay, pixel_mm=px, method=imaging.get("method", "linear"))
        model.encoder_spec = encoder or need("encoder")
        if not isinstance(model.encoder_spec, str):
            raise TactbenchError(f"{where}: metadata 'encoder' must be an encoder spec")
        if registry is None:
            registry = load_registry()
        model.encoder = registry.build("encoder", model.encoder_spec)
        shape = CLASSIFIER.get(clf, "frame_shape")
        expected = (len(model.encoder.channels), *model.imager.shape)
        if shape is not None and tuple(shape) != expected:
            raise TactbenchError(f"{where}: the classifier expects frames {tuple(shape)}, "
                                 f"but encoder '{model.encoder_spec}' on this layout at "
                                 f"{px:g} mm gives {expected}")
        _check_window_budget(L, math.prod(expected), where)
        return model


def _normalisation(meta: dict[str, Any], where: str) -> tuple[Any, float]:
    """``(offset, scale)`` of the metadata's ``normalisation``: the offset one number or
    one per taxel (float32 ``(N,)``), the scale positive (defaults 0 and 65535)."""
    norm = _dict_field(meta, "normalisation", where)
    offset = norm.get("offset", 0.0)
    if isinstance(offset, list):
        offset = _numbers(offset, f"{where}: metadata 'normalisation.offset'", np.float32)
    else:
        offset = _finite(offset, f"{where}: metadata 'normalisation.offset'")
    scale = check_positive_float(norm.get("scale", 65535.0),
                                 f"{where}: metadata 'normalisation.scale'")
    return offset, scale


def _check_window_budget(L: int, frame_values: int, where: str) -> None:
    """Refuse, before the sensor opens, a window whose frames do not fit the memory
    budget: the window of ``L`` frames and the batch it is copied into, float32."""
    check_budget(2 * 4 * L * frame_values,
                 f"{where}: a live window of L = {L} frames of {frame_values} values")


def _dict_field(meta: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = meta.get(key) or {}
    if not isinstance(value, dict):
        raise TactbenchError(f"{where}: metadata '{key}' must be an object, got "
                             f"{type(value).__name__}")
    return value


def _finite(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(float(value)):
        raise TactbenchError(f"{what} must be a finite number, got {value!r:.40}")
    return float(value)


def _numbers(values: Any, what: str, dtype: Any) -> np.ndarray:
    """A list of finite numbers (whole ones for an integer ``dtype``) as a 1-D array."""
    if not isinstance(values, list) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise TactbenchError(f"{what} must be a list of numbers")
    try:
        arr = np.asarray(values, dtype=np.float64)
    except OverflowError:
        arr = np.array([np.inf])
    if not np.all(np.isfinite(arr)):
        raise TactbenchError(f"{what} must hold finite numbers")
    if np.dtype(dtype).kind == "i":
        if not np.all(arr == np.round(arr)) or np.any(np.abs(arr) > 2.0 ** 62):
            raise TactbenchError(f"{what} must hold integer taxel ids")
        return np.asarray(values, dtype=dtype)
    return arr.astype(dtype)


def _layout(obj: Any, where: str) -> Any:
    """A layout given as an object, a layout file, or the model metadata's dict."""
    if obj is None:
        return None

    if isinstance(obj, TaxelLayout):
        return obj
    if isinstance(obj, (str, Path)):
        return load_layout(obj)
    return layout_from_dict(obj, f"{where}: metadata 'layout'")


# ------------------------------------------------------------------ cached features
class _FeatureWindow:
    """Per-frame features kept across predictions (each frame goes through the frame
    encoder once), for a classifier with the contract's ``frame_features`` and
    ``window_proba`` (the built-in torch classifiers: "frame encoder → LSTM over the
    window → head", :class:`tactbench.classifiers.nets.SequenceNet`). This is used only
    after :meth:`check` has shown, on the loaded model, that it gives the same
    probabilities as ``predict_proba``; otherwise the live loop calls ``predict_proba``
    on the whole window.
    """

    def __init__(self, clf: Any, L: int) -> None:
        self.clf = clf
        self.features = CLASSIFIER.get(clf, "frame_features")
        self.window_proba = CLASSIFIER.get(clf, "window_proba")
        self.feats: deque[Any] = deque(maxlen=L)
        self.L = L

    @staticmethod
    def supported(clf: Any) -> bool:
        return (CLASSIFIER.get(clf, "frame_features") is not None
                and CLASSIFIER.get(clf, "window_proba") is not None)

    def push(self, frame: np.ndarray) -> None:
        self.feats.append(self.features(frame))

    def clear(self) -> None:
        self.feats.clear()

    def proba(self, padded_blank: Any = None) -> np.ndarray:
        """Probabilities for the window (padded with blank-frame features to L)."""
        feats = list(self.feats)
        if len(feats) < self.L:
            feats += [padded_blank] * (self.L - len(feats))
        return np.asarray(self.window_proba(feats))

    def check(self, frame_shape: tuple[int, ...], seed: int = 0) -> bool:
        """Whether this path matches ``predict_proba`` on a random window (then use it)."""
        rng = np.random.default_rng(seed)
        window = rng.random((self.L, *frame_shape), dtype=np.float32)
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
    marker: str | None = None  # the sensor's label marker in force for the sweep, if any

    def to_dict(self, classes: list[str]) -> dict[str, Any]:
        """JSON-ready: probabilities by class name; ``marker`` only when there is one."""
        row = {"timestamp": self.timestamp, "label": self.label,
               "confidence": round(self.confidence, 6),
               "probabilities": {c: round(float(p), 6)
                                 for c, p in zip(classes, self.probabilities)},
               "frames": self.frames, "latency_ms": round(self.latency_ms, 3),
               "frame_ms": round(self.frame_ms, 3), "missing": self.missing}
        if self.marker is not None:
            row["marker"] = self.marker
        return row


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
        self.window: deque[np.ndarray] = deque(maxlen=model.L)
        self.frames = 0
        self._features: _FeatureWindow | None = None
        self._blank: Any = None
        if cache_features and _FeatureWindow.supported(model.clf):
            shape = CLASSIFIER.get(model.clf, "frame_shape")
            fw = _FeatureWindow(model.clf, model.L)
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
             received: float | None = None, missing: int = 0,
             marker: str | None = None) -> Prediction | None:
        """Add one sweep's raw values ``(N,)`` (model order); a prediction once the window
        allows one, else ``None``.

        ``timestamp`` (s, the sensor's clock), ``missing`` (taxels not received) and
        ``marker`` (the label marker in force) are passed on to the prediction.
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
        L = self.model.L
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
                          frame_ms=frame_ms, marker=marker)

    def run(self, frames: Iterable[Any], *, taxel_ids: Any = None,
            max_sweeps: int | None = None,
            on_prediction: Callable[[Prediction], None] | None = None) -> Iterator[Prediction]:
        """Predictions for a sensor's frames, one per frame once the window allows.

        Parameters
        ----------
        frames : iterable
            Objects with ``timestamp`` (s) and ``values`` float ``(N,)`` raw counts
            (a sensor's ``frames()``); optional ``missing`` (int, taxels not received)
            and ``label`` (the label marker in force, ``str`` or ``None``) are carried
            into each prediction (``missing``, ``marker``).
        taxel_ids : array-like of int (N,), optional
            The taxel of each value in the frames (the sensor's ``taxel_ids``): values
            are re-indexed into the model's taxel order (see :func:`reorder_index`);
            ``None``: they already are.
        max_sweeps : int, optional
            Stop after this many frames (``None``: when ``frames`` ends).
        on_prediction : callable, optional
            Called with each prediction as soon as it is made.
        """
        index = (None if taxel_ids is None
                 else reorder_index(taxel_ids, self.model.taxel_ids))
        if max_sweeps is not None:
            frames = itertools.islice(frames, max(0, int(max_sweeps)))
        for frame in frames:
            received = time.perf_counter()
            values = frame.values if index is None else np.asarray(frame.values)[index]
            # Optional frame members: CAN sweeps carry them, plain Frames do not.
            pred = self.push(values, frame.timestamp, received=received,
                             missing=int(FRAME.get(frame, "missing") or 0),
                             marker=FRAME.get(frame, "label"))
            if pred is not None:
                if on_prediction is not None:
                    on_prediction(pred)
                yield pred


def reorder_index(sensor_ids: Any, model_ids: Any) -> np.ndarray | None:
    """Index that puts a sensor's values in the model's taxel order: ``values[index]``.

    ``sensor_ids`` and ``model_ids`` are int ``(N_sensor,)`` and ``(N_model,)``;
    returns int ``(N_model,)``, or ``None`` when the orders are already the same. A
    sensor may have more taxels than the model (the extra are dropped); a model taxel
    the sensor lacks raises :class:`~tactbench.errors.InputError`.
    """
    sensor_ids = np.asarray(sensor_ids, dtype=np.int64)
    model_ids = np.asarray(model_ids, dtype=np.int64)
    if sensor_ids.shape == model_ids.shape and np.array_equal(sensor_ids, model_ids):
        return None
    where = {int(t): i for i, t in enumerate(sensor_ids)}
    missing = [int(t) for t in model_ids if int(t) not in where]
    if missing:
        raise InputError(f"the sensor lacks {len(missing)} of the model's taxels "
                         f"(first: {', '.join(map(str, missing[:5]))}); is it the same "
                         f"skin and layout?")
    return np.array([where[int(t)] for t in model_ids], dtype=np.int64)


def run_summary(live: LiveClassifier, latencies_ms: Sequence[float],
                sensor: Any = None) -> dict[str, Any]:
    """What a live session did, JSON-ready: ``{"sweeps", "predictions", "latency_ms"}``
    with ``latency_ms`` = ``{"p50", "p99", "max"}`` in ms (``None`` without
    predictions), plus ``"bus"`` (the sensor's ``stats.to_dict()``) when the sensor
    keeps counters."""
    lat = np.asarray(latencies_ms, dtype=np.float64)
    summary: dict[str, Any] = {
        "sweeps": live.frames, "predictions": int(lat.size),
        "latency_ms": ({"p50": float(np.percentile(lat, 50)),
                        "p99": float(np.percentile(lat, 99)),
                        "max": float(lat.max())} if lat.size else None)}
    stats = None if sensor is None else SENSOR.get(sensor, "stats")
    if stats is not None:
        summary["bus"] = stats.to_dict()
    return summary
