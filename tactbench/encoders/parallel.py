"""Encoding many sequences at once, on every core.

:func:`encode_all` is what the runner calls to encode a dataset. Sequences are
independent, so they are spread over ``workers`` threads (default) or
processes; results come back in input order.

Why threads by default: OpenCV's flow functions and numpy's large-array
operations release the GIL, so two threads keep two cores busy without the
start-up (≈ 1–3 s per process to import numpy, OpenCV and torch) and the
copying of processes. benchmarks/encoders.py measures both
(docs/encoders.md, "Encoding a dataset"). Each worker's library thread pools
(OpenCV, torch) are limited to one thread while :func:`encode_all` runs, so
``workers`` threads use ``workers`` cores instead of fighting over them.
"""

from __future__ import annotations

import contextlib
import os
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from tactbench.errors import InputError

MODES = ("threads", "processes", "serial")


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def single_threaded_libraries() -> Iterator[None]:
    """Limit OpenCV's and torch's own thread pools to 1 thread, restored afterwards.

    Only libraries already imported are touched (this must not import torch).
    """
    import sys

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
    if mode not in MODES:
        raise InputError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    total = len(sequences)
    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise InputError(f"workers must be ≥ 1, got {workers}")
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

    from concurrent import futures

    results: list[np.ndarray | None] = [None] * total
    if mode == "threads":
        executor: futures.Executor = futures.ThreadPoolExecutor(max_workers=workers)
        limits = single_threaded_libraries()
    else:
        import multiprocessing

        # forkserver, not fork: a forked child of a process whose OpenMP/torch
        # threads are running can deadlock.
        ctx = multiprocessing.get_context("forkserver")
        executor = futures.ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                               initializer=_init_process)
        limits = contextlib.nullcontext()
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
