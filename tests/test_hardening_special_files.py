"""Only regular files are read, with a size limit before reading, in every reader
(tactbench.integrity.check_regular_file / read_regular_bytes, decided by os.stat before
any open): a FIFO (opening one blocks), a device (/dev/zero reads forever) or a dangling
link is one line naming it, never a hang or a memory blow-up; inside a dataset folder it
is an error naming it, never a recording silently left out."""

from __future__ import annotations

import contextlib
import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest

from tactbench.errors import CorruptArtefactError, InputError, TactbenchError
from tactbench.integrity import check_regular_file, read_regular_bytes, special_file_problem

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs (POSIX)")

ZERO = Path("/dev/zero")


@contextlib.contextmanager
def deadline(seconds: int = 20):
    """Fail, instead of hanging the suite, when the block blocks (a FIFO opened)."""
    def expired(*_):
        raise TimeoutError("blocked: a special file was opened")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def specials(folder: Path, name: str) -> dict[str, Path]:
    """``name`` as a FIFO, as a link to /dev/zero and as a dangling link, in ``folder``."""
    made = {}
    for kind in ("fifo", "zero", "dangling"):
        where = folder / kind
        where.mkdir(parents=True, exist_ok=True)
        path = where / name
        if kind == "fifo":
            os.mkfifo(path)
        else:
            path.symlink_to(ZERO if kind == "zero" else where / "gone")
        made[kind] = path
    return made


WORDS = {"fifo": "FIFO", "zero": "character device", "dangling": "dangling link"}


def test_the_shared_check_names_each_kind_before_opening(tmp_path):
    for kind, path in specials(tmp_path, "x.json").items():
        with deadline():
            assert WORDS[kind] in special_file_problem(path)
            with pytest.raises(InputError, match=WORDS[kind]):
                read_regular_bytes(path, limit=100)
    big = tmp_path / "big.json"
    big.write_bytes(b"1" * 200)
    with pytest.raises(InputError, match="more than the"):
        check_regular_file(big, limit=100)
    assert read_regular_bytes(big, limit=200) == b"1" * 200
    assert special_file_problem(tmp_path / "absent") is None  # "no such file" is the reader's


def test_a_scene_file_that_is_a_fifo_or_a_device_is_one_line(tmp_path):
    from tactbench.runner.execution.scene_files import load_scene_file

    for kind, path in specials(tmp_path, "scene.toml").items():
        with deadline(), pytest.raises(TactbenchError, match=WORDS[kind]):
            load_scene_file(path)


def test_rows_and_results_json_that_are_special_files_never_block(tmp_path):
    """A row that is a FIFO or /dev/zero is a damaged row; results.json is never read
    (the cells are the one store), so one that is a special file changes nothing."""
    from tactbench.runner.execution.results import ResultStore

    REPORT_JSON = "results.json"

    for kind in ("fifo", "zero"):
        store = ResultStore(tmp_path / kind)
        store.cells.mkdir(parents=True)
        row, report = store.path("k"), store.out / REPORT_JSON
        if kind == "fifo":
            os.mkfifo(row)
            os.mkfifo(report)
        else:
            row.symlink_to(ZERO)
            report.symlink_to(ZERO)
        with deadline():
            with pytest.raises(CorruptArtefactError, match=WORDS[kind]):
                store.read("k")
            assert store.get("k") is None  # a damaged row: the cell is computed again
            assert store.stored_rows() == []  # nothing sound, results.json not opened


def test_a_cache_entrys_metadata_that_is_a_special_file_is_a_damaged_entry(tmp_path):
    from tactbench.runner.execution.cache import EncodingCache
    from tactbench.runner.execution.entries import readable_meta, verify_entry

    cache = EncodingCache(tmp_path / "cache")
    for kind in ("fifo", "zero", "frames"):
        folder = cache.write(f"key{kind}", [np.zeros((2, 1, 3, 3), np.float32)],
                             {"encoder": "raw"})
        target = folder / ("frames.npy" if kind == "frames" else "meta.json")
        target.unlink()
        if kind == "fifo":
            os.mkfifo(target)
        else:
            target.symlink_to(ZERO)
        with deadline():
            with pytest.raises(CorruptArtefactError, match="FIFO|character device"):
                verify_entry(folder)
            if kind != "frames":
                assert readable_meta(folder) == {}


