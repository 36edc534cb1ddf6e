"""Real-browser fixtures: an in-process mcit interface on a free port, driven by Debian's chromium.

The interface runs on the bundled scene with a frame rendered from its truth at FRAME_T_S (the
known box has moved: the database is stale) as ``mcit serve`` shows it (the live renderer's;
MCIT_E2E_FRAMES=raycast: the prerecorded video's renderer), a fresh database and no devices
(tests/e2e/harness.py).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from . import harness
from .harness import CHROMIUM, FRAME_T_S, Interface, launch, site_frame


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Whether the running test failed, for the harness: a failed test's page is closed, not kept for the next."""
    report = (yield).get_result()
    if report.when == "setup":
        harness.TEST_FAILED[0] = report.failed
    elif report.when == "call":
        harness.TEST_FAILED[0] = harness.TEST_FAILED[0] or report.failed


@pytest.fixture(scope="session")
def scene():
    from app.scene import default_scene_path, load_scene

    return load_scene(default_scene_path())


@pytest.fixture(scope="session")
def frame(scene):
    """The scene rendered at FRAME_T_S (RGB uint8), the first camera's."""
    return site_frame(scene, None, FRAME_T_S)


@pytest.fixture(scope="session")
def browser():
    if not Path(CHROMIUM).exists() and shutil.which("chromium") is None:
        pytest.skip(f"chromium not found at {CHROMIUM} (apt-get install -y chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = launch(p)
        yield b
        b.close()


@pytest.fixture
def interface(scene, frame, tmp_path):
    ui = Interface(scene, frame, tmp_path / "site.sqlite")
    yield ui
    ui.close()


@pytest.fixture
def device_interface(scene, frame, tmp_path):
    """The interface with emulated range finder and turret that answer at once."""
    ui = Interface(scene, frame, tmp_path / "site.sqlite", devices="fast")
    yield ui
    ui.close()
