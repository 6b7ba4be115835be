"""Hardening, round five: processes. The Python API from a plain script or standard input
(cells in this process rather than workers that would run the script again), a pool that
breaks is an error naming the cause and the fix, and workers that outlive their run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import pytest

from tactbench.errors import WorkerError
from tactbench.runner.execution import executors
from tactbench.runner.execution.system import main_reimport_problem

ROOT = Path(__file__).resolve().parents[1]


def _problem_seen_from(tmp_path, monkeypatch, source: str, *, write: bool = True):
    """What :func:`main_reimport_problem` says when called from the top level of a main
    module whose file holds ``source`` (``write=False``: a main with no file there)."""
    path = tmp_path / "script.py"
    if write:
        path.write_text(source)
    main = types.ModuleType("__main__")
    main.__file__ = str(path) if write else "<stdin>"
    main.__spec__ = None
    seen: list = []
    main.probe = lambda: seen.append(main_reimport_problem())
    monkeypatch.setitem(sys.modules, "__main__", main)
    exec(compile(source, main.__file__, "exec"), vars(main))
    return seen[0]


def test_a_top_level_call_without_the_guard_is_seen(tmp_path, monkeypatch):
    said = _problem_seen_from(tmp_path, monkeypatch, "x = 1\nprobe()\n")
    assert "calls tactbench at its top level" in said and "if __name__" in said


@pytest.mark.parametrize("source", [
    'if __name__ == "__main__":\n    probe()\n',
    "def main():\n    probe()\n\n\nif '__main__' == __name__:\n    x = 1\n    main()\n",
])
def test_a_guarded_call_is_safe(tmp_path, monkeypatch, source):
    assert _problem_seen_from(tmp_path, monkeypatch, source) is None


def test_a_program_read_from_standard_input_is_seen(tmp_path, monkeypatch):
    said = _problem_seen_from(tmp_path, monkeypatch, "probe()\n", write=False)
    assert "<stdin>" in said and "cannot read again" in said


def test_a_notebook_or_python_c_is_not_imported_again(monkeypatch):
    monkeypatch.setitem(sys.modules, "__main__", types.ModuleType("__main__"))
    assert main_reimport_problem() is None


def test_python_m_tactbench_is_not_imported_again(monkeypatch):
    """A package's ``__main__`` calls at its top level, unguarded, but a spawned worker
    never runs it again (multiprocessing skips ``*.__main__``)."""
    import importlib.util

    main = types.ModuleType("__main__")
    main.__spec__ = importlib.util.find_spec("tactbench.__main__")
    main.__file__ = main.__spec__.origin
    monkeypatch.setitem(sys.modules, "__main__", main)
    seen: list = []
    main.probe = lambda: seen.append(main_reimport_problem())
    exec(compile("probe()\n", main.__file__, "exec"), vars(main))
    assert seen == [None]


def _job(thing):
    from tactbench.runner.execution.planning import Cell

    return types.SimpleNamespace(cell=Cell("raw", "logreg", 3, 0, "k"), thing=thing)


def test_a_job_a_worker_could_not_receive_runs_in_this_process(monkeypatch):
    """A component defined in a notebook (its ``__main__`` has no file to import again)
    or one that does not pickle: the cells run here instead of failing in workers."""
    notebook = types.ModuleType("__main__")

    class Encoder:  # as if defined in a notebook cell
        pass

    Encoder.__module__, Encoder.__qualname__ = "__main__", "Encoder"
    notebook.Encoder = Encoder
    monkeypatch.setitem(sys.modules, "__main__", notebook)
    said = executors.unsendable_problem([_job(Encoder())])
    assert "defined in this notebook or prompt" in said and "raw × logreg" in said
    said = executors.unsendable_problem([_job(lambda x: x)])
    assert "cannot be sent to a worker process" in said
    assert executors.unsendable_problem([_job(3)]) is None
    notebook.__file__ = "/somewhere/script.py"  # a script's main is imported again
    assert executors.unsendable_problem([_job(Encoder())]) is None


WORKERS = """\
import os
import signal


def die_at_start(*args):  # a worker that cannot start (as an unimportable main module)
    os._exit(3)


def killed_on_b(job):  # a worker killed mid-cell (as by the out-of-memory killer)
    if job == "b":
        os.kill(os.getpid(), signal.SIGKILL)
    return {"key": job, "status": "ok"}
