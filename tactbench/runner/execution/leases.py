"""Leases on cache entries: what a running run is using, so that ``cache prune`` and
``cache clear`` never delete it under the run.

A run holds one *lease* for its whole life: a file ``<cache>/.leases/<pid>-<host>-<random>.lease``
whose first line is a JSON header (``pid``, ``host``, ``started``, ``command``) and whose
further lines are the keys of the entries the run uses, appended as it plans them (before
it checks or encodes them). The run keeps the file open with an exclusive ``flock``: the
kernel lets go of the lock when the process (and every worker that inherited it) ends,
however it ends, so a lease whose lock can be taken belongs to a run that is gone and is
removed. Where the file system cannot lock (``ENOLCK``), a lease of this machine is live
while its pid runs, and one of another machine is taken as live.

A ``flock`` on the cache folder itself orders the two sides: a run adds keys under a shared lock, a
prune or clear decides and removes under an exclusive one, so an entry is either leased
before the pruner looks or removed before the run checks it (and then encoded again).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

from tactbench.paths import _alive, host_tag

LEASES = ".leases"
_SUFFIX = ".lease"


@dataclass(frozen=True)
class LeaseInfo:
    """A live lease as a pruner sees it."""

    path: Path
    pid: int | None
    host: str
    started: float
    keys: frozenset[str] = field(default_factory=frozenset)

    def describe(self, now: float | None = None) -> str:
        """``"pid 123 on this machine, started 5 min ago"``."""
        where = "this machine" if self.host == host_tag() else f"host {self.host}"
        ago = max(0, int((now or time.time()) - self.started))
        return f"pid {self.pid} on {where}, started {ago // 60} min {ago % 60} s ago"


@contextlib.contextmanager
def cache_lock(root: Path, *, exclusive: bool) -> Iterator[None]:
    """The cache-wide lock (shared: adding to a lease; exclusive: pruning, clearing). A
    cache that cannot be written or locked is not locked (nothing can be removed from
    it either)."""
    try:  # the cache folder itself is the lock: nothing is made for it
        fd = os.open(root, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        except OSError:
            pass  # a file system without locks: go on unordered
        yield
    finally:
        os.close(fd)  # releases the lock


class Lease:
    """This process's lease on entries of the cache at ``root`` (see the module); a no-op
    where the cache cannot be written."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.path: Path | None = None
        self.keys: set[str] = set()
        self._fd: int | None = None
        self._failed = False
        self._started = time.time()

    def open(self) -> "Lease":
        """Start the lease; its file is made at the first :meth:`hold` (a run refused
        before it uses the cache leaves nothing there)."""
        self._started = time.time()
        return self

    def _make(self) -> None:
        folder = self.root / LEASES
        name = f"{os.getpid()}-{host_tag()}-{uuid.uuid4().hex[:8]}"
        tmp = folder / f".{name}.tmp"
        header = {"pid": os.getpid(), "host": host_tag(), "started": self._started,
                  "command": " ".join(sys.argv)[:500]}
        for _ in range(5):  # the folder of leases is removed by the last lease to close
            try:
                folder.mkdir(parents=True, exist_ok=True)
                fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
                break
            except FileNotFoundError:
                continue
            except OSError:
                self._failed = True
                return  # a read-only cache: nothing can be pruned from it
        else:
            self._failed = True
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            pass  # no locks here: the pid in the header tells a pruner
        os.write(fd, (json.dumps(header) + "\n").encode())
        os.rename(tmp, folder / f"{name}{_SUFFIX}")  # locked before any pruner sees it
        self._fd, self.path = fd, folder / f"{name}{_SUFFIX}"

    def hold(self, keys: Iterable[str]) -> None:
        """Add ``keys`` to the lease (call before the entries are checked or written)."""
        new = sorted(set(keys) - self.keys)
        if not new:
            return
        if self._fd is None and not self._failed:
            self._make()
        if self._fd is None:
            return
        with cache_lock(self.root, exclusive=False):
            os.write(self._fd, "".join(f"{k}\n" for k in new).encode())
        self.keys.update(new)

    def close(self) -> None:
        if self._fd is None:
            return
        if self.path is not None:
            self.path.unlink(missing_ok=True)
        os.close(self._fd)
        self._fd = None
        with contextlib.suppress(OSError):  # the last lease: no folder left behind
            (self.root / LEASES).rmdir()


def _lock_free(fd: int) -> bool | None:
    """Whether nobody holds the lease's lock (True: its run is gone); None: cannot tell."""
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as exc:
        if exc.errno in (errno.EAGAIN, errno.EACCES):
            return False
        return None
    fcntl.flock(fd, fcntl.LOCK_UN)
    return True


def _read(path: Path) -> LeaseInfo | None:
    """The lease at ``path`` when its run is alive; a dead run's lease is removed."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None  # gone meanwhile (its run ended), or not a file we can read
    try:
        lines = os.read(fd, 1 << 26).decode(errors="replace").split("\n")
        free = _lock_free(fd)
    finally:
        os.close(fd)
    try:
        header = json.loads(lines[0])
        pid, host, started = int(header["pid"]), str(header["host"]), float(header["started"])
    except (ValueError, KeyError, TypeError):
        pid, host, started = None, "?", 0.0
    if free is None:  # no locks: judge by the pid where it can be checked
        free = pid is not None and host == host_tag() and not _alive(pid)
    if free:
        path.unlink(missing_ok=True)
        return None
    return LeaseInfo(path, pid, host, started, frozenset(x for x in lines[1:-1] if x))


def live_leases(root: Path) -> list[LeaseInfo]:
    """Every live lease on the cache at ``root`` (removing those of runs that are gone)."""
    try:
        paths = sorted((Path(root) / LEASES).glob(f"*{_SUFFIX}"))
    except OSError:
        return []
    return [info for p in paths if (info := _read(p)) is not None]


def leased_keys(root: Path) -> dict[str, LeaseInfo]:
    """Entry key → a live lease holding it."""
    return {k: info for info in live_leases(root) for k in info.keys}
