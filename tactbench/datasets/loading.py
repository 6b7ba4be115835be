"""One entry point for every dataset: a registered name with options, or a path.

>>> load_dataset("synthetic-forearm:users=2,repetitions=1")   # doctest: +SKIP
>>> load_dataset("/data/cyskin-fingers")                        # doctest: +SKIP
"""

from __future__ import annotations

import inspect
import logging
from pathlib import Path
from typing import Any, Callable

from tactbench.can.logs import read_log
from tactbench.data.dataset import Dataset
from tactbench.data.store import MANIFEST
from tactbench.datasets.cost import CoST
from tactbench.datasets.haart import HAART, is_haart_folder
from tactbench.datasets.cyskin_text import read_cyskin_folder
from tactbench.datasets.folder import looks_like_folder, read_folder
from tactbench.errors import ContractError, InputError, MissingFileError
from tactbench.plugins import load_registry

#: CAN log suffixes read through :mod:`tactbench.can.logs` (python-can's ``.csv``
#: is not among them: ``.csv`` means CoST here).
CAN_LOG_SUFFIXES = (".blf", ".asc", ".log", ".trc")


def detect_format(path: Path) -> str:
    """``"dataset"`` (tactbench folder), ``"haart"`` (HAART's two challenge files),
    ``"folder"`` (class folders of arrays), ``"cyskin-text"``, ``"cost"`` or
    ``"can-log"``."""
    if path.is_dir():
        if (path / MANIFEST).is_file():
            return "dataset"
        if is_haart_folder(path):
            return "haart"

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
    a CySkin text file or folder, a CoST CSV file, HAART's folder or a CAN log."""
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such file or folder")
    kind = detect_format(path)
    if kind == "dataset":
        return Dataset.load(path if path.is_dir() else path.parent)
    if kind == "folder":
        return read_folder(path, progress=progress)
    if kind == "haart":  # converted once into the store, then read from there
        return HAART(str(path)).load()
    if kind == "cyskin-text":
        return read_cyskin_folder(path)
    if kind == "can-log":  # CySkin traffic recorded by `tactbench can record`
        return read_log(path).to_dataset()

    return CoST(str(path)).load()  # converted once into the store, then read from there


def is_path_spec(text: str) -> bool:
    """Whether ``text`` names a file or folder rather than a registered dataset.

    The rule: **a name is a name, a path says it is one.** Text with a ``/`` (or ``\\``),
    or starting with ``.`` or ``~``, or ending in a data suffix (``.txt``, ``.csv``,
    ``.json``, a CAN log's) is a path. A bare word is a registered dataset's name (with
    options after ``:``); only a bare word that names no registered dataset is read as a
    file or folder of the working folder, so a folder named like a registered dataset
    never replaces it: write ``./NAME`` to read the folder.
    """
    head = text.split(":", 1)[0] if ":" in text.split("/")[0] else text
    return ("/" in head or "\\" in head or head.startswith((".", "~"))
            or Path(head).suffix.lower() in (".txt", ".csv", ".json", *CAN_LOG_SUFFIXES))


def load_dataset(spec_or_path: str | Path, registry: Any = None, *,
                 progress: Callable[..., None] | None = None) -> Dataset:
    """A :class:`Dataset` from a path or a registered dataset spec (see
    :func:`is_path_spec` for which is which).

    A path is read by :func:`load_path`. A spec ``"name:key=value,..."`` is built
    through the registry (``registry.build("dataset", spec).load()``; the installed
    registry when ``registry`` is ``None``). A bare word naming no registered dataset
    but an existing file or folder is read from there.

    ``progress(done, total)`` is handed to the dataset's ``load`` when that takes a
    ``progress`` argument (the contract's ``load()`` need not: see
    :data:`tactbench.contracts.DATASET`), e.g. ``synthetic-forearm`` generating samples.
    """
    text = str(spec_or_path)
    path = Path(text).expanduser()
    if isinstance(spec_or_path, Path) or is_path_spec(text):
        if path.exists():
            return load_path(path, progress=progress)
        raise MissingFileError(f"{text}: no such file or folder (and not a dataset name)")
    if registry is None:
        registry = load_registry()
    name = text.split(":", 1)[0].strip()
    if name not in registry.names("dataset") and path.exists():
        return load_path(path, progress=progress)  # a bare word naming a local folder
    if path.exists():
        logging.getLogger("tactbench.datasets").warning(
            "tactbench: warning: %r names the registered dataset %r; the %s %s here is "
            "not read (write ./%s to read it)", text, name,
            "folder" if path.is_dir() else "file", text, text)
    source = registry.build("dataset", text)
    if progress is not None and takes_progress(source.load):
        dataset = source.load(progress=progress)
    else:
        dataset = source.load()
    return check_loaded(dataset, text)


def check_informative(dataset: Dataset) -> None:
    """Refuse a dataset that holds nothing to classify, before any work: every reading
    missing (NaN), every reading the same value, or a class with fewer than 2
    recordings (named by its name). A classifier would report chance accuracy, or a
    class never tested, as if it were a finding."""
    import numpy as np

    lo, hi, seen = np.inf, -np.inf, 0
    for sample in dataset.samples:
        values = np.asarray(sample.recording.values)
        finite = values[np.isfinite(values)]
        if finite.size:
            seen += finite.size
            lo, hi = min(lo, float(finite.min())), max(hi, float(finite.max()))
    if seen == 0:
        raise InputError(f"dataset '{dataset.name}': every reading is missing (NaN); "
                         f"there is nothing to classify")
    if lo == hi:
        raise InputError(f"dataset '{dataset.name}': every reading is {lo:g}; there is "
                         f"nothing to classify")
    counts = np.bincount(np.asarray(dataset.labels, dtype=np.int64),
                         minlength=len(dataset.classes))
    thin = [(dataset.classes[i], int(n)) for i, n in enumerate(counts) if n < 2]
    if thin:  # it could be trained on or tested on, never both: no finding either way
        name, n = thin[0]
        more = f" (and {len(thin) - 1} more such classes)" if len(thin) > 1 else ""
        raise InputError(f"dataset '{dataset.name}': class '{name}' has {n} recording"
                         f"{'' if n == 1 else 's'}{more}; a benchmark needs ≥ 2 per class "
                         f"to train and test on it")


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
