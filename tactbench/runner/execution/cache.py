"""The encoding cache: a folder of entries, each an encoded dataset computed once across
cells and runs, and the step that fills it with what a plan needs.

An entry (:mod:`tactbench.runner.execution.entries`: its format, verification and reading) is keyed
by the dataset's content hash, the imaging identity (vectors, or images at a pixel size
and method), the encoder's canonical spec and version, and the storage precision (left
out of the key for ``float32``, so entries made before precisions existed keep their
keys), and the CPU kernels numpy and OpenCV computed with (:func:`~tactbench.kernels.kernels_identity`). The cache root is ``$TACTBENCH_CACHE/encodings`` (see
:func:`tactbench.paths.cache_dir`).

:func:`ensure_encodings` encodes what is missing in one streaming pass over the dataset
(:mod:`tactbench.encoders.encoding`), each encoding appended to its entry as it is made.
Values uint8 storage clipped are said in one warning line per encoder, when the entry
is written and, from the counts its ``meta.json`` keeps, when a later run uses it.
It reports a damaged entry in one warning line and encodes it again;
:func:`~tactbench.runner.execution.entries.load_encoding` raises
:class:`~tactbench.errors.CorruptArtefactError`. Writers of one key race safely: the
first complete folder renamed into place wins, the others verify and use it; temporaries
of dead writers are removed by the next run.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Sequence

from tactbench.boundary import VIOLATION_FIELD as VIOLATION, EncoderGuard
from tactbench.contracts import ENCODER
from tactbench.encoders.encoding import (
    CHUNK_BYTES,
    Storage,
    encode_images,
    encode_vectors,
    image_storage,
    vector_storage,
    vector_width,
)
from tactbench.budget import human_bytes
from tactbench.errors import CorruptArtefactError, StorageError
from tactbench.machine import peak_rss_mb
from tactbench.paths import (
    Temporary,
    atomic_folder,
    cache_dir,
    discard,
    parse_temporary,
    remove_orphans,
    remove_path,
    temporaries,
)
from tactbench.runner.execution.entries import (
    KEY_DIGITS,
    EntryWriter,
    forget,
    last_used,
    mark_used,
    mark_verified,
    readable_meta,
    signature,
    verify_entry,
)
from tactbench.kernels import kernels_identity
from tactbench.runner.execution.leases import LEASES, Lease, cache_lock, leased_keys
from tactbench.runner.execution.planning import (Cell, Plan, digest, imaging_identity,
                                                 storage_identity)

if TYPE_CHECKING:
    from tactbench.ui import Progress

log = logging.getLogger("tactbench.runner.execution.cache")

#: :meth:`EncodingCache.prune` keeps every entry used more recently than this (seconds),
#: whatever the limits: a run may be reading it.
KEEP_RECENT_S = 15 * 60


class EncodingCache:
    """Encoded datasets on disk: one folder per (dataset, imaging, encoder, version,
    precision).

    A folder holds ``frames.npy`` (all frames stacked, ``(ΣT, C, H, W)`` or ``(ΣT, N)``
    in the entry's storage dtype), ``offsets.npy`` (int64 ``(n + 1,)``: sample i is
    ``frames[o[i]:o[i+1]]``) and ``meta.json`` (what the entry is, and the sizes and
    checksums of both files: see :func:`verify_entry`). It is written with
    :func:`atomic_folder`, so a folder that exists was complete when it was renamed
    into place; whether it is still intact is what :meth:`verify` checks.
    """

    def __init__(self, root: str | Path | None = None) -> None:
        self.root = Path(root) if root is not None else cache_dir("encodings")
        self.root.mkdir(parents=True, exist_ok=True)
        self._lease: Lease | None = None

    @contextlib.contextmanager
    def lease(self) -> Iterator[Lease]:
        """Hold a lease (:mod:`~tactbench.runner.execution.leases`) for the block: every
        key given to :meth:`hold` meanwhile is kept by ``prune`` and ``clear`` until the
        block ends (or the process dies). Nested blocks share the outer lease."""
        if self._lease is not None:
            yield self._lease
            return
        self._lease = Lease(self.root).open()
        try:
            yield self._lease
        finally:
            self._lease.close()
            self._lease = None

    def hold(self, keys: Sequence[str]) -> None:
        """Add ``keys`` to this cache's lease, when one is held (:meth:`lease`)."""
        if self._lease is not None:
            self._lease.hold(keys)

    @staticmethod
    def identity(dataset_hash: str, imaging: dict[str, Any], encoder: str, version: str,
                 precision: str = "float32") -> dict[str, Any]:
        """What decides an entry's content; its digest is the entry's key, and
        ``meta.json`` records it so that a reader can check the key against it."""
        return {"dataset": dataset_hash, "imaging": imaging, "encoder": encoder,
                "version": version, **storage_identity(precision),
                "cpu_kernels": kernels_identity()}  # numpy's and OpenCV's SIMD loops

    def key(self, dataset_hash: str, imaging: dict[str, Any], encoder: str,
            version: str, precision: str = "float32") -> str:
        return digest(EncodingCache.identity(dataset_hash, imaging, encoder, version,
                                             precision), KEY_DIGITS)

    def path(self, key: str) -> Path:
        return self.root / key

    def has(self, key: str) -> bool:
        """Whether an entry folder of ``key`` is there (cheap; :meth:`verify` says
        whether it is intact)."""
        return (self.path(key) / "meta.json").is_file()

    def verify(self, key: str, *, full: bool = True) -> dict[str, Any]:
        """The entry's ``meta.json`` after :func:`~tactbench.runner.execution.entries.verify_entry`;
        raises :class:`CorruptArtefactError` naming the entry and what is wrong."""
        return verify_entry(self.path(key), full=full)[0]

    def discard(self, key: str) -> None:
        """Remove the entry ``key`` (a damaged one, so it can be written again)."""
        forget(self.path(key))
        discard(self.path(key))

    def clean(self) -> list[Temporary]:
        """Remove the temporary folders whose writing process is gone; returns them."""
        return remove_orphans(self.root)

    @contextlib.contextmanager
    def entry(self, key: str, lengths: Sequence[int], frame_shape: Sequence[int],
              storage: Storage) -> Iterator[EntryWriter]:
        """Write the entry ``key`` sequence by sequence: the block gets an
        :class:`EntryWriter`; the entry appears, complete, when the block ends without
        an error (and not at all otherwise).

        When another process wrote the same key first, its entry is kept (ours is
        dropped) and verified here: a damaged winner raises
        :class:`CorruptArtefactError` (the next run rebuilds it).
        """
        with atomic_folder(self.path(key)) as tmp:
            writer = EntryWriter(tmp, lengths, frame_shape, storage, key=key)
            try:
                yield writer
            except BaseException:
                writer.discard()
                raise
            writer.close()
            ours = json.loads((tmp / "meta.json").read_text())["meta_checksum"]
        forget(self.path(key))
        meta = json.loads((self.path(key) / "meta.json").read_text()) \
            if (self.path(key) / "meta.json").is_file() else {}
        if meta.get("meta_checksum") != ours:  # another process's entry: verify it
            self.verify(key)
        else:  # ours: its checksum was taken of the very bytes written, no need to reread
            mark_verified(self.path(key))

    def write(self, key: str, sequences: Sequence[Any], meta: dict[str, Any], *,
              precision: str = "float32", ranges: Sequence[Sequence[float]] = ()) -> Path:
        """Store ``sequences`` (each float ``(T, ...)``, same trailing shape) under ``key``
        at ``precision`` (``ranges``: per channel, for uint8; see :class:`Storage`)."""
        frame_shape = tuple(sequences[0].shape[1:])
        channels = frame_shape[0] if len(frame_shape) == 3 else 1
        with self.entry(key, [len(s) for s in sequences], frame_shape,
                        Storage.for_channels(precision, channels, ranges)) as writer:
            writer.meta.update(meta)
            for seq in sequences:
                writer.append(seq)
        return self.path(key)

    def entries(self) -> list[dict[str, Any]]:
        """Every entry folder: its ``meta.json`` (as far as it is readable), ``key``,
        size in ``bytes``, ``precision`` and ``state``: ``"ok"``, or ``"damaged"`` with
        the ``problem`` (sizes, identity and offsets are checked; checksums are not,
        to keep listing cheap)."""
        out = []
        for folder in sorted(p for p in self.root.iterdir()
                             if p.is_dir() and not p.name.startswith(".")):
            try:
                out.append(self._entry_row(folder))
            except (FileNotFoundError, NotADirectoryError):
                if folder.exists():
                    raise
                # removed while it was listed (a prune beside us): not an entry any more
        return out

    @staticmethod
    def _entry_row(folder: Path) -> dict[str, Any]:
        size = sum(f.stat().st_size for f in folder.iterdir() if f.is_file())
        entry: dict[str, Any] = {"key": folder.name, "bytes": size, "precision": "float32"}
        try:
            entry.update(verify_entry(folder, full=False)[0])
            entry["state"] = "ok"
        except CorruptArtefactError as exc:
            if not folder.is_dir():
                raise FileNotFoundError(folder) from None
            entry.update(readable_meta(folder))
            entry.update({"state": "damaged", "problem": exc.problem})
        entry["key"], entry["bytes"] = folder.name, size
        return entry

    def prune(self, *, max_bytes: int | None = None, unused_for: float | None = None,
              dry_run: bool = False, now: float | None = None) -> dict[str, Any]:
        """Remove what a run is least likely to need, least recently used first: damaged
        entries, entries unused for ``unused_for`` seconds, then entries until the rest
        take at most ``max_bytes``; and orphaned temporary folders. An entry a live run
        holds a lease on (:meth:`lease`) is kept (``leased``, with ``lease``: who holds
        it), and so is one used within :data:`KEEP_RECENT_S` (``held``: a run from before
        leases may be reading it); a last use dated in the future (a clock set wrong) is
        taken as now and its mark set to now. One the disk would not let go of is
        ``stuck``. With ``dry_run`` nothing is removed or marked. Returns ``removed``,
        ``held``, ``leased`` and ``stuck`` (:meth:`entries` rows with ``last_used`` and,
        removed, ``why``), ``orphans`` and ``bytes_before`` / ``bytes_after``."""
        with cache_lock(self.root, exclusive=not dry_run):
            return self._prune(max_bytes, unused_for, dry_run,
                               time.time() if now is None else now)

    def _last_used(self, key: str, now: float, dry_run: bool) -> float:
        """The entry's last use, a future one taken as now (and, removing, marked now)."""
        when = last_used(self.path(key))
        if when > now:
            if not dry_run:
                mark_used(self.path(key))
            return now
        return when

    def _prune(self, max_bytes: int | None, unused_for: float | None, dry_run: bool,
               now: float) -> dict[str, Any]:
        leases = leased_keys(self.root)
        rows = sorted(({**e, "last_used": self._last_used(e["key"], now, dry_run)}
                       for e in self.entries()), key=lambda e: (e["last_used"], e["key"]))
        before = sum(e["bytes"] for e in rows)
        out: dict[str, list[dict[str, Any]]] = {"removed": [], "held": [], "leased": [],
                                                "stuck": []}

        def take(e: dict[str, Any], why: str) -> int:
            """Remove ``e`` unless a live run holds it or used it lately (looked at
            again: a run may have since); the bytes freed."""
            if e["key"] in leases:
                out["leased"].append({**e, "lease": leases[e["key"]].describe(now)})
                return 0
            if now - self._last_used(e["key"], now, dry_run) < KEEP_RECENT_S:
                out["held"].append(e)
                return 0
            if not dry_run:
                forget(self.path(e["key"]))
                remove_path(self.path(e["key"]))
                if self.path(e["key"]).exists():  # the disk refused (read-only, permissions)
                    out["stuck"].append(e)
                    return 0
            out["removed"].append({**e, "why": why})
            return e["bytes"]

        total, rest = before, []
        for e in rows:
            if e["state"] != "ok":
                total -= take(e, "damaged")
            elif unused_for is not None and now - e["last_used"] >= unused_for:
                total -= take(e, "unused")
            else:
                rest.append(e)
        for e in rest:
            if max_bytes is None or total <= max_bytes:
                break
            total -= take(e, "size")
        orphans = [t for t in self.temporaries() if t["state"] == "orphaned"]
        if not dry_run:
            self.clean()
        return {**out, "orphans": orphans, "bytes_before": before, "bytes_after": total}

    def temporaries(self) -> list[dict[str, Any]]:
        """Temporary folders beside the entries: ``name``, ``key`` (the entry it was
        going to be), ``pid``, ``state`` (``"orphaned"``: its process is gone, removed
        at the next run; ``"in progress"``; ``"other host"``) and ``bytes``."""
        out = []
        for t in temporaries(self.root):
            try:
                size = sum(f.stat().st_size for f in t.path.rglob("*") if f.is_file()) \
                    if t.path.is_dir() else t.path.stat().st_size
            except OSError:
                size = 0
            out.append({"name": t.path.name, "key": t.target, "pid": t.pid,
                        "state": t.state, "bytes": size})
        return out

    def clear(self) -> int:
        """Delete every entry and every orphaned temporary folder but those a live run
        holds a lease on (:meth:`lease`, see :meth:`leased`) and the temporaries of
        running writers (``"in progress"``), which are left to them; returns how many
        were deleted."""
        n = 0
        with cache_lock(self.root, exclusive=True):
            leases = leased_keys(self.root)
            for child in self.root.iterdir():
                temp = parse_temporary(child)
                if child.name == LEASES or child.name in leases or \
                        (temp is not None and temp.state != "orphaned"):
                    continue
                if child.is_dir() or temp is not None:
                    forget(child)
                    remove_path(child)
                    n += 1
        return n

    def leased(self) -> dict[str, str]:
        """Entry key → which live run holds a lease on it (for entries that exist)."""
        return {k: v.describe() for k, v in leased_keys(self.root).items()
                if self.path(k).is_dir()}


