"""Shared fixtures: a private cache per test session and the real data beside the repo."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import tactbench  # noqa: F401 — first: it pins the CPU kernels before numpy or torch load

REPO = Path(__file__).resolve().parents[1]
#: Third-party data kept beside the project (never inside it); see its README.
SHARED_DATA = Path(os.environ.get("TACTBENCH_SHARED_DATA", REPO.parent / "shared" / "data"))


def pytest_configure(config):
    """Under pytest-xdist each worker owns its share of the cores (CPU affinity), so the
    tests of one worker never slow another's, and a run that sizes itself to this
    process's cores (``usable_cores``: the default workers, the room check) sees the share
    it really has, as under a scheduler's CPU limit. Tests that need a process pool ask for
    one (``workers=2``); the subprocesses of a test inherit its share."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    if not worker.startswith("gw") or count < 2 or not hasattr(os, "sched_setaffinity"):
        return
    cores = sorted(os.sched_getaffinity(0))
    if len(cores) >= count:
        os.sched_setaffinity(0, cores[int(worker[2:]) % count::count])


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Every slow test says in one line why it cannot be fast: ``@pytest.mark.slow("…")``.
    (The default command leaves slow tests out; ``pytest -m slow`` and CI run them.)"""
    for item in items:
        mark = item.get_closest_marker("slow")
        if mark is None:
            continue
        reason = mark.args[0] if mark.args else mark.kwargs.get("reason")
        if not isinstance(reason, str) or not reason.strip() or "\n" in reason.strip():
            raise pytest.UsageError(
                f"{item.nodeid}: @pytest.mark.slow needs a one-line reason why the test "
                f"cannot be fast, e.g. @pytest.mark.slow(\"trains a full-size cell\")")


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    """Tests never read or write the user's cache."""
    old = os.environ.get("TACTBENCH_CACHE")
    os.environ["TACTBENCH_CACHE"] = str(tmp_path_factory.mktemp("tactbench-cache"))
    yield
    if old is None:
        os.environ.pop("TACTBENCH_CACHE", None)
    else:
        os.environ["TACTBENCH_CACHE"] = old


@pytest.fixture
def shared_data() -> Path:
    """The real third-party data folder; the test is skipped when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA} (set TACTBENCH_SHARED_DATA); "
                    f"a fresh clone does not have it")
    return SHARED_DATA


@pytest.fixture
def plugin_dist(tmp_path, monkeypatch):
    """Make an installed-looking plugin distribution on ``sys.path`` and ``PYTHONPATH``.

    ``plugin_dist(dist_name, module_name, source, entry_name=...)`` writes
    ``module_name.py`` with ``source`` and a ``.dist-info`` whose entry point in group
    ``tactbench`` points at it, exactly what ``pip install`` would leave behind. Returns
    the folder (already on ``sys.path``; subprocesses see it through ``PYTHONPATH``).
    """
    import sys
    import textwrap

    root = tmp_path / "site"
    root.mkdir(exist_ok=True)
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(root), *filter(None, [os.environ.get("PYTHONPATH")])]))

    def make(dist_name: str, module_name: str, source: str, *,
             entry_name: str | None = None, version: str = "1.0") -> Path:
        (root / f"{module_name}.py").write_text(textwrap.dedent(source))
        info = root / f"{dist_name.replace('-', '_')}-{version}.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(
            f"Metadata-Version: 2.1\nName: {dist_name}\nVersion: {version}\n")
        (info / "entry_points.txt").write_text(
            f"[tactbench]\n{entry_name or module_name} = {module_name}\n")
        sys.modules.pop(module_name, None)
        return root

    return make


@pytest.fixture(scope="module")
def one_torch_thread():
    """Tiny models gain nothing from threads, and on a busy 2-core machine two OpenMP
    threads that wait for each other make a tiny fit ~30× slower."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture
def memory_cap():
    """``with memory_cap(mib): ...`` fails the test when the block's peak traced
    allocation (Python objects and numpy array data, via tracemalloc) exceeds ``mib``.

    Used by the fuzz tests: a hostile input must be refused before anything large is
    allocated, not after.
    """
    import contextlib
    import tracemalloc

    @contextlib.contextmanager
    def cap(mib: float):
        started = not tracemalloc.is_tracing()
        if started:
            tracemalloc.start()
        tracemalloc.reset_peak()
        try:
            yield
        finally:
            _, peak = tracemalloc.get_traced_memory()
            if started:
                tracemalloc.stop()
        assert peak <= mib * (1 << 20), f"peak allocation {peak / (1 << 20):.1f} MiB > {mib} MiB"

    return cap