def test_layouts_logs_and_text_datasets_that_are_special_files_are_one_line(tmp_path):
    from tactbench.can.logs import read_messages
    from tactbench.data.layout_io import load_layout
    from tactbench.datasets.cost import read_cost_csv
    from tactbench.datasets.cyskin_text import read_cyskin_text

    readers = [(load_layout, "layout.json"), (load_layout, "layout.csv"),
               (lambda p: list(read_messages(p)), "log.asc"),
               (read_cyskin_text, "rec.txt"), (read_cost_csv, "cost.csv")]
    for reader, name in readers:
        for kind, path in specials(tmp_path / name.replace(".", "_"), name).items():
            with deadline(), pytest.raises(TactbenchError, match=WORDS[kind]):
                reader(path)


@pytest.mark.parametrize("kind", ["fifo", "zero", "dangling"])
def test_a_special_file_inside_a_dataset_folder_is_named_never_left_out(tmp_path, kind):
    from tactbench.datasets.folder import read_folder

    root = tmp_path / "rec"
    for cls in ("a", "b"):
        (root / cls).mkdir(parents=True)
        for i in range(3):
            np.save(root / cls / f"r{i}.npy", np.random.default_rng(i).random((4, 3, 3)))
    path = specials(tmp_path / "made", "r9.npy")[kind]
    os.rename(path, root / "a" / "r9.npy")
    with deadline(), pytest.raises(InputError, match=WORDS[kind]) as err:
        read_folder(root)
    assert "r9.npy" in str(err.value)


def test_a_dataset_folders_manifest_or_arrays_that_are_special_files_are_one_line(tmp_path):
    from tactbench.data.dataset import Dataset
    from tactbench.datasets.synthetic_forearm import generate

    ds = generate(users=1, positions=1, repetitions=1, workers=1)
    for name in ("manifest.json", "arrays.npz"):
        folder = tmp_path / name
        ds.save(folder)
        (folder / name).unlink()
        os.mkfifo(folder / name)
        with deadline(), pytest.raises(InputError, match="FIFO"):
            Dataset.load(folder)


def test_the_cli_says_a_fifo_scene_file_in_one_line(tmp_path):
    import subprocess
    import sys

    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    done = subprocess.run([sys.executable, "-m", "tactbench", "run", str(fifo)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "FIFO" in done.stderr
    assert json.dumps(done.stderr).count("\\n") <= 2  # one line (and a progress line)


def test_special_files_where_a_writer_looks_for_its_own_output_are_not_opened(tmp_path):
    from click.testing import CliRunner

    from tactbench.cli import cli

    seq = tmp_path / "seq.npy"
    np.save(seq, np.random.default_rng(0).random((3, 6, 6)).astype(np.float32))
    os.mkfifo(tmp_path / "enc.json")  # where encode -o enc looks for its metadata
    os.mkfifo(tmp_path / "pic.png")  # where data preview looks for its own PNG
    os.mkfifo(tmp_path / "in.npy")
    (tmp_path / "out").mkdir()
    os.mkfifo(tmp_path / "out" / "report.md")  # where run looks for its own report
    calls = [["encode", "-i", str(seq), "-o", str(tmp_path / "enc"), "-e", "raw"],
             ["encode", "-i", str(tmp_path / "in.npy"), "-o", str(tmp_path / "x"),
              "-e", "raw"],
             ["data", "preview", "synthetic-forearm:users=1", "--out",
              str(tmp_path / "pic.png")],
             ["run", "--dataset", "synthetic-forearm:users=1", "--encoder", "raw",
              "--classifier", "logreg", "--out", str(tmp_path / "out")]]
    for args in calls:
        with deadline():
            result = CliRunner().invoke(cli, args)
        assert result.exit_code == 2, (args, result.output)


@pytest.mark.parametrize("kind", ["fifo", "zero", "dangling"])
def test_a_special_file_inside_a_cyskin_text_folder_is_named(tmp_path, kind):
    from tactbench.datasets.cyskin_text import read_cyskin_folder

    root = tmp_path / "cyskin" / "tap"
    root.mkdir(parents=True)
    path = specials(tmp_path / "made", "r1.txt")[kind]
    os.rename(path, root / "r1.txt")
    with deadline(), pytest.raises(InputError, match=WORDS[kind]):
        read_cyskin_folder(tmp_path / "cyskin")
