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


@pytest.fixture(scope="module")
def forked():
    """``mcit`` commands each in a process of its own, forked from one that has imported the CLI
    (tests/forked_cli.py): ``forked.run(argv)``."""
    from tests.forked_cli import ForkedCli

    runner = ForkedCli()
    yield runner
    said = runner.stderr()
    runner.close()
    assert said == "", f"the forking process wrote on stderr: {said}"


_KERNELS_READY = "MCIT_TEST_KERNELS_READY"  # files the warm-up processes write when numba's cache holds the kernels
# Two processes, one half of the kernels each (core.pose._kernels.WARM_UP_PARTS), the matcher's after the solvers.
_WARM_UP = (
    "import pathlib, sys\n"
    "from core.pose._kernels import warm_up\n"
    "try:\n"
    "    warm_up((sys.argv[2],))\n"
    "    if sys.argv[2] == 'solvers':\n"
    "        from app.vision.matching import warm_up as warm_up_matching\n"
    "        warm_up_matching()\n"
    "    said = 'ready'\n"
    "except Exception as exc:\n"
    "    said = f'failed: {exc!r}'\n"
    "pathlib.Path(sys.argv[1]).write_text(said)\n"
)


def pytest_configure(config):
    """Under xdist, the pose solvers' numba kernels are compiled once, by two processes the controller starts (half
    each), while the workers start and run their first tests. On a fresh clone (numba's cache empty) each worker
    compiled them itself at its first solver test (31 s of CPU each, at the same time), and compiling them in the
    controller first kept the workers from starting for 46 s. A worker's first call of any compiled function waits
    for them, then loads the kernels from numba's cache (about 1 s)."""
    if hasattr(config, "workerinput"):
        if os.environ.get(_KERNELS_READY):
            _wait_for_kernels_at_first_compile([Path(p) for p in os.environ[_KERNELS_READY].split(os.pathsep)])
        return
    if not config.getoption("numprocesses", None):
        return
    # One thread of numpy's BLAS per worker (the workers inherit the environment): with a thread per core in each
    # worker, more threads than cores, and OpenBLAS's threads wait for each other by spinning: a modelling test file
    # took 80-124 s beside another worker and a busy core, 36-79 s with one thread (the same CPU, 27-31 s).
    # OpenCV's thread pool likewise waits actively: test_calibrate_intrinsics.py and test_search.py beside a busy
    # core, 32.8 s of CPU and 31.8 s of wall with its default pool, 28.0 s and 27.1 s with one thread.
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENCV_FOR_THREADS_NUM"):
        os.environ.setdefault(name, "1")
    import subprocess
    import sys
    import tempfile

    from core.pose._kernels import WARM_UP_PARTS

    folder = Path(tempfile.mkdtemp(prefix="mcit-kernels-"))
    config._mcit_warm_up = [
        subprocess.Popen([sys.executable, "-c", _WARM_UP, str(folder / part), part], cwd=PROJECT_ROOT)
        for part in WARM_UP_PARTS
    ]
    os.environ[_KERNELS_READY] = os.pathsep.join(str(folder / part) for part in WARM_UP_PARTS)


def pytest_unconfigure(config):
    for warm_up in getattr(config, "_mcit_warm_up", []):
        if warm_up.poll() is None:
            warm_up.kill()
            warm_up.wait()


def _wait_for_kernels_at_first_compile(ready: list[Path], timeout_s: float = 900.0) -> None:
    """numba compiles a function at its first call with argument types it has no machine code for, after looking in
    its cache: that first look waits until the warm-up processes have filled the cache (or failed, or timed out: the
    worker then compiles what it needs itself)."""
    import time

    from numba.core.dispatcher import Dispatcher

    compile_for_args = Dispatcher._compile_for_args
    waited = []

    def waiting(self, *args, **kwargs):
        if not waited:
            deadline = time.monotonic() + timeout_s
            while not all(p.exists() for p in ready) and time.monotonic() < deadline:
                time.sleep(0.1)
            waited.append(True)
        return compile_for_args(self, *args, **kwargs)

    Dispatcher._compile_for_args = waiting


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """xdist's load scheduling, its first handout the browser tests alone: xdist (3.8) hands each worker a quarter of
    its share first (237 of 1,902 tests), so the browser tests' worker also held the 178 tests after them, run after
    the browser tests while the other worker, done with all the rest, waited (a quiet run: 393 s against 336 s of
    tests). The first handout is now as many tests as there are browser tests, and the tests after them go to the
    worker that asks. Another ``--dist`` than load is left to xdist."""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScheduling

    class BrowserTestsFirst(LoadScheduling):
        def schedule(self) -> None:
            if self.collection is None and self.collection_is_completed and self.node2collection:
                collection = next(iter(self.node2collection.values()))
                browser = sum(1 for nodeid in collection if nodeid.startswith("tests/e2e/"))
                if browser >= 2 and self.maxschedchunk is None:
                    self.maxschedchunk = browser  # also the most a later handout gives: more even at the end
            super().schedule()

    return BrowserTestsFirst(config, log)


def pytest_collection_modifyitems(config, items):
    """The browser tests first, in their order: xdist (3.8) hands each worker a run of consecutive tests first (a
    quarter of its share, more than the browser tests), so one worker runs the browser tests and the other the rest.

    The browser tests mostly wait (for the page, the server, a robot's motion) and the rest mostly compute, so the
    two workers overlap well, and beside a busy core each takes about as long (601-710 s). Spread over both
    workers, the two often waited at once and computed at once: a quiet run was shorter (508 s against 620 s),
    runs beside a busy core were not (710 and 727 s).

    Among the browser tests, those of E2E_WITHOUT_KERNELS first: they call no compiled kernel, so the browser tests'
    worker does not wait for the warm-up at its first test (the first PnP test waited 30 s for it beside a busy
    core). They took 79 s on a quiet machine, when the warm-up takes 25 s."""

    def rank(item) -> int:
        if not item.nodeid.startswith("tests/e2e/"):
            return 2
        return 0 if item.nodeid.split("::")[0].rsplit("/", 1)[-1] in E2E_WITHOUT_KERNELS else 1

    items.sort(key=rank)


# Browser-test modules that call no compiled kernel (checked by logging numba's first call of each kernel in a run of
# them alone: none). A kernel call added to one of them costs only its wait for the warm-up, never a result.
E2E_WITHOUT_KERNELS = (
    "test_access.py",
    "test_markup.py",
    "test_view.py",
    "test_database_locked.py",
    "test_robot.py",
)
