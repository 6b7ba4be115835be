"""The CPU kernels a run computes with: pinned to one instruction set, so that a cell's
numbers are the same on every x86-64 machine that has it (docs/reliability.md, "Numbers
across machines").

Standard library only: ``import tactbench`` pins the kernels (:func:`pin_cpu_kernels`)
before numpy, OpenCV or torch are imported, the command line again before any command;
:func:`kernels_identity` is what a cell's identity holds of them.
"""

from __future__ import annotations

import os
import platform
import sys

from tactbench.errors import InputError, check_choice

#: ``TACTBENCH_CPU_KERNELS``: the CPU kernels torch (ATen), oneDNN and MKL compute with.
#: Pinned to one instruction set by default, so that two x86-64 machines give
#: bit-identical predictions at one thread count (docs/reliability.md, "Numbers across
#: machines"); ``native`` leaves the libraries alone (faster on a wider instruction set,
#: and its results are this machine's alone). Each level sets the libraries' own variables.
KERNELS_ENV = "TACTBENCH_CPU_KERNELS"
#: The level a run uses when ``TACTBENCH_CPU_KERNELS`` is not set, on a CPU that has it;
#: on one without it (not x86-64, or an x86 without AVX2) the default is ``native``.
DEFAULT_KERNELS = "avx2"
#: The level that leaves every library to choose for this CPU.
NATIVE = "native"
#: What each level sets (each variable unless already set): torch's ATen kernels, oneDNN's
#: convolutions, MKL's BLAS (its ``COMPATIBLE`` branch, the one MKL computes alike on
#: Intel and AMD processors: ``MKL_CBWR=AVX2`` falls back to ``AUTO`` on an AMD EPYC),
#: numpy's SIMD loops (its dispatch targets above the level; names of numpy 1.x and 2.x)
#: and OpenCV's (the encoders' flow). The last entry is the CPU flag the level needs.
_NUMPY_ABOVE_AVX2 = ("X86_V4 AVX512_ICL AVX512_SPR AVX512F AVX512CD AVX512_KNL AVX512_KNM "
                     "AVX512_SKX AVX512_CLX AVX512_CNL")
KERNEL_LEVELS = {  # level → (ATen, oneDNN, MKL, numpy disabled, OpenCV disabled, cpu flag)
    "default": ("default", "SSE41", "COMPATIBLE",
                "X86_V3 AVX AVX2 F16C FMA3 " + _NUMPY_ABOVE_AVX2, "AVX,FP16,AVX2,AVX512-SKX",
                None),
    "avx2": ("avx2", "AVX2", "COMPATIBLE", _NUMPY_ABOVE_AVX2, "AVX512-SKX", "avx2"),
    "avx512": ("avx512", "AVX512_CORE", "COMPATIBLE", "AVX512_ICL AVX512_SPR", "",
               "avx512f"),
}
KERNEL_VARIABLES = ("ATEN_CPU_CAPABILITY", "ONEDNN_MAX_CPU_ISA", "MKL_CBWR",
                    "NPY_DISABLE_CPU_FEATURES", "OPENCV_CPU_DISABLE")
#: The libraries that read those variables when they are imported.
PINNED_LIBRARIES = ("numpy", "cv2", "torch")
#: The libraries of :data:`PINNED_LIBRARIES` already imported when the kernels were first
#: pinned in this process (their kernels were chosen before the pin); None: not pinned yet.
_imported_before_pin: tuple[str, ...] | None = None


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


def default_kernels(flags: "set[str] | None" = None) -> str:
    """The level used when ``TACTBENCH_CPU_KERNELS`` is not set: :data:`DEFAULT_KERNELS`
    on a CPU with AVX2, else ``native`` (another architecture, an old x86, or a system
    that does not say)."""
    flags = _cpu_flags() if flags is None else flags
    wanted = KERNEL_LEVELS[DEFAULT_KERNELS][-1]
    return DEFAULT_KERNELS if flags is not None and wanted in flags else NATIVE


def pin_cpu_kernels(environ: "dict[str, str] | None" = None) -> str:
    """Apply ``TACTBENCH_CPU_KERNELS`` (``avx2``, the default where the CPU has it;
    ``default``, ``avx512`` or ``native``) to the libraries' own variables before torch
    is imported (the CLI calls this first, and :func:`tactbench.runner.run` again; worker
    processes inherit the environment). A level this CPU lacks is refused: torch would
    take the variable's word and run instructions the CPU does not have. Writes the level
    into ``TACTBENCH_CPU_KERNELS`` and returns it."""
    global _imported_before_pin
    env = os.environ if environ is None else environ
    level = env.get(KERNELS_ENV, "").strip().lower() or default_kernels()
    check_choice(level, KERNELS_ENV, [*KERNEL_LEVELS, NATIVE])
    _normalise_aten(env)
    env[KERNELS_ENV] = level
    if environ is None and _imported_before_pin is None:
        _imported_before_pin = tuple(m for m in PINNED_LIBRARIES if m in sys.modules)
    if level == NATIVE:
        return level
    *values, flag = KERNEL_LEVELS[level]
    flags = _cpu_flags()
    if flag is not None and flags is not None and flag not in flags:
        raise InputError(f"{KERNELS_ENV}={level}: this CPU ({cpu_model()}) has no {flag}; "
                         f"use a level it has (default, avx2 or native)")
    for name, value in zip(KERNEL_VARIABLES, values):
        if value:
            env.setdefault(name, value)
    return level