# ----------------------------------------------------------------------- filling


def ensure_encodings(plan_: Plan, cache: EncodingCache, pending: Sequence[Cell],
                     progress: "Progress | None" = None, *,
                     chunk_bytes: int = CHUNK_BYTES) -> dict[tuple[str, str], str]:
    """Make sure every (encoder, input kind) the pending cells need is cached.

    Returns ``(encoder spec, input kind) → cache folder`` for every pair the *plan*
    uses. Missing image encodings are made in one streaming pass over the dataset
    (each chunk of ``chunk_bytes`` of images is imaged once and encoded by every
    missing encoder); missing taxel-vector entries in another.
    """
    scene = plan_.scene
    precision = scene.resolved_precision()
    needed = {(c.encoder, plan_.input_kind[c.classifier]) for c in plan_.cells}
    pending_pairs = {(c.encoder, plan_.input_kind[c.classifier]) for c in pending}
    folders: dict[tuple[str, str], str] = {}
    missing: dict[str, dict[str, str]] = {"images": {}, "vectors": {}}  # kind → enc → key
    identities: dict[str, dict[str, Any]] = {}
    for orphan in cache.clean():
        log.info("removed the temporary folder %s left by process %s", orphan.path,
                 orphan.pid)
    cache.hold([entry_key(plan_, cache, enc, kind) for enc, kind in needed])
    for enc, kind in sorted(needed):  # leased first: a prune now keeps what is checked
        key = entry_key(plan_, cache, enc, kind)
        identities[key] = cache.identity(plan_.dataset_hash, imaging_identity(scene, kind),
                                         enc, plan_.encoder_versions[enc], precision)
        folders[(enc, kind)] = str(cache.path(key))
        if (enc, kind) not in pending_pairs:
            continue
        if cache.path(key).exists() or cache.path(key).is_symlink():
            if _usable(cache, key, enc, kind):
                continue
        missing[kind][enc] = key
    if missing["vectors"]:
        _store_vectors(plan_, cache, missing["vectors"], chunk_bytes, identities)
    if missing["images"]:
        _store_images(plan_, cache, missing["images"], progress, chunk_bytes, identities)
    return folders


