"""Saving and loading trained classifiers without pickle, verified on every read.

A model file is one safetensors file: the network's tensors, and in the
header's metadata (key ``tactbench``) a JSON document::

    {"format": "tactbench-model", "version": 3,
     "classifier": "small-cnn-lstm",          # registry name, used to rebuild it
     "config": {"options": {...}, "n_classes": 5, "frame_shape": [3, 60, 70],
                "L": 5, "fit_report": {...}},
     "classes": ["Grasp", ...],                # or null: the class names, if given
     "cell": "3f2a…",                          # or null: the run cell that produced it
     "metadata": {...},                        # what the caller passed to save()
     "tactbench": "0.1.0", "torch": "2.13.0+cpu",
     "checksum": {"algorithm": "sha256", "digest": "…"}}

What the model is (classifier, options, classes, input shape ``frame_shape`` and window
length ``L``, producing version and cell) is recorded beside the tensors, and ``checksum``
is a SHA-256 over that record (every header field but ``checksum``, as canonical JSON)
and every tensor (name, dtype, shape, bytes, in name order): a flipped bit or an
edited header field is detected.

:func:`load_model` (and :func:`verify_model`, which only checks) refuses, with
:class:`ModelFileError` (a :class:`~tactbench.errors.CorruptArtefactError`) naming the
file and the problem in one line: a file that is not safetensors or is truncated, has
no tactbench header, a newer format version, an unknown classifier, tensors that do not
fit the classifier's network, a checksum that does not match, a tensor holding NaN or
infinity, or class names whose number differs from the network's outputs. Nothing in
the file is executed or unpickled.

Files of format 1 (written before checksums existed) are refused: nothing can tell a
corrupt one from a sound one, and a corrupt option in their header is not harmless (an
``input_size`` of 100000 passes every other check and asks for tens of GB at the first
prediction). A rerun rebuilds them; a Python caller who trusts one reads it with
``load_model(path, allow_unverified=True)`` (every other check, an
:class:`UnverifiedModelWarning`) and saves it again to get a verified file.

What ``tactbench live`` needs in ``metadata`` is built by :func:`live_metadata`.

Format 3 spells the window length ``L`` (in ``config`` and in the live ``metadata``), as
the ``-L`` option, scene files and cell identities do, and the image classifiers' option
``normalisation`` as the datasets do. Format 2 wrote ``length`` and ``normalize``: a
format-2 file is verified against its own checksum as written, then read as format 3
(:func:`migrate_header`, the only translation, documented in docs/classifiers.md); it
keeps loading unchanged on disk, and saving it again writes format 3.
"""

from __future__ import annotations

import copy
import json
import os
import re
import warnings
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any, Iterator

from tactbench import __version__
from tactbench.data.layout_io import layout_to_dict
from tactbench.errors import CorruptArtefactError, InputError, TactbenchError
from tactbench.integrity import ALGORITHM, hash_chunks
from tactbench.paths import atomic_write_bytes
from tactbench.plugins import load_registry

FORMAT = "tactbench-model"
FORMAT_VERSION = 3
#: The format before checksums (refused unless allow_unverified; see the module docstring).
UNVERIFIED_VERSION = 1
HEADER_KEY = "tactbench"


class ModelFileError(CorruptArtefactError, ValueError):
    """A model file that cannot be read back (corrupt, foreign, or mismatched).

    ``ModelFileError(path, problem)``: the message is ``"<path>: <problem>"``, one line
    (line breaks that came from the file are shown as ``\\n``).
    """

    def __init__(self, artefact: Any, problem: str) -> None:
        super().__init__(artefact, problem.replace("\r", "\\r").replace("\n", "\\n"))

    def __reduce__(self):  # crosses process boundaries (runner workers) intact
        return (type(self), (self.artefact, self.problem))


class UnverifiedModelWarning(UserWarning):
    """A model file of format 1 was read: it has no checksum to verify."""


def _tensor_chunks(tensors: dict[str, Any]) -> Iterator[bytes | memoryview]:
    """Name, dtype, shape and bytes of each tensor, in name order (what the digest covers)."""
    import torch

    for name in sorted(tensors):
        t = tensors[name].detach().cpu().contiguous()
        yield json.dumps([name, str(t.dtype), list(t.shape)]).encode()
        yield t.reshape(-1).view(torch.uint8).numpy().data


def payload_digest(record: dict[str, Any], tensors: dict[str, Any]) -> str:
    """SHA-256 of a model's header ``record`` (canonical JSON, without ``checksum``) and
    its ``tensors`` (see the module docstring)."""
    head = {k: v for k, v in record.items() if k != "checksum"}
    text = json.dumps(head, sort_keys=True, separators=(",", ":"))

    def chunks():
        yield text.encode()
        yield from _tensor_chunks(tensors)

    return hash_chunks(chunks())


