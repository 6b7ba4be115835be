"""Exit statuses mean one thing each (0 ok, 1 failed cells or a bug, 2 a user's mistake,
130 interrupted), output never crashes on the terminal's encoding, --json is JSON."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import EXIT_CODES_TEXT, cli, json_text


def _strict(text: str):
    def refuse(name):
        raise ValueError(f"{name} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_json_output_never_holds_nan_or_infinity():
    doc = {"a": float("nan"), "b": [1.0, float("inf"), -float("inf")],
           "c": np.float32("nan"), "d": np.array([0.5, np.nan]), "e": "NaN"}
    assert _strict(json_text(doc)) == {"a": None, "b": [1.0, None, None], "c": None,
                                       "d": [0.5, None], "e": "NaN"}


def test_ctrl_c_in_a_command_exits_130_in_one_line(monkeypatch):
    from tactbench.commands import inspect

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(inspect.list_cmd, "callback", interrupted)
    result = CliRunner().invoke(cli, ["list"])
    assert result.exit_code == 130, result.output
    assert "interrupted" in result.output and "Traceback" not in result.output


def test_the_exit_statuses_are_in_the_cli_reference():
    from tactbench.clidoc import render

    text = render()
    for status in ("| 0 |", "| 1 |", "| 2 |", "| 130 |"):
        assert status in text
    assert "130 interrupted" in EXIT_CODES_TEXT


def test_a_forced_ascii_terminal_does_not_crash_on_the_times_sign(tmp_path):
    root = tmp_path / "d"
    for cls in ("a", "b"):
        (root / cls).mkdir(parents=True)
        np.save(root / cls / "r.npy", np.random.default_rng(0).random((4, 3, 3)))
    env = {**os.environ, "PYTHONIOENCODING": "ascii", "LC_ALL": "C"}
    done = subprocess.run([sys.executable, "-m", "tactbench", "data", "info", str(root)],
                          env=env, capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    assert b"\\xd7" in done.stdout  # "×" as an escape, not a UnicodeEncodeError


@pytest.mark.slow("a real run with two worker processes is interrupted mid-training")
def test_ctrl_c_with_two_workers_exits_130_without_worker_tracebacks(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "TACTBENCH_CACHE": str(tmp_path / "cache")}
    # long enough that Ctrl-C lands mid-training (the quick profile's 16-px concat head is
    # fast); that the workers are ended, not waited for, is test_stop_workers_ends_…
    clf = "small-cnn-lstm:epochs=400,windows_per_epoch=256,batch_size=16,input_size=16"
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 1\n")
    proc = subprocess.Popen(
        [sys.executable, "-m", "tactbench", "run", "--dataset",
         "synthetic-forearm:users=2,repetitions=1", "--encoder", "raw", "--classifier", clf,
         "-L", "2", "--seed", "0", "--seed", "1", "--pixel-mm", "10", "--threads", "1",
         "--workers", "2", "--out", str(out), "--no-plots", str(scene)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
        # an earlier test may leave SIGINT ignored in pytest, and a child inherits that
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 180
    # wait until the workers train: the encodings are cached and no cell has finished
    while time.time() < deadline and proc.poll() is None and not any(
            (tmp_path / "cache").rglob("meta.json")):
        time.sleep(0.1)
    time.sleep(8)  # the spawned workers import torch and start their cells
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C sends: the whole process group
    try:
        stdout, stderr = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise AssertionError("Ctrl-C did not stop the run within 120 s") from None
    text = stderr.decode(errors="replace")
    assert proc.returncode == 130, text[-2000:]
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text[-2000:]
    assert "interrupted" in text
    assert len(list((out / "cells").glob("*.json"))) < 2, "interrupted after the grid ended"


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads process states from /proc")
def test_stop_workers_ends_running_workers_instead_of_waiting_for_them():
    """Ctrl-C during `run --workers N` ends the workers' running cells: the pool's
    processes are terminated (shutdown() alone forgets them, and the interpreter's exit
    then waits for every running task)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from tactbench.runner.execution.system import stop_workers

    pool = ProcessPoolExecutor(max_workers=2, mp_context=multiprocessing.get_context("spawn"))
    futures = [pool.submit(time.sleep, 300) for _ in range(3)]  # a builtin: no import
    deadline = time.time() + 60
    while time.time() < deadline and len(pool._processes or {}) < 2:
        time.sleep(0.1)
    processes = list(pool._processes.values())
    assert len(processes) == 2
    time.sleep(2)
    assert not any(f.done() for f in futures)  # both workers are in their 300-s task
    stop_workers(pool)
    # by pid: the pool's own thread may reap a worker first, and is_alive() then errs
    pids = [p.pid for p in processes]
    deadline = time.time() + 20
    while time.time() < deadline and any(_running(pid) for pid in pids):
        time.sleep(0.1)
    assert not any(_running(pid) for pid in pids), "a worker was left running its task"
    assert futures[2].cancelled() or futures[2].done()


# ----------------------------------------------------------------------- round three


def test_a_full_or_closed_stdout_is_one_line_exit_2(tmp_path):
    full = subprocess.run(f"{sys.executable} -m tactbench list > /dev/full", shell=True,
                          capture_output=True, text=True, timeout=120)
    assert full.returncode == 2, full.stderr
    assert full.stderr.strip().splitlines() == [full.stderr.strip()]
    assert "could not be written" in full.stderr and "Traceback" not in full.stderr
    proc = subprocess.Popen([sys.executable, "-m", "tactbench", "list", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # the reader went away (`| head` that exited)
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 2 and "Broken pipe" in err and "Traceback" not in err


def test_an_unreachable_dask_scheduler_is_one_line(monkeypatch):
    pytest.importorskip("distributed")
    from distributed import Client

    from tactbench.errors import InputError
    from tactbench.runner.execution import executors

    monkeypatch.setattr(executors, "SCHEDULER_TIMEOUT_S", 2)
    with pytest.raises(InputError, match="the dask scheduler cannot be reached"):
        executors._connect(Client, "tcp://127.0.0.1:9")