def entry_key(plan_: Plan, cache: EncodingCache, enc: str, kind: str) -> str:
    """The cache key of encoder ``enc``'s entry for the input ``kind`` of ``plan_``."""
    return cache.key(plan_.dataset_hash, imaging_identity(plan_.scene, kind), enc,
                     plan_.encoder_versions[enc], plan_.scene.resolved_precision())


def _usable(cache: EncodingCache, key: str, enc: str, kind: str) -> bool:
    """Whether the entry ``key`` is sound; a damaged one is reported and removed. When
    its files change while they are checked (another run replacing a damaged entry with
    a new one), they are checked again rather than removed."""
    for _ in range(3):
        found = signature(cache.path(key))
        try:
            meta = cache.verify(key)
            if meta.get(VIOLATION):  # a plugin's output broke its contract
                cache.discard(key)  # last run's cells failed on it: encode it again
                return False
            _say_stored_clipping(enc, key, meta)
            mark_used(cache.path(key))
            return True
        except CorruptArtefactError as exc:
            if signature(cache.path(key)) != found:
                continue  # replaced meanwhile: look at the new files
            log.warning("tactbench: warning: cached encoding %s (%s, %s) is damaged: %s; "
                        "encoding it again", key, enc, kind, exc.problem)
            cache.discard(key)
            return False
    return False


