"""Shared fixtures: a private cache per test session and the real data beside the repo."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: Third-party data kept beside the project (never inside it); see its README.
SHARED_DATA = Path(os.environ.get("TACTBENCH_SHARED_DATA", REPO.parent / "shared" / "data"))


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
