"""Run profiles, defined once: a profile names the imaging and training defaults of a run.

``quick`` (the default)
    CPU-sized. Tactile images at 5 mm per pixel (taxels are 7.5 mm apart, so little is
    lost, and flow is ~25× cheaper than on the study's 1 mm grid). Training sized so that
    one ``small-cnn-lstm`` fit takes about a minute of CPU time: 16 px input, width 16,
    the five frames' pooled features concatenated (``head=concat``), AdamW (lr 3e-3,
    weight decay 0.01) with a one-cycle schedule, 4 epochs of 24 000 windows sampled
    without replacement. Chosen from five paired runs against
    ``sklearn:HistGradientBoostingClassifier`` (docs/classifiers.md); until issue 28 it
    was 32 px, an LSTM head, Adam with a cosine schedule and 4 × 8000 windows, which is
    still ``small-cnn-lstm:input_size=32,head=lstm,windows_per_epoch=8000,optimizer=adam,
    schedule=cosine,weight_decay=0``. This is *not* the paper's optimiser: plain SGD at
    1e-3 does not learn in that budget.
``paper``
    The study's protocol, a GPU workload: images at 1 mm per pixel; SGD, learning rate
    1e-3, 100 epochs over every training window, batch 16 (the batch size is not stated
    in the paper), and for ``cnn-lstm`` EfficientNet-B0 at 224 px.

Each profile also names the storage precision of its cached encodings (one of
:data:`PRECISIONS`, see :mod:`tactbench.encoders.encoding`): ``quick`` keeps float32 (exactly
today's numbers); ``paper`` stores 8 bits per channel value, as the study fed 8-bit images
to its network, in a quarter of the disk (~9 GB instead of ~37 GB for a 3-channel
encoding of the simulated forearm at 1 mm).

A profile is a set of defaults: a pixel size given to the run and options given with a
classifier (``small-cnn-lstm:epochs=8``) override the profile's. A classifier from a
plugin may declare its own ``profiles`` class attribute (``{"quick": {...}, "paper":
{...}}``, see :data:`tactbench.contracts.CLASSIFIER`); one that declares none gets ``{}``
(its own defaults) in every profile.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

from tactbench.contracts import CLASSIFIER
from tactbench.errors import InputError
from tactbench.plugins import load_registry
from tactbench.specs import format_spec, parse_spec

#: How cached encodings may be stored (see :mod:`tactbench.encoders.encoding`): ``float32``
#: exactly as encoded, ``float16``, or ``uint8`` (each channel mapped linearly from its
#: declared range onto 0..255).
PRECISIONS: tuple[str, ...] = ("float32", "float16", "uint8")


@dataclass(frozen=True)
class Profile:
    """One named set of run defaults."""

    name: str
    pixel_mm: float  # tactile-image pixel size, mm (> 0)
    #: classifier name → options; a classifier not listed keeps its class defaults
    classifiers: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    precision: str = "float32"  # storage precision of cached encodings, one of PRECISIONS


#: The paper's training protocol, shared by every torch classifier in ``paper``.
_PAPER_TRAINING: dict[str, Any] = {
    "epochs": 100,
    "optimizer": "sgd",
    "lr": 1e-3,
    "momentum": 0.0,
    "schedule": "constant",
    "batch_size": 16,
    "windows_per_epoch": 0,  # 0: every training window, every epoch
}

PROFILES: dict[str, Profile] = {
    "quick": Profile("quick", pixel_mm=5.0, classifiers={
        # 4 epochs × 24 000 sampled windows = 96 000 windows, AdamW with a one-cycle
        # schedule, 16 px input, the frames' pooled features concatenated: the knee of
        # the measured frontier (docs/classifiers.md, "Recipes measured against the tree").
        "small-cnn-lstm": {
            "epochs": 4, "windows_per_epoch": 24000, "batch_size": 64, "width": 16,
            "optimizer": "adamw", "lr": 3e-3, "weight_decay": 0.01, "schedule": "onecycle",
            "input_size": 16, "head": "concat",
        },
        # EfficientNet-B0 is ~10x slower per window than the small CNN at the same
        # size on a CPU: the quick profile only makes it runnable, not good.
        "cnn-lstm": {
            "epochs": 2, "windows_per_epoch": 1500, "batch_size": 32,
            "optimizer": "adam", "lr": 1e-3, "schedule": "cosine", "input_size": 32,
        },
        "taxel-lstm": {
            "epochs": 4, "windows_per_epoch": 8000, "batch_size": 64,
            "optimizer": "adam", "lr": 3e-3, "schedule": "cosine",
        },
        "logreg": {},
    }),
    "paper": Profile("paper", pixel_mm=1.0, precision="uint8", classifiers={
        "small-cnn-lstm": dict(_PAPER_TRAINING, input_size=64),
        "cnn-lstm": dict(_PAPER_TRAINING, input_size=224),
        "taxel-lstm": dict(_PAPER_TRAINING),
        "logreg": {},
    }),
}

PROFILE_NAMES: tuple[str, ...] = tuple(PROFILES)
DEFAULT_PROFILE = "quick"


def get_profile(name: str) -> Profile:
    """The profile called ``name``; an unknown name is an :class:`InputError` listing them."""
    try:
        return PROFILES[name]
    except (KeyError, TypeError):
        raise InputError(f"unknown profile '{name}'; profiles: "
                         f"{', '.join(PROFILE_NAMES)}") from None


def profile_options(profile: str = DEFAULT_PROFILE, classifier: str = "small-cnn-lstm", *,
                    registry=None) -> dict[str, Any]:
    """The options ``profile`` gives ``classifier`` (a fresh dict; user options override).

    A classifier the profile does not list is looked up in ``registry`` (default: every
    installed plugin) and its declared ``profiles`` are read; an unknown classifier is an
    :class:`~tactbench.errors.UnknownComponentError`.
    """
    table = get_profile(profile).classifiers
    if classifier in table:
        return dict(table[classifier])

    if registry is None:
        registry = load_registry()
    declared = CLASSIFIER.get(registry.get("classifier", classifier).load(), "profiles")
    return dict((declared or {}).get(profile, {}))


def canonical_classifier(spec: str, profile: str = DEFAULT_PROFILE, *, registry=None) -> str:
    """``spec`` as the cells of a run with ``profile`` name it: resolved by the registry
    (``sklearn:SVC`` → its estimator option), the profile's options merged in under the
    spec's own, options sorted (:func:`~tactbench.specs.format_spec`)."""
    if registry is None:
        registry = load_registry()
    name, options = parse_spec(registry.resolve("classifier", spec))
    return format_spec(name, {**profile_options(profile, name, registry=registry), **options})
