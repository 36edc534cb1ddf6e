"""Shared test fixtures: the real data beside the project (../shared/data), skipped cleanly when absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = (PROJECT_ROOT / ".." / "shared" / "data").resolve()


def shared_data_path(*parts: str) -> Path:
    """Path of a file or folder of ../shared/data; skips the calling test when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not found at {path} (expected ../shared/data beside the project root)")
    return path


@pytest.fixture
def shared_data():
    """The function ``shared_data(*parts) -> Path`` (skips the test when the data is absent)."""
    return shared_data_path


def pytest_configure(config):
    """Under xdist, compile the pose solvers' numba kernels once, in the controller, before the workers start: on a
    fresh clone (numba's cache empty) each worker compiled them itself at its first solver test, 31 s of CPU each,
    at the same time. The workers then load them from numba's cache (about 1 s)."""
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", None):
        return
    # One thread of numpy's BLAS per worker (the workers inherit the environment): with a thread per core in each
    # worker, more threads than cores, and OpenBLAS's threads wait for each other by spinning: a modelling test file
    # took 80-124 s beside another worker and a busy core, 36-79 s with one thread (the same CPU, 27-31 s).
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    from app.vision.matching import warm_up as warm_up_matching
    from core.pose import warm_up

    warm_up()
    warm_up_matching()


def pytest_collection_modifyitems(config, items):
    """The browser tests first (kept in their order), the rest after: xdist hands the first quarter of the tests out
    alternately and the rest to whichever worker is free, so the long tests start early and the many short ones fill
    the end, rather than a worker alone at the end with the last browser tests (the same order in every process, as
    xdist requires)."""
    items.sort(key=lambda item: 0 if item.nodeid.startswith("tests/e2e/") else 1)