def _guard(plan_: Plan, enc: str, sink: Any, frame_shape: Sequence[int]) -> EncoderGuard:
    """``sink`` behind the run-time check of ``enc``'s output (:mod:`tactbench.boundary`):
    images against each channel's declared range, taxel vectors (one channel of ``C·N``)
    against the span of them all."""
    try:
        plugin = plan_.registry.get("encoder", enc.partition(":")[0]).plugin
    except Exception:  # noqa: BLE001 — only a name for the message
        plugin = ""
    ranges = tuple(ENCODER.get(plan_.encoders[enc], "ranges"))
    if ranges and len(frame_shape) == 1:
        ranges = ((min(lo for lo, _ in ranges), max(hi for _, hi in ranges)),)
    return EncoderGuard(sink, plan_.dataset.lengths(), frame_shape, ranges=ranges,
                        component=enc, plugin=plugin)


#: Entries whose clipped values this process has said (once each, written or read).
_SAID_CLIPPING: set[str] = set()


def _say_clipping(enc: str, storage: Storage, guard: EncoderGuard, key: str,
                  meta: dict[str, Any]) -> None:
    """Warn, once per encoder and entry, of values uint8 storage clipped (an output
    outside its declared ranges is the guard's to refuse: its cells fail instead), and
    record the counts in the entry's ``meta`` (``clipped``) for the runs that read it."""
    line = None if guard.violation else storage.clipping(enc)
    if line is not None:
        meta["clipped"] = {"values": storage.values, "below": storage.clipped[0],
                           "above": storage.clipped[1]}
        _SAID_CLIPPING.add(key)
        log.warning("tactbench: warning: %s", line)


