"""The component contracts, in one place.

These are :class:`typing.Protocol` classes: a component satisfies one by having
the methods below, with no need to inherit. Encoders have a base class with the
shared input policy in :mod:`tactbench.encoders.base`; the protocol here is the
minimum the runner relies on.

Shapes use ``T`` frames, ``N`` taxels, ``H × W`` pixels, ``C`` channels,
``B`` sequences in a batch, ``L`` frames in a window.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Iterator, Protocol, runtime_checkable

if TYPE_CHECKING:  # numpy stays out of import time
    import numpy as np


@runtime_checkable
class Encoder(Protocol):
    """Built with keyword options: ``Farneback(winsize=9, levels=2)``.

    ``channels`` names the ``C`` output channels; ``encode`` maps float32
    ``(T, H, W)`` in [0, 1] to float32 ``(T, C, H, W)``, every value finite and
    in the channel's documented range, deterministic. ``I_{-1}`` is all zeros.
    Bad input (wrong rank, empty, NaN/Inf, out of range) raises ``ValueError``.
    """

    channels: tuple[str, ...]

    def encode(self, seq: "np.ndarray") -> "np.ndarray": ...


class Frame(Protocol):
    """One sweep of a sensor: ``timestamp`` in seconds, ``values`` float32 ``(N,)``."""

    timestamp: float
    values: "np.ndarray"


@runtime_checkable
class Sensor(Protocol):
    """Built with keyword options (interface, channel, file, rate, ...).

    ``frames()`` yields :class:`Frame` objects in time order until the source
    ends or ``close()`` is called; ``taxel_ids`` (int, ``(N,)``) says which
    taxel each value belongs to. Sensors are context managers.
    """

    taxel_ids: "np.ndarray"

    def frames(self) -> Iterator[Frame]: ...

    def close(self) -> None: ...


@runtime_checkable
class DatasetSource(Protocol):
    """A registered dataset: built with keyword options, ``load()`` returns the data.

    The returned object holds labelled recordings (values ``(T, N)`` float32,
    timestamps, label, user), the class names and, when known, the taxel layout.
    """

    def load(self) -> Any: ...


@runtime_checkable
class Classifier(Protocol):
    """Built with keyword options; trained on encoded windows.

    - ``fit(train, val, *, seed, device, progress)``: ``train``/``val`` hold
      windows ``(B, L, C, H, W)`` (or ``(B, L, N)`` for taxel vectors) with
      integer labels ``(B,)``; ``val`` may be ``None``; ``progress`` is a
      callable ``progress(done, total, **info)`` or ``None``.
    - ``predict(batch)`` → class indices ``(B,)``; ``predict_proba(batch)`` →
      ``(B, n_classes)`` probabilities summing to 1.
    - ``save(path)`` / ``load(path)``: state and metadata without pickle.
    """

    def fit(self, train: Any, val: Any, *, seed: int, device: str,
            progress: Callable[..., None] | None) -> Any: ...

    def predict(self, batch: "np.ndarray") -> "np.ndarray": ...
