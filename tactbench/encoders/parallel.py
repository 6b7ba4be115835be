"""Encoding many sequences at once, on every core.

:func:`encode_all` encodes a list of sequences with one encoder. Sequences are
independent, so they are spread over ``workers`` threads (default) or
processes; results come back in input order.

Why threads by default: OpenCV's flow functions and numpy's large-array
operations release the GIL, so two threads keep two cores busy without the
start-up (≈ 1–3 s per process to import numpy, OpenCV and torch) and the
copying of processes. benchmarks/encoders.py measures both
(docs/encoders.md, "Encoding a dataset"). Each worker's library thread pools
(OpenCV, torch) are limited to one thread while :func:`encode_all` runs, so
``workers`` threads use ``workers`` cores instead of fighting over them.

:func:`encode_chunks` is the streaming form the encoding pass
(:func:`tactbench.encoders.encoding.encode_images`) uses: chunks of sequences
come from an iterator (imaged as they are asked for), every encoder of a mapping encodes
each chunk on one pool of workers kept for the whole stream, and the next chunk is
already queued while the caller stores the previous one. Memory is a few chunks, not the
dataset; the workers never wait at a chunk's end.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import sys
import time
from collections import deque
from concurrent import futures
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np

from tactbench.errors import InputError
from tactbench.machine import usable_cores

MODES = ("threads", "processes", "serial")


def default_workers() -> int:
    """The cores this process may use (:func:`tactbench.machine.usable_cores`)."""
    return usable_cores()


@contextlib.contextmanager
def single_threaded_libraries() -> Iterator[None]:
    """Limit OpenCV's and torch's own thread pools to 1 thread, restored afterwards.

    Only libraries already imported are touched (this must not import torch).
    """
    restore: list[Callable[[], None]] = []
    cv2 = sys.modules.get("cv2")
    if cv2 is not None:
        old_cv = cv2.getNumThreads()
        cv2.setNumThreads(1)
        restore.append(lambda: cv2.setNumThreads(old_cv))
    torch = sys.modules.get("torch")
    if torch is not None:
        old_torch = torch.get_num_threads()
        torch.set_num_threads(1)
        restore.append(lambda: torch.set_num_threads(old_torch))
    try:
        yield
    finally:
        for undo in reversed(restore):
            undo()


def _init_process() -> None:
    import cv2

    cv2.setNumThreads(1)
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # torch is optional for numpy/OpenCV encoders
        pass


def _encode_one(encoder: Any, seq: np.ndarray) -> np.ndarray:
    return encoder.encode(seq)


def _encode_timed(encoder: Any, seq: np.ndarray) -> tuple[np.ndarray, float]:
    """``encoder.encode(seq)`` and the CPU seconds this thread spent on it (one core)."""
    t0 = time.thread_time()
    out = encoder.encode(seq)
    return out, time.thread_time() - t0


def _checked_args(mode: str, workers: int | None) -> int:
    if mode not in MODES:
        raise InputError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise InputError(f"workers must be ≥ 1, got {workers}")
    return workers


def _pool(workers: int, mode: str) -> tuple[Any, Any]:
    """``(executor, limits)``: a pool of ``workers`` and the context to run it in."""
    if mode == "threads":
        return futures.ThreadPoolExecutor(max_workers=workers), single_threaded_libraries()

    # forkserver, not fork: a forked child of a process whose OpenMP/torch
    # threads are running can deadlock.
    ctx = multiprocessing.get_context("forkserver")
    return (futures.ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                        initializer=_init_process),
            contextlib.nullcontext())


def encode_all(encoder: Any, sequences: Sequence[np.ndarray], *, workers: int | None = None,
               progress: Callable[[int, int], None] | None = None,
               mode: str = "threads") -> list[np.ndarray]:
    """Encode every sequence with ``encoder``; outputs in input order.

    Parameters
    ----------
    encoder : an encoder (``encode(seq)``: ``(T, H, W)`` → ``(T, C, H, W)``)
    sequences : sequence of arrays ``(T_i, H_i, W_i)``; lengths and sizes may differ
    workers : how many sequences to encode at once (default: the usable cores)
    progress : ``progress(done, total)``, called in the caller's thread after
        each sequence (and once with ``done = 0``)
    mode : ``"threads"`` (default), ``"processes"`` (the encoder must pickle)
        or ``"serial"``

    A bad sequence raises :class:`~tactbench.errors.InputError` naming its index; any
    other error (a bug in the encoder) keeps its type, with the index in a note.
    """
    workers = _checked_args(mode, workers)
    total = len(sequences)
    workers = min(workers, max(1, total))
    if progress:
        progress(0, total)
    if total == 0:
        return []
    if workers == 1 or mode == "serial":
        out = []
        for i, seq in enumerate(sequences):
            out.append(_checked(encoder.encode, seq, i))
            if progress:
                progress(i + 1, total)
        return out

    results: list[np.ndarray | None] = [None] * total
    executor, limits = _pool(workers, mode)
    with limits, executor:
        pending = {executor.submit(_encode_one, encoder, seq): i
                   for i, seq in enumerate(sequences)}
        done = 0
        try:
            for fut in futures.as_completed(pending):
                i = pending[fut]
                results[i] = _checked(fut.result, None, i)
                done += 1
                if progress:
                    progress(done, total)
        except BaseException:
            for fut in pending:
                fut.cancel()
            raise
    return results  # type: ignore[return-value]


def _checked(fn: Callable[..., np.ndarray], arg: Any, index: int) -> np.ndarray:
    """``fn(arg)`` (or ``fn()``), with the index of the sequence added to any error."""
    try:
        return fn(arg) if arg is not None else fn()
    except InputError as exc:  # the user's bad sequence: one line that says which
        raise InputError(f"sequence {index}: {exc}") from exc
    except Exception as exc:  # a bug keeps its type and traceback, with a note
        if hasattr(exc, "add_note"):  # Python ≥ 3.11
            exc.add_note(f"while encoding sequence {index}")
        raise


def _results(queued: tuple[int, dict[str, list[futures.Future]]]):
    """A queued chunk ``(start, name → futures)`` as ``(start, name → their result)``."""
    start, pending = queued
    return start, {name: [fut.result for fut in futs] for name, futs in pending.items()}


@dataclass
class EncodedChunk:
    """One chunk of :func:`encode_chunks`'s stream, encoded by every encoder."""

    start: int  # index of the chunk's first sequence in the whole stream
    encoded: dict[str, list[np.ndarray]]  # encoder name → ``(T_i, C, H, W)``, in input order
    cpu_seconds: dict[str, float]  # encoder name → CPU seconds its encoding took, one core


