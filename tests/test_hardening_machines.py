"""Numbers across machines: a row records the CPU and the kernels torch used; one machine
gives identical predictions whatever runs beside it; TACTBENCH_CPU_KERNELS pins them."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tactbench.errors import InputError
from tactbench.kernels import (
    KERNEL_LEVELS,
    KERNEL_VARIABLES,
    KERNELS_ENV,
    _cpu_flags,
    pin_cpu_kernels,
)
from tactbench.machine import describe_machines, machine


def test_machine_facts_name_the_cpu_and_the_kernels():
    import torch

    facts = machine()
    assert facts["cpu"] and facts["cores"] >= 1
    assert facts["cpu_kernels"] == torch.backends.cpu.get_cpu_capability()
    text = describe_machines([{"machine": facts}, {"machine": facts}, {}])
    assert text.count(facts["cpu"]) == 1 and "not recorded" in text


def test_pinning_the_kernels_sets_what_torch_honours():
    env = {KERNELS_ENV: "default", "ONEDNN_MAX_CPU_ISA": "AVX2"}
    assert pin_cpu_kernels(env) == "default"
    assert env["ATEN_CPU_CAPABILITY"] == "default" and env["MKL_CBWR"] == "COMPATIBLE"
    assert env["ONEDNN_MAX_CPU_ISA"] == "AVX2"  # a variable already set is kept
    code = ("from tactbench.machine import machine; "
            "from tactbench.kernels import pin_cpu_kernels; "
            "pin_cpu_kernels(); import torch, json; torch.ones(1); "
            "print(json.dumps(machine()))")
    child = {k: v for k, v in os.environ.items() if k not in KERNEL_VARIABLES}
    child[KERNELS_ENV] = "default"
    done = subprocess.run([sys.executable, "-c", code], env=child, capture_output=True,
                          text=True, timeout=120)
    facts = json.loads(done.stdout)
    assert facts["cpu_kernels"] == "DEFAULT"  # torch took the pin
    assert facts["pinned"] == {KERNELS_ENV: "default", "ATEN_CPU_CAPABILITY": "default",
                               "ONEDNN_MAX_CPU_ISA": "SSE41", "MKL_CBWR": "COMPATIBLE",
                               "NPY_DISABLE_CPU_FEATURES": KERNEL_LEVELS["default"][3],
                               "OPENCV_CPU_DISABLE": KERNEL_LEVELS["default"][4]}


def test_a_kernel_level_the_cpu_lacks_is_refused():
    with pytest.raises(InputError, match="unknown TACTBENCH_CPU_KERNELS 'sse9'"):
        pin_cpu_kernels({KERNELS_ENV: "sse9"})
    flags = _cpu_flags()
    if flags is None or "avx512f" in flags:
        pytest.skip("this CPU has AVX-512 (or does not say): no level above it to refuse")
    with pytest.raises(InputError, match="has no avx512f"):
        pin_cpu_kernels({KERNELS_ENV: "avx512"})
    out = subprocess.run([sys.executable, "-m", "tactbench", "list"],
                         env={**os.environ, KERNELS_ENV: "avx512"}, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 2 and out.stderr.startswith("Error: TACTBENCH_CPU_KERNELS")


@pytest.mark.slow("two fresh tactbench processes train the same cell, one beside a CPU-bound load")
def test_one_cell_gives_identical_predictions_in_fresh_processes_under_load(tmp_path):
    """The guarantee the docs state: one machine, one thread count, whatever runs
    beside it. Two fresh processes (own caches), the second beside a CPU-bound load."""
    scene = tmp_path / "scene.toml"
    scene.write_text("test_per_class = 2\n")
    clf = "small-cnn-lstm:epochs=1,windows_per_epoch=96,batch_size=16,input_size=16"

    def cell(name: str) -> dict:
        out = tmp_path / name
        env = {**os.environ, "TACTBENCH_CACHE": str(tmp_path / f"cache-{name}")}
        done = subprocess.run(
            [sys.executable, "-m", "tactbench", "run", "--dataset",
             "synthetic-forearm:users=2,repetitions=1", "--encoder", "raw",
             "--classifier", clf, "-L", "3", "--seed", "0", "--pixel-mm", "10",
             "--threads", "2", "--out", str(out), "--no-plots", "--json", str(scene)],
            env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        [row] = [json.loads(p.read_text()) for p in (out / "cells").glob("*.json")]
        assert "machine:" in (out / "report.md").read_text()
        return row

    quiet = cell("quiet")
    burner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        loaded = cell("loaded")
    finally:
        burner.kill()
        burner.wait()
    assert quiet["key"] == loaded["key"]
    assert quiet["test_predictions"] == loaded["test_predictions"]
    assert quiet["confusion"] == loaded["confusion"]
    assert quiet["accuracy"] == loaded["accuracy"]
    assert quiet["machine"]["cpu"] and quiet["machine"] == loaded["machine"]


def _child(code: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in (*KERNEL_VARIABLES, KERNELS_ENV)}
    done = subprocess.run([sys.executable, "-c", code], env={**clean, **env},
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_importing_tactbench_pins_the_kernels_before_numpy_and_says_when_it_came_late():
    flags = _cpu_flags()
    if flags is None or "avx2" not in flags:
        pytest.skip("this CPU has no AVX2 (or does not say): the default is native here")
    code = ("import os, tactbench; from tactbench.kernels import kernels_identity; "
            "print(kernels_identity(), os.environ['ATEN_CPU_CAPABILITY'], "
            "os.environ['MKL_CBWR'])")
    assert _child(code) == "avx2 avx2 COMPATIBLE"
    late = _child("import numpy; " + code)
    assert late.startswith("unpinned ") and "numpy imported before tactbench" in late
    native = _child(code.replace("os.environ['ATEN_CPU_CAPABILITY'], "
                                 "os.environ['MKL_CBWR']", "'-'"),
                    TACTBENCH_CPU_KERNELS="native")
    assert native.startswith("native ") and native.endswith(" -")


def test_a_cell_keyed_to_other_kernels_is_refused_by_a_worker_computing_with_these():
    from tactbench.runner.execution.cell import check_kernels

    import torch  # noqa: F401 — what the worker computes with is torch's capability

    here = torch.backends.cpu.get_cpu_capability().lower()
    check_kernels({"cpu_kernels": here})  # the same: nothing to say
    other = "default" if here != "default" else "avx2"
    with pytest.raises(RuntimeError, match=f"identity says {other}"):
        check_kernels({"cpu_kernels": other})
