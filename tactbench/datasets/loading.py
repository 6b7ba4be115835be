"""One entry point for every dataset: a registered name with options, or a path.

>>> load_dataset("synthetic-forearm:users=2,repetitions=1")   # doctest: +SKIP
>>> load_dataset("/data/cyskin-fingers")                        # doctest: +SKIP
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any, Callable

from tactbench.can.logs import read_log
from tactbench.data.dataset import Dataset
from tactbench.data.store import MANIFEST
from tactbench.datasets.cost import read_cost_csv
from tactbench.datasets.cyskin_text import read_cyskin_folder
from tactbench.datasets.folder import looks_like_folder, read_folder
from tactbench.errors import ContractError, InputError, MissingFileError
from tactbench.plugins import load_registry

#: CAN log suffixes read through :mod:`tactbench.can.logs` (python-can's ``.csv``
#: is not among them: ``.csv`` means CoST here).
CAN_LOG_SUFFIXES = (".blf", ".asc", ".log", ".trc")


def detect_format(path: Path) -> str:
    """``"dataset"`` (tactbench folder), ``"folder"`` (class folders of arrays),
    ``"cyskin-text"``, ``"cost"`` or ``"can-log"``."""
    if path.is_dir():
        if (path / MANIFEST).is_file():
            return "dataset"

        if looks_like_folder(path):
            return "folder"
        if any(p.is_file() for p in path.rglob("*.txt")):
            return "cyskin-text"
        raise InputError(f"{path}: neither a tactbench dataset folder (no {MANIFEST}), a "
                         f"folder of recordings (ROOT/<class>/*.npy|.npz|.csv) nor a folder "
                         f"of CySkin text files (*.txt)")
    suffix = path.suffix.lower()
    if suffix in CAN_LOG_SUFFIXES:
        return "can-log"
    if suffix == ".txt":
        return "cyskin-text"
    if suffix == ".csv":
        return "cost"
    if path.name == MANIFEST:
        return "dataset"
    raise InputError(f"{path}: unknown data format {suffix or '(no suffix)'!r}; expected a "
                     f"dataset folder, CySkin text (.txt, or a folder of them), CoST (.csv) "
                     f"or a CAN log ({', '.join(CAN_LOG_SUFFIXES)})")


def load_path(path: str | Path, *, progress: Callable[..., None] | None = None) -> Dataset:
    """Load a dataset folder, a folder of recordings (class folders of .npy/.npz/.csv),
    a CySkin text file or folder, a CoST CSV file or a CAN log."""
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such file or folder")
    kind = detect_format(path)
    if kind == "dataset":
        return Dataset.load(path if path.is_dir() else path.parent)
    if kind == "folder":
        return read_folder(path, progress=progress)
    if kind == "cyskin-text":
        return read_cyskin_folder(path)
    if kind == "can-log":  # CySkin traffic recorded by `tactbench can record`
        return read_log(path).to_dataset()

    return read_cost_csv(path)


def _looks_like_path(text: str) -> bool:
    return ("/" in text or "\\" in text or text.startswith(".")
            or Path(text).suffix.lower() in (".txt", ".csv", ".json"))


def load_dataset(spec_or_path: str | Path, registry: Any = None, *,
                 progress: Callable[..., None] | None = None) -> Dataset:
    """A :class:`Dataset` from a path or a registered dataset spec.

    An existing path is read by :func:`load_path`. Anything else is a spec
    ``"name:key=value,..."`` built through the registry
    (``registry.build("dataset", spec).load()``; the installed registry when
    ``registry`` is ``None``). A spec that names no registered dataset and
    looks like a path reports the missing path.

    ``progress(done, total)`` is handed to the dataset's ``load`` when that takes a
    ``progress`` argument (the contract's ``load()`` need not: see
    :data:`tactbench.contracts.DATASET`), e.g. ``synthetic-forearm`` generating samples.
    """
    text = str(spec_or_path)
    path = Path(text).expanduser()
    if path.exists():
        return load_path(path, progress=progress)
    if isinstance(spec_or_path, Path) or _looks_like_path(text) and ":" not in text.split("/")[0]:
        raise MissingFileError(f"{text}: no such file or folder (and not a dataset name)")
    if registry is None:
        registry = load_registry()
    source = registry.build("dataset", text)
    if progress is not None and takes_progress(source.load):
        dataset = source.load(progress=progress)
    else:
        dataset = source.load()
    return check_loaded(dataset, text)


def check_loaded(dataset: Any, spec: str) -> Dataset:
    """``dataset`` if a dataset's ``load()`` returned a :class:`Dataset`, else ContractError."""
    if not isinstance(dataset, Dataset):
        raise ContractError(f"dataset {spec!r}: load() returned {type(dataset).__name__}, "
                            f"expected a tactbench.data.dataset.Dataset")
    return dataset


def takes_progress(load: Callable[..., Any]) -> bool:
    try:
        params = inspect.signature(load).parameters
    except (TypeError, ValueError):  # a builtin or C callable: call it plainly
        return False
    return "progress" in params or any(p.kind is p.VAR_KEYWORD for p in params.values())