def save_model(clf, path: str | os.PathLike, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``clf`` (fitted) and ``metadata`` (JSON-serialisable) to ``path``.

    ``metadata["classes"]`` (the class names) and ``metadata["cell"]`` (the producing
    run cell's key), when given, are also recorded in the header; class names must be
    as many as the classifier's outputs. The file is written atomically
    (:func:`tactbench.paths.atomic_write_bytes`), so an interrupted save never leaves a
    half-written model under ``path``.
    """
    import torch
    from safetensors.torch import save

    config, tensors = clf.export()
    meta = dict(metadata or {})
    classes = meta.get("classes")
    if classes is not None:
        classes = [str(c) for c in classes]
        if len(classes) != config.get("n_classes"):
            raise InputError(f"model metadata names {len(classes)} classes, the classifier "
                             f"has {config.get('n_classes')} outputs")
    header = {"format": FORMAT, "version": FORMAT_VERSION, "classifier": clf.name,
              "config": config, "classes": classes, "cell": meta.get("cell"),
              "metadata": meta, "tactbench": __version__, "torch": torch.__version__}
    try:  # round trip: the digest is of what a reader parses back
        header = json.loads(json.dumps(header))
    except (TypeError, ValueError) as exc:
        raise InputError(f"model metadata must be JSON-serialisable: {exc}") from exc
    # safetensors refuses tensors that share memory or are not contiguous.
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in tensors.items()}
    header["checksum"] = {"algorithm": ALGORITHM, "digest": payload_digest(header, tensors)}
    dest = Path(path)
    atomic_write_bytes(dest, save(tensors, metadata={HEADER_KEY: json.dumps(header)}))
    return dest


def live_metadata(dataset: Any, *, encoder: str, L: int, pixel_mm: float,
                  method: str = "linear") -> dict[str, Any]:
    """The metadata to save with a model so ``tactbench live`` can use it (JSON-ready).

    ``dataset`` is the :class:`tactbench.data.recording.Dataset` the model was trained
    on: its ``classes``, ``taxel_ids`` (the order of the values), normalisation
    (``offset`` scalar or per taxel, ``scale``, in raw sensor units) and layout
    (:func:`tactbench.data.layout_io.layout_to_dict`, positions in mm) are recorded,
    with the ``encoder`` spec, the window length ``L`` (frames) and the imaging
    (``pixel_mm`` in mm per pixel, ``method``). :class:`tactbench.live.LiveModel`
    reads it back.
    """
    import numpy as np

    offset, scale = dataset.normalisation_params()
    meta: dict[str, Any] = {
        "classes": list(dataset.classes), "encoder": encoder, "L": int(L),
        "imaging": {"pixel_mm": float(pixel_mm), "method": method},
        "taxel_ids": [int(i) for i in dataset.taxel_ids],
        "normalisation": {"spec": dataset.normalisation.spec,
                          "offset": (np.asarray(offset).astype(float).tolist()
                                     if np.ndim(offset) else float(offset)),
                          "scale": float(scale)},
        "dataset": dataset.name,
    }
    if dataset.layout is not None:
        meta["layout"] = layout_to_dict(dataset.layout)
    return meta


def _is_count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def read_header(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON header of a model file, without loading its tensors (not verified
    against them: :func:`load_model` does that). Its fields' types are checked."""
    from safetensors import safe_open

    p = Path(path)
    if not p.is_file():
        raise ModelFileError(p, "is a folder, not a model file" if p.is_dir() else
                             "is not a regular file (a pipe or a device?), not a model file"
                             if p.exists() else "model file does not exist")
    try:
        with safe_open(str(p), framework="pt") as f:
            raw = (f.metadata() or {}).get(HEADER_KEY)
    except Exception as exc:  # noqa: BLE001 — safetensors raises several kinds
        raise ModelFileError(p, f"not a readable model file (corrupt, truncated or not "
                                f"safetensors): {type(exc).__name__}: {exc}") from None
    if raw is None:
        raise ModelFileError(p, f"a safetensors file but not a tactbench model "
                                f"(no '{HEADER_KEY}' metadata)")
    try:
        header = json.loads(raw)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise ModelFileError(p, f"the tactbench header is not valid JSON: {exc}") from None
    found = header.get("format") if isinstance(header, dict) else header
    if found != FORMAT:
        raise ModelFileError(p, f"header format is {found!r:.60}, expected '{FORMAT}'")
    version = header.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise ModelFileError(p, f"header 'version' must be a positive integer, got "
                                f"{version!r:.40}")
    if version > FORMAT_VERSION:
        raise ModelFileError(p, f"model format version {version!r} is newer than this "
                                f"tactbench reads ({FORMAT_VERSION}); upgrade tactbench")
    for key in ("classifier", "config"):
        if key not in header:
            raise ModelFileError(p, f"header lacks '{key}'")
    _check_header(header, p)
    return header


def _check_header(h: dict[str, Any], p: Path) -> None:
    """Types of the header's fields: one line naming the first that is wrong."""
    def bad(field: str, want: str) -> ModelFileError:
        return ModelFileError(p, f"header field '{field}' must be {want}")

    if not isinstance(h["classifier"], str) or not h["classifier"]:
        raise bad("classifier", "a classifier name")
    config = h["config"]
    if not isinstance(config, dict):
        raise bad("config", "an object")
    if not isinstance(config.get("options", {}), dict):
        raise bad("config.options", "an object")
    if not _is_count(config.get("n_classes")):
        raise bad("config.n_classes", "a positive integer")
    shape = config.get("frame_shape")
    if not isinstance(shape, list) or not shape or not all(_is_count(s) for s in shape):
        raise bad("config.frame_shape", "a list of positive integers")
    length_key = "L" if h["version"] >= 3 else "length"
    if config.get(length_key) is not None and not _is_count(config[length_key]):
        raise bad(f"config.{length_key}", "a positive integer or null")
    if not isinstance(h.get("metadata", {}), dict):
        raise bad("metadata", "an object")
    classes = h.get("classes")
    if classes is not None and not (isinstance(classes, list)
                                    and all(isinstance(c, str) for c in classes)):
        raise bad("classes", "a list of names or null")
    if h.get("cell") is not None and not isinstance(h["cell"], str):
        raise bad("cell", "a cell key or null")
    if h["version"] >= 2:
        check = h.get("checksum")
        if not isinstance(check, dict) or not isinstance(check.get("digest"), str):
            raise ModelFileError(p, "header has no checksum ('checksum.digest')")

        if not re.fullmatch(r"[0-9a-f]{64}", check["digest"]):
            raise ModelFileError(p, "header 'checksum.digest' is not a SHA-256 hex digest")
        if check.get("algorithm") != ALGORITHM:
            raise ModelFileError(p, f"checksum algorithm {check.get('algorithm')!r:.40} is "
                                    f"not {ALGORITHM!r}")


def _check_agreement(header: dict[str, Any], p: Path) -> None:
    """Class names, window length and taxels of the metadata against the network."""
    config, meta = header["config"], header.get("metadata", {})
    k = config["n_classes"]
    for where, names in (("header 'classes'", header.get("classes")),
                         ("metadata 'classes'", meta.get("classes"))):
        if names is None:
            continue
        if not isinstance(names, list):
            raise ModelFileError(p, f"{where} must be a list of class names")
        if len(names) != k:
            raise ModelFileError(p, f"{where} lists {len(names)} classes, but the network "
                                    f"has {k} outputs")
    if header.get("classes") is not None and meta.get("classes") is not None \
            and [str(c) for c in meta["classes"]] != header["classes"]:
        raise ModelFileError(p, "metadata 'classes' differ from the header's")
    length = meta.get("L")
    if length is not None and config.get("L") is not None and length != config["L"]:
        raise ModelFileError(p, f"metadata 'L' {length!r:.20} differs from the network's "
                                f"window length {config['L']}")
    ids = meta.get("taxel_ids")
    shape = config["frame_shape"]
    # An encoder of taxel vectors gives C values per taxel (frame-diff: the value and its
    # change), so a network's vectors hold a whole multiple of the taxels.
    if ids is not None and len(shape) == 1 and (not isinstance(ids, list) or not ids
                                                or shape[0] % len(ids) != 0):
        raise ModelFileError(p, f"metadata 'taxel_ids' names "
                                f"{len(ids) if isinstance(ids, list) else '?'} taxels, but "
                                f"the network takes vectors of {shape[0]} values, not a "
                                "whole number per taxel")


def _check_finite(tensors: dict[str, Any], p: Path) -> None:
    import torch

    for name in sorted(tensors):
        t = tensors[name]
        if t.is_floating_point() and not bool(torch.isfinite(t).all()):
            bad = int((~torch.isfinite(t)).sum())
            raise ModelFileError(p, f"tensor '{name}' holds {bad} NaN or infinite value(s)")


def load_model(path: str | os.PathLike, *, registry=None,
               allow_unverified: bool = False) -> tuple[Any, dict[str, Any]]:
    """Read and verify a model saved by ``clf.save(path, metadata)``: ``(clf, metadata)``.

    ``clf`` is ready to predict on the CPU (``clf.to("cuda")`` moves it);
    ``metadata`` is the dict given to ``save``. The classifier is rebuilt through
    the registry (``registry`` or all installed plugins), so models of plugin
    classifiers load when the plugin is installed. Every check of the module
    docstring runs first; a failure raises :class:`ModelFileError` in one line.
    ``allow_unverified`` reads a format-1 file (no checksum) with a warning instead of
    refusing it.
    """
    from safetensors.torch import load_file

    p = Path(path)
    header = read_header(p)
    name = header["classifier"]
    if registry is None:
        registry = load_registry()
    try:
        cls = registry.get("classifier", name).load()
    except TactbenchError as exc:
        raise ModelFileError(p, f"cannot rebuild classifier {name!r}: {exc}") from None
    try:
        tensors = load_file(str(p))
    except Exception as exc:  # noqa: BLE001 — safetensors raises several kinds
        raise ModelFileError(p, f"cannot read the tensors (corrupt or truncated): "
                                f"{type(exc).__name__}: {exc}") from None
    if header["version"] >= 2:
        digest = payload_digest(header, tensors)
        if digest != header["checksum"]["digest"]:
            raise ModelFileError(p, f"checksum {digest[:12]}… does not match the recorded "
                                    f"{header['checksum']['digest'][:12]}…: the file was "
                                    f"modified or is corrupted")
    elif not allow_unverified:
        raise ModelFileError(p, f"model file of format {UNVERIFIED_VERSION} has no checksum "
                                f"and cannot be verified; retrain it, or, if you trust it, "
                                f"read it with load_model(path, allow_unverified=True) and "
                                f"save it again")
    else:
        warnings.warn(f"{p}: model file of format {UNVERIFIED_VERSION} has no checksum; "
                      f"read with every other check (save it again to get a verified file)",
                      UnverifiedModelWarning, stacklevel=2)
    verified = header["version"] >= 2
    header = migrate_header(header, cls)
    _check_agreement(header, p)
    _check_finite(tensors, p)
    if not verified:  # a verified config came from a network that existed
        _restore(cls, header["config"], tensors, p, name, probe=True)
    clf = _restore(cls, header["config"], tensors, p, name)
    return clf, header.get("metadata", {})


#: What format 3 renamed: ``config`` keys, live ``metadata`` keys, and the options of
#: classifiers that have the new option (see the module docstring).
RENAMED_IN_3 = {"config": {"length": "L"}, "metadata": {"length": "L"},
                "options": {"normalize": "normalisation"}}


def migrate_header(header: dict[str, Any], cls: Any = None) -> dict[str, Any]:
    """A header of format 1 or 2 read as format 3 (a copy; format 3 is returned as is):
    ``length`` becomes ``L`` in ``config`` and ``metadata``, and the option ``normalize``
    becomes ``normalisation`` for a classifier ``cls`` whose options include it. Called
    after the file's checksum was verified against the header as written."""
    if header["version"] >= FORMAT_VERSION:
        return header

    out = copy.deepcopy(header)
    for part in ("config", "metadata"):
        table = out.get(part)
        if isinstance(table, dict):
            for old, new in RENAMED_IN_3[part].items():
                if old in table and new not in table:
                    table[new] = table.pop(old)
    options = out["config"].get("options")
    known = {f.name for f in fields(cls)} if cls is not None and is_dataclass(cls) else set()
    if isinstance(options, dict):
        for old, new in RENAMED_IN_3["options"].items():
            if old in options and new in known and new not in options:
                options[new] = options.pop(old)
    out["version"] = FORMAT_VERSION
    return out


def _restore(cls, config: dict[str, Any], tensors: dict[str, Any], p: Path, name: str, *,
             probe: bool = False) -> Any:
    """``cls._restore``, its mismatches as :class:`ModelFileError`.

    ``probe`` restores on torch's meta device (shapes only, no memory): options that ask
    for a network far larger than the tensors (a corrupt ``layers`` or ``hidden`` in a file
    without a checksum) are refused before a real network is built (it doubles the
    building time, so only unverified files are probed). A classifier that
    cannot be restored on the meta device is left to the real restore."""
    import torch

    try:
        if not probe:
            return cls._restore(config, tensors)
        with torch.device("meta"), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # torch: "copying ... to a meta parameter"
            return cls._restore(config, tensors)
    except (ValueError, TypeError, KeyError, OverflowError) as exc:
        raise ModelFileError(p, f"does not match classifier {name!r}: "
                                f"{type(exc).__name__}: {str(exc)[:300]}") from None
    except RuntimeError as exc:
        if probe:
            # torch: sizes that overflow, or that the meta device cannot build
            if "overflow" in str(exc).lower() or "size" in str(exc).lower():
                raise ModelFileError(p, f"does not match classifier {name!r}: the options "
                                        f"ask for an impossible network: "
                                        f"{str(exc).splitlines()[0][:200]}") from None
            return None
        raise


def verify_model(path: str | os.PathLike, *, registry=None) -> None:
    """Raise :class:`ModelFileError` unless ``path`` is a model :func:`load_model` accepts
    (every check, the network rebuilt; nothing returned)."""
    load_model(path, registry=registry)
