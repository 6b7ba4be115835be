"""The README's promise (docs/reliability.md, "Numbers across machines"): a cell of the
committed main job, trained again here with the default pinned kernels and one thread,
gives the committed predictions to the last one — on an Intel x86-64 machine with AVX2,
the vendor it was measured on. On an AMD EPYC pinned alike the same key gave 140 of 150
predictions the same (2026-11-28): a known gap, reported as an expected failure there
with its count, never as a pass."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tactbench.kernels import DEFAULT_KERNELS, KERNELS_ENV, _cpu_flags

REPO = Path(__file__).resolve().parents[1]
COMMITTED = REPO / "docs" / "results" / "study-quick" / "cells"


def _committed_raw_seed0() -> dict:
    for path in sorted(COMMITTED.glob("*.json")):
        row = json.loads(path.read_text())
        if row["encoder"] == "raw" and row["seed"] == 0:
            return row
    pytest.fail(f"no committed raw seed-0 cell in {COMMITTED}")


@pytest.mark.slow("trains a full quick-profile cell of the main job (minutes) to compare every prediction")
@pytest.mark.timeout(1200)
def test_a_committed_cell_of_the_main_job_trains_again_to_the_same_predictions(tmp_path):
    flags = _cpu_flags()
    if flags is None or "avx2" not in flags:
        pytest.skip("the promise is for x86-64 machines with AVX2; this CPU has none")
    committed = _committed_raw_seed0()
    assert "cpu_kernels" not in committed and committed["threads"] == 1  # the defaults
    env = {**os.environ, "TACTBENCH_CACHE": str(tmp_path / "cache"),
           KERNELS_ENV: DEFAULT_KERNELS}
    done = subprocess.run([sys.executable, "-m", "tactbench", "run", "--encoder", "raw",
                           "--seed", "0", "--out", str(tmp_path / "out"), "--no-plots"],
                          env=env, capture_output=True, text=True, timeout=1100)
    assert done.returncode == 0, done.stderr[-2000:]
    path = tmp_path / "out" / "cells" / f"{committed['key']}.json"
    assert path.is_file(), "the committed cell's key was not planned: its identity changed"
    row = json.loads(path.read_text())
    assert row["machine"]["cpu_kernels"] == "AVX2"
    if _vendor() != "GenuineIntel" and row["test_predictions"] != committed["test_predictions"]:
        ours, theirs = (r["test_predictions"]["predictions"] for r in (row, committed))
        same = sum(a == b for a, b in zip(ours, theirs))
        pytest.xfail(f"known gap (docs/reliability.md): on {_vendor()} {row['machine']['cpu']} "
                     f"{same} of {len(theirs)} predictions are the committed Intel cell's "
                     f"({100 * row['accuracy']:.1f} % against {100 * committed['accuracy']:.1f} %)")
    assert row["test_predictions"] == committed["test_predictions"]
    assert row["accuracy"] == committed["accuracy"]


def _vendor() -> str | None:
    """The CPU's vendor (``GenuineIntel``, ``AuthenticAMD``), from /proc/cpuinfo."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("vendor_id"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        return None
    return None
