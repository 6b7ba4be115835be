"""Hardening, round five: identity. A kernel level torch would ignore is refused or
normalised before any key is made, and the key holds what torch computes with."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tactbench.errors import InputError
from tactbench.kernels import (KERNEL_VARIABLES, KERNELS_ENV, _cpu_flags, aten_level,
                               kernels_identity, pin_cpu_kernels)


@pytest.mark.parametrize("given", ["AVX2", " Avx2 ", "avx2"])
def test_an_aten_level_in_another_case_is_written_as_torch_takes_it(given):
    env = {KERNELS_ENV: "native", "ATEN_CPU_CAPABILITY": given}
    if "avx2" not in (_cpu_flags() or set()):
        pytest.skip("this CPU has no AVX2")
    pin_cpu_kernels(env)
    assert env["ATEN_CPU_CAPABILITY"] == "avx2"
    assert kernels_identity(env) == "custom ATEN_CPU_CAPABILITY=avx2"
    assert aten_level(kernels_identity(env)) == "avx2"


@pytest.mark.parametrize("given", ["avx-2", "sse4", "AVX 512", ""])
def test_an_aten_level_torch_would_ignore_is_refused_in_one_line(given):
    with pytest.raises(InputError, match="is not a level torch takes") as err:
        pin_cpu_kernels({KERNELS_ENV: "avx2", "ATEN_CPU_CAPABILITY": given})
    assert "\n" not in str(err.value) and "torch would ignore it" in str(err.value)


def test_an_aten_level_this_cpu_lacks_is_refused(monkeypatch):
    from tactbench import kernels

    monkeypatch.setattr(kernels, "_cpu_flags", lambda: {"sse2", "avx", "avx2"})
    with pytest.raises(InputError, match="has no avx512f, so torch would ignore it"):
        pin_cpu_kernels({KERNELS_ENV: "native", "ATEN_CPU_CAPABILITY": "avx512"})


def test_a_plan_refuses_an_ignored_level_before_any_key(tmp_path, monkeypatch):
    from click.testing import CliRunner

    from tactbench.cli import cli

    monkeypatch.setenv("TACTBENCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "avx-512")
    out = CliRunner().invoke(cli, ["run", "--dataset", "synthetic-forearm:users=2,"
                                   "repetitions=1", "--encoder", "raw", "--classifier",
                                   "logreg:max_iter=20", "-L", "3", "--seed", "0",
                                   "--out", str(tmp_path / "out")])
    assert out.exit_code != 0 and "ATEN_CPU_CAPABILITY='avx-512'" in out.output
    assert "Traceback" not in out.output and not (tmp_path / "out" / "cells").exists()


@pytest.mark.slow("starts a fresh Python that imports torch (~3 s)")
def test_the_key_names_what_torch_computes_with():
    """Upper case ``AVX2`` (torch ignores it: AVX-512 where the CPU has it) is written as
    ``avx2`` before torch is imported, so torch computes with what the key says."""
    if "avx2" not in (_cpu_flags() or set()):
        pytest.skip("this CPU has no AVX2")
    code = ("import tactbench, torch; from tactbench.kernels import kernels_identity, "
            "aten_level; print(aten_level(kernels_identity()), "
            "torch.backends.cpu.get_cpu_capability())")
    env = {k: v for k, v in os.environ.items() if k not in KERNEL_VARIABLES}
    env.update({KERNELS_ENV: "native", "ATEN_CPU_CAPABILITY": "AVX2"})
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["avx2", "AVX2"]
    assert "ignoring invalid value" not in done.stderr


def test_a_worker_refuses_a_custom_key_its_torch_does_not_follow():
    import torch  # noqa: F401 — the capability this process computes with

    from tactbench.runner.execution.cell import check_kernels

    here = torch.backends.cpu.get_cpu_capability().lower()
    check_kernels({"cpu_kernels": f"custom ATEN_CPU_CAPABILITY={here}"})
    other = "default" if here != "default" else "avx2"
    with pytest.raises(RuntimeError, match="computes with"):
        check_kernels({"cpu_kernels": f"custom ATEN_CPU_CAPABILITY={other}"})
