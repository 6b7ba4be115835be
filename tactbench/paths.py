"""Where tactbench keeps files it can recompute (caches), and how it writes files: atomically.

Every file or folder tactbench writes is first built under a *temporary name* beside its
target and renamed over it when complete, so a reader sees the old version or the new
one, never half of one. A temporary name says who made it:
``.<target>.tmp-<pid>-<host>-<random>`` (``host``: 8 hex digits of the machine's name), so
a temporary whose process is gone (killed mid-write) is recognised as an *orphan* by
:func:`temporaries` and removed by :func:`remove_orphans` at the next start.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import shutil
import socket
import tempfile
import uuid
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from tactbench.errors import InputError, storage_error

CACHE_ENV = "TACTBENCH_CACHE"

#: ``.<target>.<kind>-<pid>[-<host>][-<random>]``: kind ``tmp`` (being written) or ``bad``
#: (a damaged artefact moved aside to be deleted). Names from before the pid was recorded
#: (``.<target>.tmp-<random>``) have no pid.
_TEMP = re.compile(r"^\.(?P<target>.+)\.(?P<kind>tmp|bad)-(?:(?P<pid>\d+)"
                   r"(?:-(?P<host>[0-9a-f]{8}))?(?:-[0-9a-z]+)?|[0-9a-z_]+)$")


def cache_root() -> Path:
    """``$TACTBENCH_CACHE``, else ``$XDG_CACHE_HOME/tactbench`` or ``~/.cache/tactbench``
    (not created)."""
    root = os.environ.get(CACHE_ENV)
    if root:
        return expand_env_path(root, CACHE_ENV)
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg:
        return expand_env_path(xdg, "XDG_CACHE_HOME") / "tactbench"
    try:
        home = Path.home()
    except (RuntimeError, KeyError):  # no HOME and no password entry (a bare container)
        raise InputError(f"this process has no home folder to keep its cache in (HOME "
                         f"is not set); set {CACHE_ENV} to a folder") from None
    return home / ".cache" / "tactbench"


def expand_env_path(text: str, name: str) -> Path:
    """A path given through the environment variable ``name`` (a ``.env`` file, a
    notebook's ``os.environ``: no shell expanded it), with ``~`` and ``$VARIABLE`` /
    ``${VARIABLE}`` expanded as a shell would; a variable that is not set is one line
    (a folder named ``$HOME`` in the working folder is never what was meant)."""
    expanded = os.path.expanduser(os.path.expandvars(text))
    unset = re.search(r"\$(\w+|\{[^}]*\})", expanded)
    if unset:
        raise InputError(f"{name}={text} names the environment variable "
                         f"{unset.group(1).strip('{}')}, which is not set; set it or give "
                         f"the folder itself")
    if expanded.startswith("~"):  # ~user of no such user
        raise InputError(f"{name}={text}: {expanded.split('/')[0]} is not a user's home "
                         f"folder here; give the folder itself")
    return Path(expanded)


def cache_dir(*parts: str) -> Path:
    """``$TACTBENCH_CACHE`` or ``~/.cache/tactbench`` (``$XDG_CACHE_HOME`` respected), joined
    with ``parts``; created on first use."""
    root = os.environ.get(CACHE_ENV)
    base = cache_root()
    path = base.joinpath(*parts)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file, read-only, no permission: known before any work
        where = f"${CACHE_ENV}={root}" if root else f"the cache folder {base}"
        raise InputError(f"{where} cannot be used: {path} cannot be made "
                         f"({exc.strerror or exc}); set {CACHE_ENV} to a writable "
                         f"folder") from None
    return path


def host_tag() -> str:
    """8 hex digits naming this machine (its host name's SHA-256), for temporary names."""
    return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]


def temp_name(target: str, kind: str = "tmp") -> str:
    """A fresh temporary name for ``target``: ``.<target>.<kind>-<pid>-<host>-<random>``."""
    return f".{target}.{kind}-{os.getpid()}-{host_tag()}-{uuid.uuid4().hex[:8]}"


@dataclass(frozen=True)
class Temporary:
    """A temporary file or folder beside its target (see the module docstring)."""

    path: Path
    target: str  # the name it was going to have (a cache key, a row's file name)
    pid: int | None  # the process writing it (None: a name from before pids were recorded)
    state: str  # "orphaned" (its process is gone), "in progress", or "other host"

    @property
    def orphaned(self) -> bool:
        return self.state == "orphaned"


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists, someone else's (or cannot tell: keep it)
    return True


def parse_temporary(path: str | Path) -> Temporary | None:
    """The :class:`Temporary` that ``path`` names, or None when it is not a temporary name.

    A temporary of this machine whose process no longer runs is ``"orphaned"``, as is
    one named before pids were recorded; one of another machine (a shared cache) is
    ``"other host"``: its process cannot be checked from here.
    """
    path = Path(path)
    match = _TEMP.match(path.name)
    if match is None:
        return None
    pid = int(match["pid"]) if match["pid"] else None
    if match["kind"] == "bad" or pid is None:
        state = "orphaned" if pid is None or not _alive(pid) else "in progress"
    elif match["host"] and match["host"] != host_tag():
        state = "other host"
    else:
        state = "in progress" if _alive(pid) else "orphaned"
    return Temporary(path, match["target"], pid, state)


def temporaries(folder: str | Path) -> list[Temporary]:
    """The temporary files and folders directly in ``folder``, by name."""
    try:
        children = sorted(Path(folder).iterdir())
    except FileNotFoundError:
        return []
    return [t for c in children if (t := parse_temporary(c)) is not None]


def remove_path(path: str | Path) -> None:
    """Delete a file or a folder tree; nothing when it is already gone."""
    path = Path(path)
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def remove_orphans(folder: str | Path) -> list[Temporary]:
    """Delete the orphaned temporaries in ``folder`` (their writers are gone); returns them."""
    gone = [t for t in temporaries(folder) if t.orphaned]
    for t in gone:
        remove_path(t.path)
    return gone


def discard(path: str | Path) -> bool:
    """Remove a damaged artefact so that a new one can take its name: renamed aside first
    (atomic: readers and writers see it or nothing), then deleted. False when it was
    already gone (another process discarded it first)."""
    path = Path(path)
    aside = path.with_name(temp_name(path.name, "bad"))
    try:
        os.rename(path, aside)
    except FileNotFoundError:
        return False
    remove_path(aside)
    return True


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` so that ``path`` holds either the old or the new content, never half."""
    atomic_write_bytes(path, text.encode())


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, flush it to disk, rename it over
    ``path``: readers see the old file or the new one, never half of one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(temp_name(path.name))
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            full = storage_error(exc, path)
            if full is not None:
                raise full from None
        raise


#: What ``rename(2)`` says when the target folder exists and is not empty.
_TAKEN = (errno.ENOTEMPTY, errno.EEXIST)


@contextmanager
def atomic_folder(folder: str | Path) -> Iterator[Path]:
    """Build a folder under a temporary name beside ``folder``; rename it to ``folder``
    when the block ends without an error, else remove it.

    Readers see no folder or the complete one, never half of one. When ``folder``
    appeared meanwhile (another process finished the same entry first: ``rename`` fails
    with ENOTEMPTY or EEXIST), theirs is kept and ours dropped; any other failure of the
    rename is raised. The temporary is named by :func:`temp_name`
    (``.<name>.tmp-<pid>-...``), so one left by a killed process is found as an orphan.
    """
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.with_name(temp_name(folder.name))
    tmp.mkdir()

    def lost_race(exc: OSError) -> None:  # theirs is kept; anything else is raised
        if exc.errno not in _TAKEN or not folder.is_dir():
            raise exc

    with _renamed_into_place(tmp, folder, lost_race):
        yield tmp


@contextmanager
def _renamed_into_place(tmp: Path, folder: Path, taken) -> Iterator[None]:
    """The block fills ``tmp``, then ``tmp`` is renamed to ``folder``; a rename that
    fails is handed to ``taken(exc)`` (which raises or accepts it); a full disk is one
    line (:func:`storage_error`); ``tmp`` is removed whatever happens."""
    try:
        yield
        try:
            os.rename(tmp, folder)
        except OSError as exc:
            taken(exc)
    except OSError as exc:  # a full disk while the folder was written: one line
        full = storage_error(exc, folder)
        if full is not None:
            raise full from None
        raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# ------------------------------------------------------------------ what a command may write
#
# One rule for every command that writes a file or folder the user named: it never
# replaces its own input, never writes inside the cache folder (``cache clear`` deletes
# what is there), and never replaces what tactbench did not write. Each command says how
# it recognises its own earlier output (``ours``); anything else that exists is refused
# with one line before any work starts.


def _same_or_inside(path: Path, other: Path) -> bool:
    try:
        a, b = path.resolve(), other.resolve()
    except (OSError, RuntimeError):
        return False
    return a == b or b in a.parents


def _in_cache(path: Path) -> Path | None:
    """The cache folder when ``path`` is it or lies inside it (without creating it)."""
    base = cache_root()
    return base if _same_or_inside(path, base) else None


def check_not_in_cache(path: str | Path, option: str = "--out") -> None:
    """Refuse an output that is the cache folder or inside it: ``tactbench cache clear``
    removes what is there, and ``cache ls`` would call it damaged."""
    cache = _in_cache(Path(path))
    if cache is not None:
        raise InputError(f"{option} {path} is inside the cache folder {cache} "
                         f"(${CACHE_ENV}), which 'tactbench cache clear' empties; write "
                         f"results elsewhere")


def _writable_parent(path: Path, option: str, verb: str = "written") -> None:
    folder = path.absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"{option} {path} cannot be {verb}: {folder} is a file, not a "
                         f"folder")
    _probe(folder, f"{option} {path}")


def _probe(folder: Path, what: str) -> None:
    """Create and remove a file in ``folder``: permissions alone do not tell whether it
    can be written (root, a read-only mount)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".tactbench-probe-", dir=folder)
    except OSError as exc:
        where = "" if what.endswith(str(folder)) else f" ({folder})"
        raise InputError(f"{what} cannot be written: {exc.strerror or exc}{where}") from None
    os.close(fd)
    os.unlink(probe)


@contextmanager
def _usable_path(path: Path, option: str):
    """Turn what the file system says of ``path`` into one line naming ``option``: a NUL
    in the name (a ``ValueError``), or an ``OSError``; an ``InputError`` passes as is."""
    try:
        yield
    except InputError:
        raise
    except ValueError as exc:
        raise InputError(f"{option} {path!r} is not a usable path: {exc}") from None
    except OSError as exc:
        raise InputError(f"{option} {path} cannot be used: {exc.strerror or exc}") from None


def check_output_file(path: str | Path, *, option: str = "--out", inputs=(),
                      ours=None) -> Path:
    """Refuse, before any work, an output file that would lose something (the rule above).

    ``inputs``: the files the command reads (the output may be none of them);
    ``ours(path)``: whether an existing ``path`` is tactbench's earlier output of this
    command, which it may replace. Also refused: a folder at ``path``, a parent that is
    a file or cannot be written, a path in the cache folder. Returns ``path``.
    """
    path = Path(path)
    with _usable_path(path, option):
        for src in inputs:
            if _same_or_inside(path, Path(src)):
                raise InputError(f"{option} {path} is the input {src}; tactbench never "
                                 f"replaces its input, give another name")
        check_not_in_cache(path, option)
        if path.is_dir():
            raise InputError(f"{option} {path} is a folder; give a file name")
        if path.exists() or path.is_symlink():
            if ours is None:
                raise InputError(f"{option} {path} exists, and this command does not "
                                 f"replace files; give a new name, or remove it first "
                                 f"(nothing was written)")
            if not ours(path):
                raise InputError(f"{option} {path} exists and tactbench did not write it; "
                                 f"give a new name, or remove it first (nothing was written)")
        _writable_parent(path, option)
    return path


#: What file managers leave in any folder they show (tactbench neither reads nor writes it).
LITTER = (".DS_Store", "Thumbs.db", "desktop.ini")


def check_output_folder(path: str | Path, *, option: str = "--out", inputs=(),
                        ours=None) -> Path:
    """:func:`check_output_file` for a folder, the one check of every folder a command
    writes (``tactbench run --out`` included): it may not exist yet (its parent must be
    writable), or be empty, or hold only what this command writes, ``ours(entry)`` for
    each entry at its top (a temporary of an entry, ``.NAME.tmp-*``, counts as the
    entry; :data:`LITTER` is ignored). A folder holding anything else is refused, naming
    what it holds; a folder kept must be writable, and so must its subfolders.
    """
    path = Path(path)
    with _usable_path(path, option):
        for src in inputs:
            if _same_or_inside(path, Path(src)) or _same_or_inside(Path(src), path):
                raise InputError(f"{option} {path} overlaps the input {src}; tactbench "
                                 f"never writes over its input, give another folder")
        check_not_in_cache(path, option)
        if path.exists() and not path.is_dir():
            raise InputError(f"{option} {path} is a file, not a folder; give a folder")
        if not path.is_dir():
            _writable_parent(path, option, "made")
            return path
        entries = sorted(path.iterdir())
        foreign = [e.name for e in entries if not _is_ours(e, ours)]
        if foreign and ours is None:
            shown = ", ".join(repr(n) for n in foreign[:3]) + (", …" if len(foreign) > 3
                                                               else "")
            what = ("a tactbench dataset" if (path / "manifest.json").is_file()
                    else f"files ({shown})")
            raise InputError(f"{option} {path} already holds {what}; tactbench does not "
                             f"replace them: give a new or empty folder (nothing was "
                             f"written)")
        if foreign:
            raise InputError(f"{option} {path} holds files tactbench did not write "
                             f"({', '.join(repr(n) for n in foreign[:3])}); give a new or "
                             f"empty folder, or one an earlier run wrote")
        for folder in [path, *(e for e in entries if e.is_dir() and not e.is_symlink())]:
            _probe(folder, f"{option} {path}")
    return path


def _is_ours(entry: Path, ours) -> bool:
    """Whether ``entry`` may stay in an output folder (see :func:`check_output_folder`)."""
    if entry.name in LITTER:
        return True
    if ours is None:
        return False
    temporary = _TEMP.match(entry.name)
    return bool(ours(entry.with_name(temporary["target"]) if temporary else entry))


@contextmanager
def publish_folder(folder: str | Path, option: str = "--out") -> Iterator[Path]:
    """Write a new folder whole or not at all, and refuse a second writer.

    The block writes into a temporary sibling (:func:`temp_name`); when it ends without
    an error the temporary is renamed to ``folder``. ``folder`` may not exist or be
    empty (a rename replaces an empty folder); when another process filled it meanwhile
    (two ``data synth`` runs into one new folder) the rename fails and this writer is
    refused in one line, its temporary removed: one wins whole, the other is refused.
    """
    folder = Path(folder)
    with _usable_path(folder, option):
        folder.absolute().parent.mkdir(parents=True, exist_ok=True)
        tmp = folder.absolute().with_name(temp_name(folder.absolute().name))
        tmp.mkdir()

    def refused(exc: OSError) -> None:  # another writer filled it: this one is refused
        if exc.errno not in _TAKEN and exc.errno != errno.EISDIR:
            raise exc
        raise InputError(f"{option} {folder} was filled by another process while this "
                         f"one wrote; it was left as that process wrote it (nothing of "
                         f"this run was kept)") from None

    with _renamed_into_place(tmp, folder, refused):
        yield tmp