def encode_chunks(encoders: Mapping[str, Any], chunks: Iterable[Sequence[np.ndarray]], *,
                  workers: int | None = None, mode: str = "threads", ahead: int = 1,
                  total: int | None = None,
                  progress: Callable[..., None] | None = None) -> Iterator[EncodedChunk]:
    """Encode a stream of chunks of sequences with every encoder, chunk by chunk, in order.

    Parameters
    ----------
    encoders : name → encoder (``encode(seq)``: ``(T, H, W)`` → ``(T, C, H, W)``)
    chunks : an iterable of chunks, each a sequence of arrays ``(T_i, H, W)``; it is
        read lazily, one chunk ahead of the chunk being handed back, so a generator
        that images the next chunk runs while the workers encode
    workers : sequences encoded at once (default: the usable cores); one pool of
        workers serves the whole stream
    ahead : chunks queued beyond the one being handed back (memory: about
        ``ahead + 2`` chunks of inputs and ``ahead + 1`` of outputs)
    total, progress : ``progress(done, total, encoder=name)`` after each sequence an
        encoder finished (in input order, in the caller's thread); ``total`` is the
        stream's sequence count if known

    Yields one :class:`EncodedChunk` per input chunk. Errors are those of
    :func:`encode_all`, with the sequence's index in the whole stream.
    """
    workers = _checked_args(mode, workers)
    ahead = int(ahead)
    if ahead < 0:
        raise InputError(f"ahead must be ≥ 0, got {ahead}")
    done = dict.fromkeys(encoders, 0)

    def report(name: str) -> None:
        done[name] += 1
        if progress:
            progress(done[name], total, encoder=name)

    def collect(start: int, pending: dict[str, list[Callable[[], Any]]]) -> EncodedChunk:
        """The chunk from ``start``: ``pending[name][i]()`` gives ``(encoded, cpu s)``."""
        encoded: dict[str, list[np.ndarray]] = {}
        seconds = dict.fromkeys(pending, 0.0)
        for name, results in pending.items():
            encoded[name] = []
            for i, result in enumerate(results):
                out, cpu = _checked(result, None, start + i)
                encoded[name].append(out)
                seconds[name] += cpu
                report(name)
        return EncodedChunk(start, encoded, seconds)

    if workers == 1 or mode == "serial":
        start = 0
        for chunk in chunks:
            yield collect(start, {name: [functools.partial(_encode_timed, enc, seq)
                                         for seq in chunk]
                                  for name, enc in encoders.items()})
            start += len(chunk)
        return

    executor, limits = _pool(workers, mode)
    queue: deque[tuple[int, dict[str, list[Any]]]] = deque()
    with limits, executor:
        try:
            start = 0
            for chunk in chunks:
                queue.append((start, {name: [executor.submit(_encode_timed, enc, seq)
                                             for seq in chunk]
                                      for name, enc in encoders.items()}))
                start += len(chunk)
                del chunk  # the queued tasks hold the inputs until they are done
                while len(queue) > ahead:
                    yield collect(*_results(queue.popleft()))
            while queue:
                yield collect(*_results(queue.popleft()))
        except BaseException:
            for _, pending in queue:
                for futs in pending.values():
                    for fut in futs:
                        fut.cancel()
            raise
