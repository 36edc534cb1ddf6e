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
    """The browser test files spread evenly over the first three quarters of the run, each file kept whole (its
    fixtures are set up once) and between two other files.

    xdist (3.8) hands each worker a run of consecutive tests first, then more as it finishes: with the browser
    tests together, one worker had nearly all of them (526 s of its 600 s) while the other ended 136 s early. Spread
    out, every run of tests holds its share of them, whichever scheduler hands them out, and the end of the run is
    short tests (the same order in every process, as xdist requires)."""
    files: dict[str, list] = {}
    for item in items:
        files.setdefault(item.nodeid.split("::")[0], []).append(item)
    browser = [f for name, f in files.items() if name.startswith("tests/e2e/")]
    others = [f for name, f in files.items() if not name.startswith("tests/e2e/")]
    if not browser or not others:
        return
    span = 0.75 * sum(len(f) for f in others)  # the browser files placed among the first three quarters
    order, done, b = [], 0, 0
    for f in others:
        while b < len(browser) and done >= span * b / len(browser):
            order.append(browser[b])
            b += 1
        order.append(f)
        done += len(f)
    order.extend(browser[b:])
    items[:] = [item for f in order for item in f]
