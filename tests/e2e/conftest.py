"""Real-browser fixtures: an in-process mcit interface on a free port, driven by Debian's chromium.

The interface runs on the bundled scene with a frame rendered from its truth (the known box
moved: the database is stale), a fresh database and no devices. Screen coordinates of a video
pixel are computed from the viewer camera the browser reports (viser's OpenCV convention), so
clicks land on exact pixels whatever the window size.
"""

from __future__ import annotations

import os
import shutil
import socket
import time
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = os.environ.get("MCIT_CHROMIUM", "/usr/bin/chromium")
ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]
FRAME_T_S = 16.0  # the known box has moved (12 s → 15 s) and stays there
VIEWPORT = {"width": 1200, "height": 700}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


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
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


class Interface:
    """A running interface and helpers to reach it from a page."""

    def __init__(self, scene, frame, db_path):
        from app.db import Database, seed_from_scene
        from app.ui.server import InterfaceServer
        from app.video import FrameGrabber, StillSource
        from app.workflows import Site

        self.db = Database.open(db_path)
        seed_from_scene(self.db, scene)
        self.site = Site(scene, self.db, clock=lambda: FRAME_T_S)
        self.server = InterfaceServer(self.site, FrameGrabber(StillSource(frame, fps=20)), port=free_port()).start()
        self.url = f"http://127.0.0.1:{self.server.port}/?fixedDpr=1"
        self.frame_t_s = FRAME_T_S

    def open(self, browser):
        """A new page on the interface, connected, fitted, with the software-WebGL notice closed."""
        before = set(self.server.clients)
        page = browser.new_page(viewport=VIEWPORT)
        page.goto(self.url)
        deadline = time.monotonic() + 20
        panel = None
        while time.monotonic() < deadline:
            new = set(self.server.clients) - before
            if new:
                panel = self.server.clients[new.pop()]
                if panel.fitted_aspect is not None and not panel.need_fit:
                    break
            time.sleep(0.1)
        assert panel is not None and panel.fitted_aspect is not None, "the page did not connect and fit its view"
        notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
        try:
            notice.locator("button").click(timeout=5000)
        except Exception:  # noqa: BLE001 - the notice is not shown on hardware WebGL
            pass
        time.sleep(0.8)  # let the fitted camera and the first overlay arrive
        page.panel = panel
        return page

    def screen_of(self, page, uv):
        """Screen position (x, y) in the canvas of video pixel uv, from the page's viewer camera."""
        import viser

        cam = page.panel.client.camera
        X = self.server.pixel_world.to_world(np.asarray(uv, float))
        R = viser.transforms.SO3(np.asarray(cam.wxyz)).as_matrix()
        p = R.T @ (X - np.asarray(cam.position))
        t = np.tan(cam.fov / 2.0)
        x = (0.5 + p[0] / p[2] / (2 * t * cam.aspect)) * cam.image_width
        y = (0.5 + p[1] / p[2] / (2 * t)) * cam.image_height
        return float(x), float(y)

    def click_pixel(self, page, uv):
        x, y = self.screen_of(page, uv)
        page.locator("canvas").nth(1).click(position={"x": x, "y": y})
        time.sleep(0.25)

    def screenshot(self, page, path=None) -> np.ndarray:
        import cv2

        png = page.screenshot(path=path)
        return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]

    def close(self):
        self.server.stop()
        self.db.close()


@pytest.fixture
def interface(scene, frame, tmp_path):
    ui = Interface(scene, frame, tmp_path / "site.sqlite")
    yield ui
    ui.close()
