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
