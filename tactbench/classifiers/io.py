"""Saving and loading trained classifiers without pickle.

A model file is one safetensors file: the network's tensors, and in the
header's metadata (key ``tactbench``) a JSON document::

    {"format": "tactbench-model", "version": 1,
     "classifier": "small-cnn-lstm",          # registry name, used to rebuild it
     "config": {"options": {...}, "n_classes": 5, "frame_shape": [3, 60, 70],
                "length": 5, "fit_report": {...}},
     "metadata": {...},                        # what the caller passed to save()
     "tactbench": "0.1.0", "torch": "2.13.0+cpu"}

Nothing in the file is executed or unpickled. A file that is not safetensors,
is truncated, has no tactbench header, a newer format version, an unknown
classifier, or tensors that do not fit the classifier's network raises
:class:`ModelFileError` naming the file and the problem.

What ``tactbench live`` needs in ``metadata`` is built by :func:`live_metadata`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from tactbench import __version__
from tactbench.errors import InputError, TactbenchError

FORMAT = "tactbench-model"
FORMAT_VERSION = 1
HEADER_KEY = "tactbench"


class ModelFileError(TactbenchError, ValueError):
    """A model file that cannot be read back (corrupt, foreign, or mismatched)."""


def save_model(clf, path: str | os.PathLike, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``clf`` (fitted) and ``metadata`` (JSON-serialisable) to ``path``.

    The file is written atomically (:func:`tactbench.paths.atomic_write_bytes`), so an
    interrupted save never leaves a half-written model under ``path``.
    """
    import torch
    from safetensors.torch import save

    from tactbench.paths import atomic_write_bytes

    config, tensors = clf._export()
    header = {"format": FORMAT, "version": FORMAT_VERSION, "classifier": clf.name,
              "config": config, "metadata": dict(metadata or {}),
              "tactbench": __version__, "torch": torch.__version__}
    try:
        text = json.dumps(header)
    except (TypeError, ValueError) as exc:
        raise InputError(f"model metadata must be JSON-serialisable: {exc}") from exc
    # safetensors refuses tensors that share memory or are not contiguous.
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in tensors.items()}
    dest = Path(path)
    atomic_write_bytes(dest, save(tensors, metadata={HEADER_KEY: text}))
    return dest


def live_metadata(dataset: Any, *, encoder: str, length: int, pixel_mm: float,
                  method: str = "linear") -> dict[str, Any]:
    """The metadata to save with a model so ``tactbench live`` can use it (JSON-ready).

    ``dataset`` is the :class:`tactbench.data.recording.Dataset` the model was trained
    on: its ``classes``, ``taxel_ids`` (the order of the values), normalisation
    (``offset`` scalar or per taxel, ``scale``, in raw sensor units) and layout
    (:func:`tactbench.data.layout_io.layout_to_dict`, positions in mm) are recorded,
    with the ``encoder`` spec, the window ``length`` L (frames) and the imaging
    (``pixel_mm`` in mm per pixel, ``method``). :class:`tactbench.live.LiveModel`
    reads it back.
    """
    import numpy as np

    offset, scale = dataset.normalisation_params()
    meta: dict[str, Any] = {
        "classes": list(dataset.classes), "encoder": encoder, "length": int(length),
        "imaging": {"pixel_mm": float(pixel_mm), "method": method},
        "taxel_ids": [int(i) for i in dataset.taxel_ids],
        "normalisation": {"spec": dataset.normalisation.spec,
                          "offset": (np.asarray(offset).astype(float).tolist()
                                     if np.ndim(offset) else float(offset)),
                          "scale": float(scale)},
        "dataset": dataset.name,
    }
    if dataset.layout is not None:
        from tactbench.data.layout_io import layout_to_dict

        meta["layout"] = layout_to_dict(dataset.layout)
    return meta


def read_header(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON header of a model file, without loading its tensors."""
    from safetensors import safe_open

    p = Path(path)
    if not p.is_file():
        raise ModelFileError(f"model file {p} does not exist")
    try:
        with safe_open(str(p), framework="pt") as f:
            raw = (f.metadata() or {}).get(HEADER_KEY)
    except Exception as exc:
        raise ModelFileError(f"{p} is not a readable model file (corrupt, truncated or not "
                             f"safetensors): {type(exc).__name__}: {exc}") from exc
    if raw is None:
        raise ModelFileError(f"{p} is a safetensors file but not a tactbench model "
                             f"(no '{HEADER_KEY}' metadata)")
    try:
        header = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise ModelFileError(f"{p}: the tactbench header is not valid JSON: {exc}") from exc
    found = header.get("format") if isinstance(header, dict) else header
    if found != FORMAT:
        raise ModelFileError(f"{p}: header format is {found!r}, expected '{FORMAT}'")
    version = header.get("version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise ModelFileError(f"{p}: model format version {version!r} is newer than this "
                             f"tactbench reads ({FORMAT_VERSION}); upgrade tactbench")
    for key in ("classifier", "config"):
        if key not in header:
            raise ModelFileError(f"{p}: header lacks '{key}'")
    return header


def load_model(path: str | os.PathLike, *, registry=None) -> tuple[Any, dict[str, Any]]:
    """Read a model saved by ``clf.save(path, metadata)``: returns ``(clf, metadata)``.

    ``clf`` is ready to predict on the CPU (``clf.to("cuda")`` moves it);
    ``metadata`` is the dict given to ``save``. The classifier is rebuilt through
    the registry (``registry`` or all installed plugins), so models of plugin
    classifiers load when the plugin is installed.
    """
    from safetensors.torch import load_file

    p = Path(path)
    header = read_header(p)
    name = header["classifier"]
    if registry is None:
        from tactbench.plugins import load_registry

        registry = load_registry()
    try:
        cls = registry.get("classifier", name).load()
    except TactbenchError as exc:
        raise ModelFileError(f"{p}: cannot rebuild classifier '{name}': {exc}") from exc
    try:
        tensors = load_file(str(p))
    except Exception as exc:
        raise ModelFileError(f"{p}: cannot read the tensors (corrupt or truncated): "
                             f"{type(exc).__name__}: {exc}") from exc
    try:
        clf = cls._restore(header["config"], tensors)
    except (ValueError, TypeError, KeyError) as exc:
        raise ModelFileError(f"{p}: does not match classifier '{name}': "
                             f"{type(exc).__name__}: {exc}") from exc
    return clf, header.get("metadata", {})
