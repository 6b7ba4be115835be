"""The one way tactbench writes files and folders: atomically."""

from __future__ import annotations

import os

import pytest

from tactbench.paths import atomic_folder, atomic_write_bytes, atomic_write_text, cache_dir


def test_atomic_write_replaces_whole_files_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "sub" / "row.json"
    atomic_write_text(target, "old")
    atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"new"
    assert [p.name for p in target.parent.iterdir()] == ["row.json"]


def test_atomic_write_that_fails_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "row.json"
    atomic_write_text(target, "kept")

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError):
        atomic_write_text(target, "lost")
    assert target.read_text() == "kept"


def test_atomic_folder_appears_complete_or_not_at_all(tmp_path):
    target = tmp_path / "cache" / "entry"
    with pytest.raises(RuntimeError):
        with atomic_folder(target) as tmp:
            (tmp / "half.npy").write_bytes(b"x")
            raise RuntimeError("crash while writing")
    assert not target.exists() and list((tmp_path / "cache").iterdir()) == []
    with atomic_folder(target) as tmp:
        assert tmp.name.startswith(".entry.tmp-")
        (tmp / "who").write_text("first")
        assert not target.exists()
    assert (target / "who").read_text() == "first"


def test_atomic_folder_keeps_the_entry_that_finished_first(tmp_path):
    target = tmp_path / "entry"
    with atomic_folder(target) as tmp:
        (tmp / "who").write_text("first")
    with atomic_folder(target) as tmp:  # a second writer of the same key loses the race
        (tmp / "who").write_text("second")
    assert (target / "who").read_text() == "first"
    assert [p.name for p in tmp_path.iterdir()] == ["entry"]


def test_cache_dir_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "c"))
    assert cache_dir("encodings") == tmp_path / "c" / "encodings"
    assert (tmp_path / "c" / "encodings").is_dir()


def test_temporary_names_say_which_process_on_which_machine_wrote_them(tmp_path):
    from tactbench.paths import host_tag, parse_temporary, temp_name

    name = temp_name("abc.json")
    assert name.startswith(f".abc.json.tmp-{os.getpid()}-{host_tag()}-")
    mine = parse_temporary(tmp_path / name)
    assert (mine.target, mine.pid, mine.state) == ("abc.json", os.getpid(), "in progress")
    other = "0" * 8 if host_tag() != "0" * 8 else "1" * 8
    away = parse_temporary(tmp_path / f".k.tmp-{os.getpid()}-{other}-aa")
    assert away.state == "other host" and not away.orphaned  # its pid means nothing here
    assert parse_temporary(tmp_path / ".k.tmp-ab_c9xyz").state == "orphaned"  # pre-pid name
    assert parse_temporary(tmp_path / f".k.bad-{os.getpid()}-{host_tag()}-aa").state == \
        "in progress"
    for plain in ("k", ".hidden", "k.tmp-1", ".k.tmp-"):
        assert parse_temporary(tmp_path / plain) is None, plain


def test_atomic_folder_raises_a_rename_that_fails_for_another_reason(tmp_path, monkeypatch):
    import errno

    def refused(src, dst):
        raise OSError(errno.EACCES, "Permission denied")

    (tmp_path / "entry").mkdir()
    (tmp_path / "entry" / "x").write_text("old")
    monkeypatch.setattr(os, "rename", refused)
    with pytest.raises(PermissionError):
        with atomic_folder(tmp_path / "entry") as tmp:
            (tmp / "x").write_text("new")
    assert [p.name for p in tmp_path.iterdir()] == ["entry"]  # the temporary went too


def test_an_interrupted_atomic_write_leaves_no_temporary(tmp_path, monkeypatch):
    def broken_fsync(fd):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", broken_fsync)
    with pytest.raises(OSError):
        atomic_write_text(tmp_path / "row.json", "x")
    assert list(tmp_path.iterdir()) == []


def test_discard_moves_aside_then_deletes(tmp_path):
    from tactbench.paths import discard

    (tmp_path / "entry").mkdir()
    (tmp_path / "entry" / "x").write_text("x")
    assert discard(tmp_path / "entry") is True
    assert discard(tmp_path / "entry") is False  # already gone: another process was first
    assert list(tmp_path.iterdir()) == []
