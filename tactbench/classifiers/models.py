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
from tactbench.errors import InputError, check_choice, check_positive_float, check_positive_int

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

    def _wrap(self, encoder, frame_shape, n_classes):
        import torch

        from tactbench.classifiers.nets import IMAGENET_MEAN, IMAGENET_STD, SequenceNet

        if self.normalisation == "imagenet" and frame_shape[0] != 3:
            raise InputError(f"normalisation=imagenet needs 3 channels; frames have {frame_shape[0]}")
        net = SequenceNet(encoder, frame_shape=frame_shape, n_classes=n_classes,
                          hidden=self.hidden, fc=self.fc, dropout=self.dropout,
                          input_size=self.input_size)
        if self.normalisation == "imagenet":
            net.normalize.set(torch.tensor(IMAGENET_MEAN), torch.tensor(IMAGENET_STD))
        return net

    def _set_normalization(self, net, train, seed) -> None:
        if self.normalisation == "data":  # the fixed choices were set when the net was built
            super()._set_normalization(net, train, seed)


@dataclass(eq=False, repr=False, kw_only=True)
class SmallCnnLstm(ImageSequenceClassifier):
    """A CPU-sized CNN-LSTM: ``layers`` conv blocks of ``width`` → LSTM → FC 256 → classes."""

    name = "small-cnn-lstm"
    width: int = 16
    layers: int = 4

    def __post_init__(self) -> None:
        super().__post_init__()
        check_positive_int(self.width, "width")
        check_positive_int(self.layers, "layers")

    def _build_net(self, frame_shape, n_classes, *, pretrained):
        from tactbench.classifiers.nets import SmallCNN

        return self._wrap(SmallCNN(frame_shape[0], self.width, self.layers), frame_shape,
                          n_classes)


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