def _say_stored_clipping(enc: str, key: str, meta: dict[str, Any]) -> None:
    """The warning of :func:`_say_clipping`, said again (once per process) by a run that
    uses the cached entry instead of writing it: the clipped values are still in it."""
    counts = meta.get("clipped")
    if key in _SAID_CLIPPING or not isinstance(counts, dict):
        return
    storage = Storage.from_meta(meta, len(meta.get("scale") or [1.0]))
    try:  # counts tactbench wrote are integers; anything else says nothing
        storage.values = int(counts.get("values", 0))
        storage.clipped = [int(counts.get("below", 0)), int(counts.get("above", 0))]
    except (TypeError, ValueError, OverflowError):
        return
    line = storage.clipping(enc)
    if line is not None:
        _SAID_CLIPPING.add(key)
        log.warning("tactbench: warning: %s (cached encoding %s, stored so)", line, key)


def _common_meta(plan_: Plan, enc: str, kind: str) -> dict[str, Any]:
    return {"encoder": enc, "encoder_version": plan_.encoder_versions[enc],
            "channels": list(ENCODER.get(plan_.encoders[enc], "channels")),
            "imaging": imaging_identity(plan_.scene, kind),
            "dataset": plan_.dataset.name, "dataset_hash": plan_.dataset_hash}