"""


def _workers_module(tmp_path, monkeypatch):
    """Functions a spawned worker can import (the tests folder is not on its path)."""
    import importlib
    import uuid

    name = f"r5_workers_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(WORKERS)
    monkeypatch.syspath_prepend(str(tmp_path))
    return importlib.import_module(name)


def test_workers_that_cannot_start_are_an_error_naming_the_fix(tmp_path, monkeypatch):
    helpers = _workers_module(tmp_path, monkeypatch)
    # the pool's initializer, pickled by name: the spawned worker runs the helper's
    monkeypatch.setattr(executors, "_start_local_worker", helpers.die_at_start)
    stored: list = []
    with pytest.raises(WorkerError, match=r"cannot start here \(a worker exit status 3\).*"
                                          r"--workers 1"):
        executors.run_processes(["a", "b"], stored.append, workers=2)
    assert stored == []


def test_a_worker_killed_mid_run_is_an_error_not_failed_rows(tmp_path, monkeypatch):
    helpers = _workers_module(tmp_path, monkeypatch)
    monkeypatch.setattr(executors, "run_cell", helpers.killed_on_b)
    stored: list = []
    with pytest.raises(WorkerError, match="a worker process died while cells ran") as err:
        executors.run_processes(["a", "b", "c", "d"], stored.append, workers=1)
    assert "SIGKILL" in str(err.value) and "run again" in str(err.value)
    assert [r["key"] for r in stored] == ["a"]  # what finished first is stored


SCRIPT = """\
from tactbench.runner import Scene, run
report = run(Scene(dataset="synthetic-forearm:users=2,repetitions=1", encoders=["raw"],
                   classifiers=["logreg:max_iter=20"], L=[3], seeds=[0, 1], pixel_mm=10,
                   test_per_class=1, workers=2, out={out!r}), progress=False, plots=False)
print("computed", report.computed, sorted(r["status"] for r in report.rows))
"""


@pytest.mark.slow("starts Python twice and runs a two-cell grid in each (~6 s)")
@pytest.mark.parametrize("how", ["file", "stdin"])
def test_the_api_from_a_plain_script_or_stdin_computes_every_cell(tmp_path, how):
    script = tmp_path / "plain.py"
    script.write_text(SCRIPT.format(out=str(tmp_path / "out")))
    env = {**os.environ, "TACTBENCH_CACHE": str(tmp_path / "cache")}
    args = [sys.executable, str(script)] if how == "file" else [sys.executable, "-"]
    done = subprocess.run(args, input=None if how == "file" else script.read_text(),
                          capture_output=True, text=True, cwd=tmp_path, env=env,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "computed 2 ['ok', 'ok']" in done.stdout
    assert "run one at a time in this process" in done.stderr
    assert "Traceback" not in done.stderr


KILLED_PARENT = """\
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, {helpers!r})


def write_and_wait(folder):  # a cell half-way through writing its output
    from tactbench.paths import atomic_folder

    with atomic_folder(Path(folder) / "entry") as tmp:
        (tmp / "frames").write_text("partial")
        (Path(folder) / f"pid-{{os.getpid()}}").write_text("")
        time.sleep(120)


if __name__ == "__main__":
    from tactbench.runner.execution import executors

    import parent_main
    executors.run_cell = parent_main.write_and_wait
    executors.run_processes([{a!r}, {b!r}], print, workers=2)
"""


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return True
    return state in ("Z", "X")  # a zombie no init has reaped yet holds no memory


@pytest.mark.slow("starts a parent process and two spawned workers, then kills the parent")
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_of_a_killed_run_end_and_leave_no_temporaries(tmp_path):
    import time

    folders = [tmp_path / "a", tmp_path / "b"]
    for f in folders:
        f.mkdir()
    (tmp_path / "parent_main.py").write_text(KILLED_PARENT.format(
        helpers=str(tmp_path), a=str(folders[0]), b=str(folders[1])))
    log = tmp_path / "stderr.txt"
    with log.open("w") as err:
        parent = subprocess.Popen([sys.executable, str(tmp_path / "parent_main.py")],
                                  cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=err)
    try:
        deadline = time.monotonic() + 120
        while sum(1 for f in folders for _ in f.glob("pid-*")) < 2:
            assert parent.poll() is None, log.read_text()
            assert time.monotonic() < deadline, "the workers did not start"
            time.sleep(0.2)
        workers = [int(p.name[4:]) for f in folders for p in f.glob("pid-*")]
        assert any(p.name.startswith(".entry.tmp-") for f in folders for p in f.iterdir())
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.monotonic() + 10
    while not all(_gone(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert all(_gone(pid) for pid in workers), "workers outlived their run"
    left = [p.name for f in folders for p in f.iterdir() if not p.name.startswith("pid-")]
    assert left == [], log.read_text()  # each removed its temporary on its way out


WATCHED = """\
import subprocess, sys, time
import os
child = subprocess.Popen([sys.executable, "-c", {child!r}, str(os.getpid())])
print(child.pid, flush=True)
time.sleep(60)
"""
WATCHER = """\
import os, signal, sys, threading, time
from tactbench.runner.execution import system
parent = int(sys.argv[1])
def ended(signum, frame):
    open({marker!r}, "w").write("ended")
    os._exit(0)
signal.signal(signal.SIGTERM, ended)
threading.Thread(target=system._watch_parent, args=(parent,), daemon=True).start()
print("watching", flush=True)
time.sleep(60)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_watchdog_ends_a_worker_whose_parent_died(tmp_path):
    """Where no parent-death signal exists, a thread watching the parent ends the worker."""
    import time

    marker = tmp_path / "ended"
    parent = subprocess.Popen(
        [sys.executable, "-c", WATCHED.format(child=WATCHER.format(marker=str(marker)))],
        stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())
        assert parent.stdout.readline().strip() == "watching"
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.monotonic() + 10
    while not marker.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert marker.read_text() == "ended"
    deadline = time.monotonic() + 5
    while not _gone(child) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _gone(child)
