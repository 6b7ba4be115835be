"""Tracebacks where a line is due: an unusable cache folder, unreadable recordings, a
full disk, a bad scheduler address, options a folder's files ignore, names that would
break a report."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import pytest

from tactbench.datasets.folder import read_folder
from tactbench.errors import InputError, StorageError

ROOT = os.geteuid() == 0 if hasattr(os, "geteuid") else False


def _folder(root: Path) -> Path:
    for cls in ("a", "b"):
        (root / cls).mkdir(parents=True)
        for i in range(2):
            np.save(root / cls / f"r{i}.npy", np.random.default_rng(i).random((4, 3, 3)))
    return root


def test_a_cache_folder_that_is_a_file_is_one_line_before_the_dataset_loads(tmp_path,
                                                                             monkeypatch):
    from tactbench.runner import Scene, run

    (tmp_path / "cache").write_text("a file")
    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    scene = Scene(dataset=str(tmp_path / "missing"), encoders=["raw"], classifiers=["logreg"],
                  L=[2], seeds=[0], out=str(tmp_path / "out"))
    with pytest.raises(InputError, match=r"TACTBENCH_CACHE=.*cache cannot be used"):
        run(scene, progress=False)  # before "missing: no such file or folder"


@pytest.mark.skipif(ROOT, reason="root reads files whatever their permissions")
def test_unreadable_recordings_users_files_and_class_folders_are_one_line(tmp_path):
    root = _folder(tmp_path / "d")
    os.chmod(root / "a" / "r0.npy", 0)
    with pytest.raises(InputError, match=r"r0.npy: cannot read it \(Permission denied\)"):
        read_folder(root)
    os.chmod(root / "a" / "r0.npy", 0o644)
    (root / "users.csv").write_text("recording,user\n")
    os.chmod(root / "users.csv", 0)
    with pytest.raises(InputError, match="cannot read the users file"):
        read_folder(root)
    os.chmod(root / "users.csv", 0o644)
    (root / "users.csv").unlink()
    os.chmod(root / "b", 0)
    try:
        with pytest.raises(InputError, match=r"b: cannot read this class folder"):
            read_folder(root)
    finally:
        os.chmod(root / "b", 0o755)


def test_a_full_disk_is_one_line_and_leaves_nothing_half_written(tmp_path, monkeypatch):
    from tactbench import paths

    real = os.replace

    def full(src, dst):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(paths.os, "replace", full)
    with pytest.raises(StorageError, match=r"cannot write .*x.json: No space left"):
        paths.atomic_write_text(tmp_path / "x.json", "{}")
    monkeypatch.setattr(paths.os, "replace", real)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(StorageError, match="No space left"):
        with paths.atomic_folder(tmp_path / "entry") as tmp:
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp / "frames.npy"))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("address", ["notaurl", "tcp://", "http://x:1", "host:port"])
def test_a_scheduler_address_is_checked_before_any_work(address):
    from tactbench.runner.execution.system import check_scheduler

    with pytest.raises(InputError, match="not a dask scheduler address"):
        check_scheduler(address)
    assert check_scheduler("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    assert check_scheduler("localhost:8786") == "localhost:8786"


def test_options_a_folders_files_would_ignore_are_refused(tmp_path):
    root = _folder(tmp_path / "d")
    with pytest.raises(InputError, match="grid= is for"):
        read_folder(root, grid="3x3")
    with pytest.raises(InputError, match="holds no CSV recordings"):
        read_folder(root, timestamp_column="t")


def test_a_class_name_with_a_newline_is_refused_before_it_breaks_a_report(tmp_path):
    root = _folder(tmp_path / "d")
    os.rename(root / "b", root / "b\nc")
    with pytest.raises(InputError, match=r"holds a control character"):
        read_folder(root)


def test_a_finite_huge_reading_is_not_called_infinite():
    from tactbench.data.recording import Recording

    values = np.zeros((2, 3))
    values[1, 2] = 1e300
    with pytest.raises(InputError, match=r"value of 1e\+300 .*beyond the ±3.4e38"):
        Recording(values, np.arange(2.0), np.arange(3))
    values[1, 2] = np.inf
    with pytest.raises(InputError, match="infinite values"):
        Recording(values, np.arange(2.0), np.arange(3))


def test_a_model_path_that_is_a_folder_or_a_pipe_says_so(tmp_path):
    from tactbench.classifiers.io import read_header
    from tactbench.errors import TactbenchError

    with pytest.raises(TactbenchError, match="is a folder, not a model file"):
        read_header(tmp_path)
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(TactbenchError, match="not a regular file"):
        read_header(tmp_path / "pipe")
    with pytest.raises(TactbenchError, match="does not exist"):
        read_header(tmp_path / "none.safetensors")
