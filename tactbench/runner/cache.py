"""Encoded datasets on disk, so that each encoding is computed once across cells and runs.

A cache entry is keyed by the dataset's content hash, the imaging identity (vectors, or
images at a pixel size and method) and the encoder's canonical spec and version. The
cache root is ``$TACTBENCH_CACHE/encodings`` (see :func:`tactbench.paths.cache_dir`).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from tactbench.paths import atomic_folder, cache_dir
from tactbench.runner.planning import Cell, Plan, digest, imaging_identity
from tactbench.runner.system import now

if TYPE_CHECKING:
    from tactbench.ui import Progress


class EncodingCache:
    """Encoded datasets on disk: one folder per (dataset, imaging, encoder, version).

    A folder holds ``frames.npy`` (all frames stacked, float32 ``(ΣT, C, H, W)`` or
    ``(ΣT, N)``), ``offsets.npy`` (int64 ``(n + 1,)``: sample i is
    ``frames[o[i]:o[i+1]]``) and ``meta.json``. It is written with
    :func:`atomic_folder`, so a folder that exists is complete.
    """

    def __init__(self, root: str | Path | None = None) -> None:
        self.root = Path(root) if root is not None else cache_dir("encodings")
        self.root.mkdir(parents=True, exist_ok=True)

    def key(self, dataset_hash: str, imaging: dict[str, Any], encoder: str,
            version: str) -> str:
        return digest({"dataset": dataset_hash, "imaging": imaging, "encoder": encoder,
                       "version": version}, 24)

    def path(self, key: str) -> Path:
        return self.root / key

    def has(self, key: str) -> bool:
        return (self.path(key) / "meta.json").is_file()

    def write(self, key: str, sequences: Sequence[Any], meta: dict[str, Any]) -> Path:
        """Store ``sequences`` (each ``(T, ...)`` float32, same trailing shape) under ``key``."""
        import numpy as np

        final = self.path(key)
        with atomic_folder(final) as tmp:
            lengths = [len(s) for s in sequences]
            offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
            # Written through a memory map: the stacked frames are never all in memory.
            frames = np.lib.format.open_memmap(
                tmp / "frames.npy", mode="w+", dtype=np.float32,
                shape=(int(offsets[-1]), *sequences[0].shape[1:]))
            for seq, start in zip(sequences, offsets[:-1]):
                frames[start:start + len(seq)] = seq
            frames.flush()
            del frames
            np.save(tmp / "offsets.npy", offsets)
            (tmp / "meta.json").write_text(json.dumps({**meta, "created": now()}, indent=2))
        return final

    def entries(self) -> list[dict[str, Any]]:
        """``meta.json`` of every entry, with its ``key`` and size in ``bytes``."""
        out = []
        for meta_path in sorted(self.root.glob("*/meta.json")):
            meta = json.loads(meta_path.read_text())
            size = sum(f.stat().st_size for f in meta_path.parent.iterdir())
            out.append({"key": meta_path.parent.name, "bytes": size, **meta})
        return out

    def clear(self) -> int:
        """Delete every entry; returns how many."""
        n = 0
        for child in self.root.iterdir():
            if child.is_dir():
                shutil.rmtree(child)
                n += 1
        return n


_LOADED: dict[str, tuple[list[Any], dict[str, Any]]] = {}


def load_encoding(folder: str | Path) -> tuple[list[Any], dict[str, Any]]:
    """The cached sequences (memory-mapped views) and metadata; memoised per process."""
    import numpy as np

    folder = str(folder)
    if folder not in _LOADED:
        # copy-on-write: writable views for the classifiers, the file stays untouched
        frames = np.load(Path(folder) / "frames.npy", mmap_mode="c")
        offsets = np.load(Path(folder) / "offsets.npy")
        meta = json.loads((Path(folder) / "meta.json").read_text())
        seqs = [frames[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
        _LOADED[folder] = (seqs, meta)
    return _LOADED[folder]


def ensure_encodings(plan_: Plan, cache: EncodingCache, pending: Sequence[Cell],
                     progress: "Progress | None" = None) -> dict[tuple[str, str], str]:
    """Make sure every (encoder, input kind) the pending cells need is cached.

    Returns ``(encoder spec, input kind) → cache folder`` for every pair the *plan*
    uses; images are made from the dataset once, and only if some encoding is missing.
    """
    from tactbench.contracts import ENCODER

    scene = plan_.scene
    needed = {(c.encoder, plan_.input_kind[c.classifier]) for c in plan_.cells}
    pending_pairs = {(c.encoder, plan_.input_kind[c.classifier]) for c in pending}
    folders: dict[tuple[str, str], str] = {}
    images = vectors = None
    image_s = 0.0
    for enc, kind in sorted(needed):
        imaging = imaging_identity(scene, kind)
        key = cache.key(plan_.dataset_hash, imaging, enc, plan_.encoder_versions[enc])
        folders[(enc, kind)] = str(cache.path(key))
        if cache.has(key) or (enc, kind) not in pending_pairs:
            continue
        if kind == "vectors":
            if vectors is None:
                vectors = plan_.dataset.vectors()
            # The taxel-vector path has no image encoder: raw passes vectors through.
            cache.write(key, vectors, {"encoder": enc, "imaging": imaging,
                                       "dataset_hash": plan_.dataset_hash,
                                       "encode_seconds": 0.0, "workers": 1,
                                       "frames": int(sum(len(v) for v in vectors))})
            continue
        if images is None:
            task = progress.add(f"tactile images at {scene.resolved_pixel_mm():g} mm",
                                total=1) if progress else None
            t0 = time.perf_counter()
            images = plan_.dataset.images(pixel_mm=scene.resolved_pixel_mm(),
                                          method=scene.imaging)
            image_s = time.perf_counter() - t0
            if progress:
                progress.update(task, 1)
        from tactbench.encoders.parallel import encode_all

        workers = max(1, os.cpu_count() or 1)
        t0 = time.perf_counter()
        encoded = encode_all(plan_.encoders[enc], images, workers=workers,
                             progress=progress.callback(f"encode {enc}", total=len(images))
                             if progress else None)
        seconds = time.perf_counter() - t0
        n_frames = int(sum(len(s) for s in images))
        cache.write(key, encoded, {
            "encoder": enc, "encoder_version": plan_.encoder_versions[enc],
            "channels": list(ENCODER.get(plan_.encoders[enc], "channels")),
            "imaging": imaging, "imaging_seconds": image_s,
            "dataset": plan_.dataset.name, "dataset_hash": plan_.dataset_hash,
            "encode_seconds": seconds, "workers": workers, "frames": n_frames,
            "frame_shape": list(encoded[0].shape[1:]),
        })
        del encoded
    return folders
