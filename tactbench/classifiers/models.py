"""The built-in torch classifiers: ``cnn-lstm``, ``small-cnn-lstm``, ``taxel-lstm``.

Options are keyword arguments (dataclass fields), each with a default; the
defaults are the ``quick`` profile's (see :mod:`tactbench.classifiers.training`).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from typing import Any

from tactbench.classifiers.base import TorchSequenceClassifier, n_params
from tactbench.classifiers.pretrained import PretrainedBackbone, check_pretrained_options
from tactbench.classifiers.training import TEMPORAL_HEADS, augment_windows, carve_validation
from tactbench.data.windows import Windows
from tactbench.errors import InputError, check_choice, check_positive_float, check_positive_int
from tactbench.seeds import derive_seed

#: From this input size (px) up, ``cnn-lstm`` trains with gradient checkpointing of its
#: backbone (every stage's inner activations recomputed in the backward pass): at 224 px
#: one step of batch 16 × 5 frames peaks at 7.3 GB resident without it, 3.0 GB
#: with it (docs/classifiers.md). The same updates either way, to float rounding.
CHECKPOINT_FROM_PX = 112


@dataclass(eq=False, repr=False, kw_only=True)
class ImageSequenceClassifier(TorchSequenceClassifier):
    """Image frames ``(C, H, W)``, resized to ``input_size`` and normalised."""

    input_size: int = 32  # frames are resized to input_size × input_size
    normalisation: str = "data"  # data (training statistics), imagenet (3 channels) or none

    def __post_init__(self) -> None:
        super().__post_init__()
        check_positive_int(self.input_size, "input_size (px)", minimum=8)
        check_choice(self.normalisation, "normalisation", ["data", "imagenet", "none"])

    def _wrap(self, encoder, frame_shape, n_classes, *, temporal: str = "lstm"):
        import torch

        from tactbench.classifiers.nets import IMAGENET_MEAN, IMAGENET_STD, SequenceNet

        if self.normalisation == "imagenet" and frame_shape[0] != 3:
            raise InputError(f"normalisation=imagenet needs 3 channels; frames have {frame_shape[0]}")
        net = SequenceNet(encoder, frame_shape=frame_shape, n_classes=n_classes,
                          hidden=self.hidden, fc=self.fc, dropout=self.dropout,
                          input_size=self.input_size, temporal=temporal,
                          L=self.L)
        if self.normalisation == "imagenet":
            net.normalize.set(torch.tensor(IMAGENET_MEAN), torch.tensor(IMAGENET_STD))
        return net

    def _set_normalization(self, net, train, seed) -> None:
        if self.normalisation == "data":  # the fixed choices were set when the net was built
            super()._set_normalization(net, train, seed)


@dataclass(eq=False, repr=False, kw_only=True)
class SmallCnnLstm(ImageSequenceClassifier):
    """A CPU-sized CNN-LSTM: ``layers`` conv blocks of ``width`` → temporal head → FC 256
    → classes.

    Recipe options (each at a default that trains as before, so a spec without them
    names the cells it always did): ``head`` ``lstm`` | ``concat`` | ``tcn`` (see
    :class:`~tactbench.classifiers.nets.SequenceNet`); ``label_smoothing`` of the
    cross-entropy targets; ``shift`` (pixels at ``input_size``) and ``gain`` (log
    amplitude), the augmentation of :func:`~tactbench.classifiers.training.augment_windows`;
    ``val_fraction`` > 0 carves that fraction of the training recordings off as a
    validation split (:func:`~tactbench.classifiers.training.carve_validation`), evaluated
    after every epoch, and the best epoch's weights are kept; ``patience`` > 0 stops
    after that many epochs without a gain.
    """

    name = "small-cnn-lstm"
    width: int = 16
    layers: int = 4
    head: str = "lstm"
    label_smoothing: float = 0.0
    shift: int = 0
    gain: float = 0.0
    val_fraction: float = 0.0
    patience: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_positive_int(self.width, "width")
        check_positive_int(self.layers, "layers")
        check_choice(self.head, "head", list(TEMPORAL_HEADS))
        if not 0 <= check_positive_float(self.label_smoothing, "label_smoothing",
                                         allow_zero=True) < 1:
            raise InputError(f"label_smoothing must lie in [0, 1), got {self.label_smoothing}")
        check_positive_int(self.shift, "shift (px)", minimum=0, maximum=self.input_size // 4)
        check_positive_float(self.gain, "gain", allow_zero=True)
        if not 0 <= check_positive_float(self.val_fraction, "val_fraction",
                                         allow_zero=True) < 1:
            raise InputError(f"val_fraction must lie in [0, 1), got {self.val_fraction}")
        check_positive_int(self.patience, "patience (0: off)", minimum=0)
        if self.patience and not self.val_fraction:
            raise InputError("patience needs a validation split: give val_fraction too")
        if (self.shift or self.gain) and self.shared_features:
            raise InputError("shift and gain augment whole windows: use shared_features=0")

    def _build_net(self, frame_shape, n_classes, *, pretrained):
        from tactbench.classifiers.nets import SmallCNN

        return self._wrap(SmallCNN(frame_shape[0], self.width, self.layers), frame_shape,
                          n_classes, temporal=self.head)

    def fit(self, train, val=None, *, seed, **kwargs):
        """As the base's; with ``val_fraction`` and no ``val`` given, the validation
        split is carved from ``train`` by recording (seeded by ``seed``)."""
        if self.val_fraction and val is None:
            self._check_windows(train, "train")
            train, val = carve_validation(train, self.val_fraction,
                                          derive_seed(seed, self.name, "validation"))
        return super().fit(train, val, seed=seed, **kwargs)

    def _loop_options(self) -> dict[str, Any]:
        augment = None
        if self.shift or self.gain:
            def augment(x, rng):
                return augment_windows(x, rng, shift=self.shift, gain=self.gain)
        return {"label_smoothing": float(self.label_smoothing), "augment": augment,
                "keep_best": bool(self.val_fraction), "patience": int(self.patience)}

    def _check_input(self, x):
        x = super()._check_input(x)
        window = x.L if isinstance(x, Windows) else x.shape[1]
        if self.head == "concat" and self.L is not None and window != self.L:
            raise InputError(f"head=concat was trained on windows of L = {self.L} frames; "
                             f"these have L = {window}")
        return x


@dataclass(eq=False, repr=False, kw_only=True)
class CnnLstm(PretrainedBackbone, ImageSequenceClassifier):
    """The study's model: EfficientNet-B0 per frame → LSTM → dropout 0.3 → FC 256 → classes.

    ``weights``: a local file of ImageNet EfficientNet-B0 weights (lukemelas,
    torchvision or timm layout; see :mod:`tactbench.classifiers.efficientnet`); without
    it the backbone starts from random initialisation, with a warning.
    ``backbone``: ``efficientnet-b0``, ``efficientnet-lite0`` (both built in) or
    ``timm:<model name>`` when timm is installed. ``pretrained=imagenet`` (with
    ``backbone=efficientnet-lite0``) and ``frozen=true``: see
    :mod:`tactbench.classifiers.pretrained`.
    """

    name = "cnn-lstm"
    hidden: int = 256
    epochs: int = 2
    windows_per_epoch: int = 1500
    batch_size: int = 32
    lr: float = 1e-3
    weights: str | None = None
    backbone: str = "efficientnet-b0"
    drop_path: float = 0.2
    bn_recalibration_batches: int = 50  # BN momentum 0.01: see the base class

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.backbone not in ("efficientnet-b0", "efficientnet-lite0") \
                and not str(self.backbone).startswith("timm:"):
            raise InputError(f"unknown backbone '{self.backbone}': use efficientnet-b0, "
                             f"efficientnet-lite0 or timm:<name>")
        check_pretrained_options(self.backbone, self.pretrained, self.weights, self.frozen)
        check_positive_float(self.drop_path, "drop_path", allow_zero=True)
        self.weights_report: dict[str, Any] | None = None

    def preflight(self, device: str) -> None:
        super().preflight(device)
        if self.weights:  # read once at planning: a file every cell would fail on
            from tactbench.classifiers.efficientnet import read_state_dict

            read_state_dict(self.weights)

    def _build_net(self, frame_shape, n_classes, *, pretrained):
        from tactbench.classifiers.nets import segments_of

        channels = frame_shape[0]
        if self.backbone.startswith("timm:"):
            encoder = self._timm_backbone(self.backbone[5:], channels, pretrained)
        elif self.backbone in ("efficientnet-b0", "efficientnet-lite0"):
            from tactbench.classifiers.efficientnet import BACKBONES

            encoder = BACKBONES[self.backbone](channels, drop_path=self.drop_path)
            self.weights_report = self._load_backbone(encoder, pretrained) \
                or self.weights_report
        else:  # __post_init__ refused any other name
            raise AssertionError(f"unchecked backbone {self.backbone!r}")
        net = self._wrap(encoder, frame_shape, n_classes)
        if self.input_size >= CHECKPOINT_FROM_PX:
            net.checkpoint_segments = len(segments_of(encoder))
        return net

    def _timm_backbone(self, model_name: str, channels: int, pretrained: bool):
        if importlib.util.find_spec("timm") is None:
            raise InputError(f"backbone 'timm:{model_name}' needs timm, which is not "
                             f"installed; use backbone=efficientnet-b0")
        import timm
        from torch import nn

        model = timm.create_model(model_name, pretrained=False, num_classes=0,
                                  in_chans=channels)
        if pretrained and self.weights:
            from tactbench.classifiers.efficientnet import read_state_dict

            result = model.load_state_dict(read_state_dict(self.weights), strict=False)
            self.weights_report = {"source": self.weights, "missing": result.missing_keys,
                                   "unused": result.unexpected_keys}

        class _Timm(nn.Module):  # gives timm models the out_features the LSTM needs
            def __init__(self, inner):
                super().__init__()
                self.inner = inner
                self.out_features = inner.num_features

            def forward(self, x):
                return self.inner(x)

        return _Timm(model)

    def _extra_report(self) -> dict[str, Any]:
        return {**super()._extra_report(), "weights": self.weights_report,
                "parameters": n_params(self.net) if self.net is not None else 0}


@dataclass(eq=False, repr=False, kw_only=True)
class TaxelLstm(TorchSequenceClassifier):
    """For taxel vectors without a layout ``(N,)``: per-frame MLP → LSTM → FC 256 → classes.

    Each taxel is standardised with its training mean and deviation.
    """

    name = "taxel-lstm"
    frame_rank = 1
    width: int = 128  # hidden units of the per-frame MLP
    features: int = 64  # per-frame features fed to the LSTM

    def __post_init__(self) -> None:
        super().__post_init__()
        check_positive_int(self.width, "width")
        check_positive_int(self.features, "features")

    def _build_net(self, frame_shape, n_classes, *, pretrained):
        from tactbench.classifiers.nets import SequenceNet, TaxelMLP

        return SequenceNet(TaxelMLP(frame_shape[0], self.width, self.features),
                           frame_shape=frame_shape, n_classes=n_classes, hidden=self.hidden,
                           fc=self.fc, dropout=self.dropout, input_size=None)