#: The values of ``ATEN_CPU_CAPABILITY`` torch takes (lower case, exactly); any other it
#: ignores with a warning and computes with the widest kernels the CPU has.
ATEN_LEVELS = {"default": None, "avx2": "avx2", "avx512": "avx512f", "zvector": None,
               "vsx": None}


def _normalise_aten(env) -> None:
    """``ATEN_CPU_CAPABILITY`` as torch reads it, before any key is made from it: a value
    torch would take but for its case or spaces (``AVX2``) is written as torch takes it
    (``avx2``); one it would ignore (another word, a level this CPU lacks, which torch
    also passes over for the widest it has) is refused in one line, since a key would
    name kernels torch does not use."""
    given = env.get("ATEN_CPU_CAPABILITY")
    if given is None:
        return
    value = given.strip().lower()
    if value not in ATEN_LEVELS:
        raise InputError(f"ATEN_CPU_CAPABILITY={given!r} is not a level torch takes "
                         f"({', '.join(ATEN_LEVELS)}): torch would ignore it and use "
                         f"{_widest_isa()}; unset it, or set {KERNELS_ENV} (avx2, default, "
                         f"avx512, native)")
    flags = _cpu_flags()
    flag = ATEN_LEVELS[value]
    if flag is not None and flags is not None and flag not in flags:
        raise InputError(f"ATEN_CPU_CAPABILITY={given}: this CPU ({cpu_model()}) has no "
                         f"{flag}, so torch would ignore it and use {_widest_isa()}; unset "
                         f"it, or use a level this CPU has")
    env["ATEN_CPU_CAPABILITY"] = value


def aten_level(identity_kernels: str) -> str | None:
    """The ATen level (``avx2``) that a cell identity's ``cpu_kernels`` says torch
    computes with; None when it names none (an unpinned process)."""
    if identity_kernels in KERNEL_LEVELS:
        return KERNEL_LEVELS[identity_kernels][0]
    if identity_kernels.startswith("custom "):
        for part in identity_kernels[len("custom "):].split(", "):
            name, _, value = part.partition("=")
            if name == "ATEN_CPU_CAPABILITY":
                return value
        return None
    if identity_kernels.startswith("native ") and identity_kernels.endswith(")"):
        widest = identity_kernels.rsplit("(", 1)[-1][:-1]
        return widest if widest in ATEN_LEVELS else None  # another architecture: no level
    return None


def kernels_identity(environ: "dict[str, str] | None" = None) -> str:
    """The CPU kernels as a cell's identity holds them: the pinned level (``avx2``) when
    the libraries' variables are the level's; ``native <cpu> (<flags>)`` for unpinned
    kernels, whose results are this kind of processor's alone; the variables themselves
    when someone set them apart from the level. Call after :func:`pin_cpu_kernels`."""
    env = os.environ if environ is None else environ
    level = env.get(KERNELS_ENV, "").strip().lower() or default_kernels()
    given = {name: env.get(name, "") for name in KERNEL_VARIABLES}
    if environ is None and _imported_before_pin:
        return f"unpinned {cpu_model()} ({_widest_isa()}; " \
               f"{', '.join(_imported_before_pin)} imported before tactbench)"
    if level != NATIVE and tuple(given.values()) == KERNEL_LEVELS.get(level, ())[:-1]:
        return level
    if level == NATIVE and not any(given.values()):
        return f"native {cpu_model()} ({_widest_isa()})"
    return "custom " + ", ".join(f"{k}={v}" for k, v in given.items() if v)


def _widest_isa() -> str:
    """The widest vector instruction set torch would pick here, from the CPU's flags."""
    flags = _cpu_flags() or set()
    for level in ("avx512", "avx2"):
        if KERNEL_LEVELS[level][-1] in flags:
            return level
    return platform.machine() or "unknown"


def torch_kernels() -> str | None:
    """``torch.backends.cpu.get_cpu_capability()`` when torch is imported, else None."""
    torch = sys.modules.get("torch")
    if torch is None:
        return None
    try:
        return str(torch.backends.cpu.get_cpu_capability())
    except Exception:  # noqa: BLE001 — an older torch without it
        return None
