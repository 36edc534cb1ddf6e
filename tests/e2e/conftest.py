"""Real-browser fixtures: an in-process mcit interface on a free port, driven by Debian's chromium.

The interface runs on the bundled scene with a frame rendered from its truth at FRAME_T_S (the
known box has moved: the database is stale), a fresh database and no devices (tests/e2e/harness.py).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from .harness import CHROMIUM, FRAME_T_S, Interface, launch


@pytest.fixture(scope="session")
def scene():
    from app.scene import default_scene_path, load_scene

    return load_scene(default_scene_path())


@pytest.fixture(scope="session")
def frame(scene):
    """The scene rendered at FRAME_T_S (RGB uint8)."""
    from app.render.renderer import render_frame

    img = render_frame(scene, FRAME_T_S)
    return np.repeat(img[:, :, None], 3, axis=2) if img.ndim == 2 else img


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