def entry_layout(plan_: Plan, enc: str, kind: str) -> tuple[tuple[int, ...], Storage]:
    """The frame shape and storage of encoder ``enc``'s entry for input ``kind``
    (``"images"``: ``(channels, h, w)`` at the scene's imaging; ``"vectors"``:
    ``(C·N,)``), as the run writes it."""
    encoder, precision = plan_.encoders[enc], plan_.scene.resolved_precision()
    data = _sized(plan_)
    if kind == "vectors":
        return (vector_width(encoder, data.n_taxels),), vector_storage(encoder, precision)
    h, w = data.image_shape(plan_.scene.resolved_pixel_mm(), plan_.scene.imaging)
    return (len(tuple(ENCODER.get(encoder, "channels"))), h, w), \
        image_storage(encoder, precision)


def entries_bytes(plan_: Plan, pairs: Sequence[tuple[str, str]]) -> int:
    """Bytes the entries of ``pairs`` ((encoder, input kind)) take on disk (their frames;
    the offsets and ``meta.json`` are a few kB)."""
    frames = int(sum(_sized(plan_).lengths()))
    return sum(frames * math.prod(shape) * storage.dtype.itemsize
               for shape, storage in (entry_layout(plan_, *pair) for pair in pairs))


def _sized(plan_: Plan) -> Any:
    """What answers the sizes of ``plan_``'s data set: the data set, or the
    :class:`~tactbench.runner.execution.planning.DatasetSizes` kept when it was let go."""
    return plan_.dataset if plan_.dataset is not None else plan_.sizes


def check_room_runs(cache: EncodingCache, todo: Sequence[tuple[Plan, Sequence[Cell]]]
                    ) -> None:
    """:func:`check_room` for every run of a scene at once (``(plan, its pending cells)``
    each; one plan a run where every run draws its own data set), before any entry is
    written: a run is refused whole, not after its first runs' entries."""
    need: list[tuple[Plan, list[tuple[str, str]]]] = []
    for p, cells in todo:
        pairs = dict.fromkeys((c.encoder, p.input_kind[c.classifier]) for c in cells)
        missing = [pair for pair in pairs if not cache.has(entry_key(p, cache, *pair))]
        if missing and _sized(p) is not None:
            need.append((p, missing))
    if need:
        check_room(cache.root, need[0][0], [], extra=need)


def check_room(root: Path, plan_: Plan, pairs: Sequence[tuple[str, str]], *,
               extra: Sequence[tuple[Plan, Sequence[tuple[str, str]]]] = ()) -> None:
    """Refuse before any encoding when the entries of ``pairs`` (and of each plan's pairs
    in ``extra``: other runs' data sets) would not fit on the disk of ``root``: a
    :class:`StorageError` naming what they need, what is free and how to make room. A
    disk that cannot say how much is free is not refused here (the write itself says
    so, as when space runs out meanwhile)."""
    need = entries_bytes(plan_, pairs) + sum(entries_bytes(p, ps) for p, ps in extra)
    try:
        free = shutil.disk_usage(root).free
    except OSError:
        return
    if need > free:
        names = dict.fromkeys(enc for _, ps in [(plan_, pairs), *extra] for enc, _ in ps)
        runs = len(extra) + bool(pairs)
        raise StorageError(
            f"the encodings of {', '.join(names)}"
            f"{f' for {runs} runs (a data set each)' if runs > 1 else ''} need about "
            f"{human_bytes(need)} in {root}, and its disk has {human_bytes(free)} free; "
            f"make room (tactbench cache prune --max-size SIZE) or set TACTBENCH_CACHE to "
            f"a folder on another disk")


