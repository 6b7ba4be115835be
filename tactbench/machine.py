"""The machine a result was computed on, and pinning its CPU kernels.

Light on purpose (standard library only): the CLI calls :func:`pin_cpu_kernels` before any
command runs, and before anything imports torch.
"""

from __future__ import annotations

import os
import platform
import sys

from tactbench.errors import InputError, check_choice


#: ``TACTBENCH_CPU_KERNELS``: pin the CPU kernels of torch (ATen), oneDNN and MKL to one
#: instruction set, so that two x86 machines give bit-identical predictions (see
#: docs/reliability.md, "Numbers across machines"). Each level sets the libraries' own
#: variables, unless set.
KERNELS_ENV = "TACTBENCH_CPU_KERNELS"
#: MKL's ``COMPATIBLE`` branch at every level: it is the one MKL computes alike on Intel
#: and AMD processors (``MKL_CBWR=AVX2`` falls back to ``AUTO`` on an AMD EPYC).
KERNEL_LEVELS = {  # level → (ATEN_CPU_CAPABILITY, ONEDNN_MAX_CPU_ISA, MKL_CBWR, cpu flag)
    "default": ("default", "SSE41", "COMPATIBLE", None),
    "avx2": ("avx2", "AVX2", "COMPATIBLE", "avx2"),
    "avx512": ("avx512", "AVX512_CORE", "COMPATIBLE", "avx512f"),
}
KERNEL_VARIABLES = ("ATEN_CPU_CAPABILITY", "ONEDNN_MAX_CPU_ISA", "MKL_CBWR")


def usable_cores() -> int:
    """The cores this process may use (its CPU affinity where the OS tells it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def cpu_model() -> str:
    """The processor's model name (``/proc/cpuinfo``; ``platform`` elsewhere)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return " ".join(line.split(":", 1)[1].split())
    except OSError:
        pass
    return platform.processor() or platform.machine() or ""


def _cpu_flags() -> set[str] | None:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return None  # not Linux: cannot tell


def pin_cpu_kernels(environ: "dict[str, str] | None" = None) -> str | None:
    """Apply ``TACTBENCH_CPU_KERNELS`` (``default``, ``avx2``, ``avx512``) to the
    libraries' own variables before torch is imported (the CLI calls this first; worker
    processes inherit the environment). A level this CPU lacks is refused: torch would
    take the variable's word and run instructions the CPU does not have. Returns the
    level, or None when the variable is not set."""
    env = os.environ if environ is None else environ
    level = env.get(KERNELS_ENV, "").strip().lower()
    if not level:
        return None
    check_choice(level, KERNELS_ENV, list(KERNEL_LEVELS))
    *values, flag = KERNEL_LEVELS[level]
    flags = _cpu_flags()
    if flag is not None and flags is not None and flag not in flags:
        raise InputError(f"{KERNELS_ENV}={level}: this CPU ({cpu_model()}) has no {flag}; "
                         f"use a level it has (default, or avx2)")
    for name, value in zip(KERNEL_VARIABLES, values):
        env.setdefault(name, value)
    return level


def machine() -> dict[str, object]:
    """What decides a cell's floating-point results besides its identity: the CPU model,
    the instruction set torch's CPU kernels use (``torch.backends.cpu
    .get_cpu_capability()``, when torch is imported), and the variables that pin the
    kernels (see :func:`pin_cpu_kernels`). Recorded in every row and the report."""
    out: dict[str, object] = {"cpu": cpu_model(), "cores": os.cpu_count() or 0}
    torch = sys.modules.get("torch")
    if torch is not None:
        try:
            out["cpu_kernels"] = str(torch.backends.cpu.get_cpu_capability())
        except Exception:  # noqa: BLE001 — an older torch without it: not recorded
            pass
    pinned = {name: os.environ[name] for name in (KERNELS_ENV, *KERNEL_VARIABLES)
              if os.environ.get(name)}
    if pinned:
        out["pinned"] = pinned
    return out