def _store_vectors(plan_: Plan, cache: EncodingCache, keys: dict[str, str],
                   chunk_bytes: int, identities: dict[str, dict[str, Any]]) -> None:
    """The taxel-vector entries: no imaging; each encoder's ``encode_vectors`` gives
    ``(T, C·N)`` frames, its channels side by side (planning refuses an encoder without
    one on vectors). Stored as one channel whose range spans every channel's."""
    dataset = plan_.dataset
    for enc, key in keys.items():
        encoder = plan_.encoders[enc]
        t0 = time.perf_counter()
        (width,), storage = entry_layout(plan_, enc, "vectors")
        check_room(cache.root, plan_, [(enc, "vectors")])
        with cache.entry(key, dataset.lengths(), (width,), storage) as writer:
            guard = _guard(plan_, enc, writer.append, (width,))
            encode_s = encode_vectors(dataset, enc, encoder, guard, chunk_bytes=chunk_bytes)
            _say_clipping(enc, storage, guard, key, writer.meta)
            writer.meta.update({**_common_meta(plan_, enc, "vectors"),
                                **({VIOLATION: guard.violation} if guard.violation else {}),
                                "identity": identities[key],
                                "encode_seconds": encode_s, "encode_cpu_seconds": encode_s,
                                "imaging_seconds": 0.0, "workers": 1,
                                "wall_seconds": time.perf_counter() - t0,
                                "peak_rss_mb": peak_rss_mb()})


def _store_images(plan_: Plan, cache: EncodingCache, keys: dict[str, str],
                  progress: "Progress | None", chunk_bytes: int,
                  identities: dict[str, dict[str, Any]]) -> None:
    """One streaming pass (:func:`~tactbench.encoders.encoding.encode_images`) appends
    every encoder's encoding of each chunk to its entry; all entries appear together at
    the end."""
    scene, dataset = plan_.scene, plan_.dataset
    pixel_mm, method = scene.resolved_pixel_mm(), scene.imaging
    encoders = {enc: plan_.encoders[enc] for enc in keys}
    check_room(cache.root, plan_, [(enc, "images") for enc in keys])
    with contextlib.ExitStack() as stack:
        writers = {}
        for enc, key in keys.items():
            writers[enc] = stack.enter_context(cache.entry(
                key, dataset.lengths(), *entry_layout(plan_, enc, "images")))
        guards = {e: _guard(plan_, e, w.append, w.frame_shape)
                  for e, w in writers.items()}
        times = encode_images(dataset, encoders, guards, pixel_mm=pixel_mm, method=method,
                              progress=progress, chunk_bytes=chunk_bytes)
        for enc, writer in writers.items():
            _say_clipping(enc, writer.storage, guards[enc], keys[enc], writer.meta)
            writer.meta.update({
                **_common_meta(plan_, enc, "images"),
                **({VIOLATION: guards[enc].violation} if guards[enc].violation else {}),
                "identity": identities[keys[enc]],
                "imaging_seconds": times.imaging_seconds,
                # one core's CPU time over the workers: the wall time the encoding
                # alone takes on `workers` cores (cell rows: × workers / frames)
                "encode_seconds": times.cpu_seconds[enc] / times.workers,
                "encode_cpu_seconds": times.cpu_seconds[enc],
                "workers": times.workers,
                "wall_seconds": times.wall_seconds,  # imaging and every encoder of this pass
                "chunk_bytes": chunk_bytes,
                "peak_rss_mb": peak_rss_mb(),
            })
