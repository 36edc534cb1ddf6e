"""A running mcit interface for real-browser tests and the documentation's screenshots.

The interface runs in process, on this process's one interface port, with a fresh database seeded from the scene; the
video is a still frame: the site at FRAME_T_S as ``mcit serve`` shows it (``site_frame``: the live
renderer's; MCIT_E2E_FRAMES=raycast, or no OpenGL here, takes the ray-cast renderer's, the recording's).
Screen coordinates of a video pixel come from the viewer camera the browser reports (viser's OpenCV
convention), so clicks land on exact pixels whatever the window.
"""

from __future__ import annotations

import ctypes.util
import glob
import os
import re
import socket
import sys
import time
import weakref

import numpy as np

CHROMIUM = os.environ.get("MCIT_CHROMIUM", "/usr/bin/chromium")
ARGS = [
    "--no-sandbox",
    # one renderer process for the pages of one site (127.0.0.1, whatever the port) in one context: a page opened
    # after the first finds viser's script compiled, and opens on about half the CPU (tests/e2e: 3.5 s against 6.5 s
    # of chromium's CPU a page with software WebGL)
    "--process-per-site",
    # the page composited by the CPU rather than through the software WebGL: a page opened on 2.1 s of the GPU
    # process's CPU against 4.8 s, and a frame on 72 ms against 100 ms (the 3D canvas still draws with SwiftShader)
    "--disable-gpu-compositing",
    *(
        # WebGL on Mesa's llvmpipe through EGL where it is installed (the live site's renderer needs it too): the GPU
        # process's CPU a third less than on SwiftShader (tests/e2e/test_workflows_site.py: 6.9 s against 10.7 s)
        ["--use-angle=gl-egl", "--use-gl=angle", "--ignore-gpu-blocklist"]
        if ctypes.util.find_library("EGL") and glob.glob("/usr/lib/*/dri/swrast_dri.so")
        else ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
    ),
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
FRAME_T_S = 16.0  # the known box has moved (12 s → 15 s) and stays there
VIEWPORT = {"width": 1200, "height": 700}
# The 3D canvas drawn at a quarter of the page's pixels (viser's ``fixedDpr``): the software WebGL's cost is per pixel
# drawn, about 100 ms a frame at 1 against 12-18 ms at 0.25 (1200x700 with --disable-gpu-compositing), and a browser
# test draws some hundred frames. Clicks are in the page's CSS pixels, viser's camera report in the canvas's own
# (a quarter of them): clicks are placed by the view's size the page tells (``canvas_size``). A test that reads the
# overlay's pixels from a screenshot opens its page at ``dpr=1``.
PAGE_DPR = 0.25
DOUBLE_GAP_S = 0.7  # two clicks at one place further apart than this are two clicks (app/ui/clicks.py: 0.6 s)


def site_frame(scene, view: str | None = None, t_s: float = FRAME_T_S) -> np.ndarray:
    """One camera's image (RGB uint8, H × W × 3) of the scene at t_s, as ``mcit serve`` shows it: rendered live
    (app.render.live) by default, by the ray-cast renderer of the prerecorded videos with MCIT_E2E_FRAMES=raycast
    or where OpenGL cannot start (as serve falls back to the recordings)."""
    from app.render.live import LiveRenderer, LiveRenderError, scene_bodies
    from app.render.renderer import Renderer

    v = scene.view(view)
    img = None
    if os.environ.get("MCIT_E2E_FRAMES", "live") != "raycast":
        try:
            with LiveRenderer(scene, v.name) as r:
                img = r.render(scene_bodies(scene, t_s), 0)
        except LiveRenderError:
            img = None
    if img is None:
        img = Renderer(scene, camera=v.camera, lens=v.lens).render(t_s, 0)
    return np.repeat(img[:, :, None], 3, axis=2)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


_INTERFACE_PORT: list[int] = []


def _refused(page, text: str) -> None:
    """A console line or page error: kept when it is the Content-Security-Policy's refusal."""
    if "Content Security Policy" in text:
        page._mcit_refusals.append(text[:300])


def interface_port() -> int:
    """The port this process's interfaces are served on, one after another: the same address each time, so that
    the browser's renderer finds viser's client compiled for it (a page opened on 1.0 s of the renderer's CPU
    against 1.5 s on a new port). viser takes the next port when it is taken."""
    if not _INTERFACE_PORT:
        _INTERFACE_PORT.append(free_port())
    return _INTERFACE_PORT[0]


_PAGE_DPRS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # panel → the DPR its page was opened at


def _size_agrees(page) -> bool:
    """The 3D view's size in the page now (its canvas's CSS pixels) is the size the server holds."""
    try:
        w, h = page.locator("canvas").nth(1).evaluate("c => [c.clientWidth, c.clientHeight]")
    except Exception:  # noqa: BLE001 - the page busy or reloading: take the server's word
        return True
    size = page.panel.viewport.screen_size
    return size is not None and max(abs(size[0] - w), abs(size[1] - h)) <= 1.5


def canvas_size(panel, timeout_s: float = 30.0) -> tuple[float, float]:
    """The 3D view's size on the page (CSS pixels, where the mouse clicks), as the page told it, once it agrees with
    viser's camera report (the canvas's own pixels, the page's DPR times its own): the page tells a new size a moment
    after the view changed size, the camera report comes with the change. AssertionError when they never agree."""
    dpr = _PAGE_DPRS.get(panel)

    def agreed() -> bool:
        size, cam = panel.viewport.screen_size, panel.client.camera
        if size is None:
            return False
        return dpr is None or max(abs(size[0] * dpr - cam.image_width), abs(size[1] * dpr - cam.image_height)) <= 1.5

    wait_until(agreed, timeout_s, "the view's size told by the page to agree with viser's camera report", panel=panel)
    size = panel.viewport.screen_size
    return float(size[0]), float(size[1])


def screen_of(server, panel, uv) -> tuple[float, float]:
    """Canvas position (x, y, CSS pixels) of video pixel uv in a client's view, from the camera it reports."""
    import viser

    from app.ui.viewport import camera_now

    width, height = canvas_size(panel)
    cam = camera_now(panel.client.camera)  # one report of the page's, not parts of two
    X = server.views[panel.camera_view].pixel_world.to_world(np.asarray(uv, float))  # on the camera it shows
    R = viser.transforms.SO3(np.asarray(cam.wxyz)).as_matrix()
    p = R.T @ (X - np.asarray(cam.position))
    t = np.tan(cam.fov / 2.0)
    x = (0.5 + p[0] / p[2] / (2 * t * cam.aspect)) * width
    y = (0.5 + p[1] / p[2] / (2 * t)) * height
    return float(x), float(y)


def wait_until(predicate, timeout_s: float = 60.0, what: str = "condition", panel=None) -> None:
    """Poll ``predicate()`` until it is true; AssertionError naming ``what`` after timeout_s (and, given a
    client ``panel``, what its panel said then)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    said = "" if panel is None else f"; the panel: {panel_state(panel)}"
    raise AssertionError(f"timed out waiting for {what}{said}")


def measured(wf, n: int) -> bool:
    """Calibrate turret's workflow ``wf`` holds ``n`` measurements and none is under way, its state complete: read
    under its lock, which a measurement holds from storing the range to its check, message and next suggestion."""
    with wf.lock:
        return len(wf.pan) == n and wf.progress is None


def panel_state(panel) -> str:
    """What a client's panel shows: its workflow and step, error, warning, message, selection."""
    wf = panel.session.workflow
    step = None if wf is None else wf.current_step()
    return (
        f"workflow={getattr(wf, 'name', None)}:{getattr(wf, 'object_name', None)} "
        f"step={getattr(step, 'name', None)} offers={sorted(getattr(step, 'enabled', ()))} "
        f"finished={getattr(wf, 'finished', None)} error={panel.error!r} warning={panel.warning!r} "
        f"message={getattr(wf, 'message', '')!r} selected={panel.session.selected!r} "
        f"camera={panel.camera_view} clicks={panel.clicks_received} last click={_last_click(panel)} "
        f"keys={panel.keys_received} view: {_view_state(panel.viewport)}"
    )


def _view_state(v) -> str:
    """The viewport's fit state and the camera the page last reported against the last fit's."""
    at = None if v._page_position is None else np.round(v._page_position, 3).tolist()
    fit = None if v._fitted_at is None else np.round(v._fitted_at, 3).tolist()
    return (
        f"all_cameras={v.all_cameras} need_fit={v.need_fit} fit_pending={v.fit_pending} moved={v._moved} "
        f"page at {at}, fitted at {fit}"
    )


def _last_click(panel) -> str:
    last = panel.clicks.last
    return "none" if last is None else f"({last[1][0]:.1f}, {last[1][1]:.1f})"


def wait_for_steady_camera(panel, timeout_s: float = 20.0, steady_s: float | None = None) -> None:
    """Wait until the page has been fitted and the viewer camera it reports has not changed for
    ``steady_s`` (a click placed through a camera the page has already left misses: on a loaded
    machine the fitted camera can arrive well after the page connects). By default three of the page's frames
    (FRAME_GAP_MS): a camera on the move reports at each frame."""
    steady_s = 3 * FRAME_GAP_MS / 1000 if steady_s is None else steady_s

    def state():
        cam = panel.client.camera
        return (
            # fitted, and the page shows the fit: the camera the server holds is the fit's as soon as it is sent
            panel.viewport.fitted_aspect is not None and not panel.viewport.fit_pending,
            tuple(np.round(cam.position, 6)),
            tuple(np.round(cam.wxyz, 6)),
            round(float(cam.fov), 6),
            int(cam.image_width),
            int(cam.image_height),
        )

    deadline = time.monotonic() + timeout_s
    last, since = None, time.monotonic()
    while time.monotonic() < deadline:
        now = state()
        if now != last:
            last, since = now, time.monotonic()
        elif now[0] and time.monotonic() - since >= steady_s:
            return
        time.sleep(0.05)
    raise AssertionError("timed out waiting for the page's fitted camera to settle")


# The 3D view's size on the page, as static/wheel.js tells it (the largest canvas, CSS pixels, rounded).
VIEW_SIZE_JS = """() => {
  let best = null;
  for (const c of document.querySelectorAll("canvas")) {
    const r = c.getBoundingClientRect();
    if (r.width >= 200 && r.height >= 200 && (!best || r.width * r.height > best.width * best.height)) best = r;
  }
  return best ? [Math.round(best.width), Math.round(best.height)] : null;
}"""


def wait_for_fit_shown(page, panel, timeout_s: float = 60.0) -> None:
    """Wait until the page shows the server's fit of its view: the view's size on the page now is the one it told,
    viser's camera report has that size (times the page's DPR) and the fit's aspect, and the camera the page reports
    stands where the last fit put it (the page sets it at once: equal to rounding). Clicks are then placed through
    the camera the page shows. Keyed on the page, not on a time without change (wait_for_steady_camera: 0.75 s a
    page); the size is read from the page, since the view narrows when the panel docks, after the page connects."""
    vp, dpr = panel.viewport, _PAGE_DPRS.get(panel)

    def shown(size) -> bool:
        cam, fit, at = panel.client.camera, vp._fitted_at, vp._page_position
        if size is None or vp.need_fit or vp.fit_pending or fit is None or at is None or vp.screen_size != size:
            return False
        if dpr is not None and max(abs(size[0] * dpr - cam.image_width), abs(size[1] * dpr - cam.image_height)) > 1.5:
            return False
        if vp.fitted_aspect is None or abs(cam.aspect - vp.fitted_aspect) > 1e-3:  # the viewport's own rule for a refit
            return False
        return float(np.linalg.norm(at - fit)) <= 1e-6 * max(abs(float(fit[2])), 1e-9)

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        size = page.evaluate(VIEW_SIZE_JS)
        if shown(None if size is None else tuple(size)):
            return
        time.sleep(0.05)
    # never shown (a fit the page never got, app.ui.viewport.place_camera): said, not walked around by waiting for the
    # camera to stay put, which let the test click through a view the operator would not have been given
    raise AssertionError(
        f"the page never showed its fitted view: the page's camera at {vp._page_position}, the fit's {vp._fitted_at}, "
        f"fit pending {vp.fit_pending}, need fit {vp.need_fit}"
    )


def wait_for_panel(server, before: set, timeout_s: float = 60.0):
    """The panel of the client that connected after ``before`` (a set of client ids), once fitted."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        new = set(server.clients) - before
        if new:
            panel = server.clients[new.pop()]
            if panel.viewport.fitted_aspect is not None and not panel.viewport.need_fit:
                return panel
        time.sleep(0.05)
    raise AssertionError("the page did not connect and fit its view")


# (a parked page's panel, left on it until its next connection replaces it, is marked old: not ready)
READY_JS = (
    "() => Array.from(document.querySelectorAll('p')).some((p) => p.textContent === 'mcit-dblclick' && "
    "!p.dataset.mcitOld)"
)


def wait_for_page_ready(page, timeout_s: float = 60.0) -> None:
    """Wait until the page shows its panel whole: the panel's last elements are its hidden fields
    (app/ui/layout.py), added after the shortcuts, and the page takes the server's messages in order; a key
    pressed before then reached no shortcut."""
    page.wait_for_function(READY_JS, timeout=timeout_s * 1000, polling=100)


# A canvas point, in the canvas's own coordinates: whether it lies in the window and nothing (a notification)
# is over the canvas there.
_CLEAR_JS = """(c, [x, y]) => {
  const r = c.getBoundingClientRect(), px = r.left + x, py = r.top + y;
  if (px < 0 || py < 0 || px >= window.innerWidth || py >= window.innerHeight) return false;
  return document.elementFromPoint(px, py) === c;
}"""


_PROBE_JS = """(c, [x, y]) => {
  const r = c.getBoundingClientRect(), e = document.elementFromPoint(r.left + x, r.top + y), t0 = performance.now();
  return new Promise((done) => setTimeout(() => done({
    at: e ? e.tagName + (e === c ? " (the canvas)" : "") : null, canvas: [r.left, r.top, r.width, r.height],
    visibility: document.visibilityState, focus: document.hasFocus(), timer_ms: Math.round(performance.now() - t0),
  }), 100));
}"""


def _click_probe(ui, page, uv) -> str:
    """What the page shows at a click that did not reach the server (for the failure's message): the element at the
    point, the canvas's box, the page's visibility and focus, how late a 100 ms timer fired, the camera's fit."""
    try:
        x, y = ui.screen_of(page, uv)
        said = page.locator("canvas").nth(1).evaluate(_PROBE_JS, [x, y], timeout=10_000)
        vp = page.panel.viewport
        return f"{said}, click at {(round(x, 1), round(y, 1))}, fit pending {vp.fit_pending}, need fit {vp.need_fit}"
    except Exception as exc:  # noqa: BLE001 - a page that does not answer is the answer
        return f"no answer ({type(exc).__name__}: {str(exc)[:120]})"


def close_webgl_notice(page) -> bool:
    """Close the "software WebGL" notification where it is shown (it covers the canvas's top-left corner, and
    stays until closed; absent on hardware WebGL). True when there was one."""
    notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
    if not notice.count():
        return False
    try:
        notice.locator("button").first.click(timeout=5000)
    except Exception:  # noqa: BLE001 - closed meanwhile
        pass
    return True


def workflow_shown(page, name: str):
    """The workflow ``name`` once it is under way on the page's panel with its controls built; the workflow."""
    wait_until(
        lambda: (
            page.panel.session.workflow is not None
            and page.panel.session.workflow.name == name
            and page.panel.workflow_controls.built_for is page.panel.session.workflow
        ),
        what=f"the {name} workflow's controls",
        panel=page.panel,
    )
    wf = page.panel.session.workflow
    buttons_shown(page, wf)  # and the page shows them, its shortcuts taken (Esc pressed before went nowhere)
    return wf


def select_by_click(page, name: str, click) -> int:
    """Select object ``name`` by ``click()`` (a canvas click on its wireframe) and wait for the
    selection. On a loaded machine a page's first canvas click can arrive before the page listens
    for clicks (nothing happens, as an operator would see): then the click is made once more, as an
    operator would. Returns the number of clicks made (1 or 2)."""
    for attempt, timeout_s in ((1, 6.0), (2, 14.0)):
        click()
        try:
            wait_until(lambda: page.panel.session.selected == name, timeout_s, "the selection", panel=page.panel)
            return attempt
        except AssertionError:
            if attempt == 2:
                raise
    return 2


def buttons_shown(page, wf, timeout_s: float = 60.0) -> None:
    """Wait until the page shows a button that ``wf`` shows now (read again each time: its step can change meanwhile),
    or ``wf`` has finished. The page takes the server's messages at its animation frames (every FRAME_GAP_MS here), a
    workflow's shortcuts before its buttons: a key pressed before the page took them went nowhere (Esc pressed 0.2 s
    after Update pose was pressed again 8 s later)."""
    panel = page.panel

    def labels() -> set[str]:
        handles = panel.workflow_controls.handles
        shown = (handles.get(c.action) for c in wf.controls if c.kind != "choice")
        return {h.label for h in shown if h is not None and h.visible}

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        now = labels()
        if wf.finished or not now or now & set(page.evaluate(SHOWN_BUTTONS_JS)):
            return
        time.sleep(0.05)
    raise AssertionError(f"the page never showed the buttons of {wf.title} ({sorted(labels())})")


def shortcut_shown(page, key: str) -> None:
    """Before ``key`` is pressed: when it is a control's of the workflow under way, wait until the page shows that
    workflow's buttons (``buttons_shown``)."""
    panel = getattr(page, "panel", None)
    wf = None if panel is None else panel.session.workflow
    name = {" ": "space"}.get(key, key).lower()
    if wf is not None and any(c.key is not None and c.key.lower() == name for c in wf.controls):
        buttons_shown(page, wf)


# The texts of the page's buttons that are shown.
SHOWN_BUTTONS_JS = (
    "() => Array.from(document.querySelectorAll('button')).filter((b) => b.offsetParent !== null)"
    ".map((b) => b.innerText.trim())"
)


def key_until(page, key: str, predicate, what: str, panel=None) -> int:
    """Press ``key`` and wait for ``predicate()``. On a loaded machine a key can arrive before the page's
    shortcuts take it, and nothing happens, as an operator would see: it is pressed once more, as they
    would. Returns the number of presses (1 to 3). Not for a key whose second press undoes or goes past
    the first (N, Escape): press those once and wait on the page.

    The page sends a key only as a shortcut it has taken (``panel.keys_received`` counts those that reached the
    server): a key that reached neither the server nor ``predicate`` within REACH_S is pressed again at once, rather
    than after the whole wait (a turret test lost 6 s a run to it). A key that reached the server but was refused
    (a measurement's worker not yet ended: "a measurement is running") is pressed again after 6 s, as before."""
    panel = panel if panel is not None else getattr(page, "panel", None)
    shortcut_shown(page, key)
    for attempt in (1, 2, 3):
        before = None if panel is None else panel.keys_received
        page.keyboard.press(key)
        try:
            if panel is not None:
                reached = lambda: predicate() or panel.keys_received > before  # noqa: E731
                wait_until(reached, REACH_S if attempt < 3 else 30.0, f"the key {key} to reach the server")
            wait_until(predicate, 6.0 if attempt < 3 else 30.0, what, panel=panel)
            return attempt
        except AssertionError:
            if attempt == 3:
                raise
    return 3


REACH_S = 2.0  # how long a key pressed has to reach the server before it is pressed again (key_until)


def press_key(page, key: str, timeout_s: float = 8.0) -> int:
    """Press ``key`` until it reaches the server (the page's ``panel.keys_received``). A key is sent only as a
    shortcut the page has taken (a workflow's come with its controls): on a loaded machine a key pressed before
    the page took them sends nothing, and is pressed again, as an operator who saw nothing happen would. A key
    that reached the server is not pressed again (Escape's second press would throw the work away), so this
    is for keys that have a shortcut. Returns the number of presses (1 to 3)."""
    panel = page.panel
    shortcut_shown(page, key)
    for attempt in (1, 2, 3):
        before = panel.keys_received
        page.keyboard.press(key)
        try:
            wait_until(lambda: panel.keys_received > before, timeout_s, f"the key {key} to reach the server", panel)
            return attempt
        except AssertionError:
            if attempt == 3:
                raise
    return 3


def close_notifications(page, timeout_s: float = 20.0, required: bool = True) -> None:
    """Close every notification and wait until none is left: they stack over the video's top-left
    corner (below them a click or a drag reaches the notification, not the canvas).

    Each is closed by its close button. A click that cannot land (the toast still sliding in, or
    something over it on a loaded machine) is sent to the button directly; the mouse then leaves the
    toasts, since a toast under the cursor pauses its own auto-close."""
    deadline = time.monotonic() + timeout_s
    roots = page.locator(".mantine-Notification-root")
    last_error = ""
    while roots.count() and time.monotonic() < deadline:
        for button in roots.locator("button").all():
            try:
                button.click(timeout=1000)
            except Exception as exc:  # noqa: BLE001 - it may close (auto-close) before the click
                last_error = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                try:
                    button.dispatch_event("click", timeout=1000)
                except Exception:  # noqa: BLE001 - gone meanwhile
                    pass
        try:
            page.mouse.move(1, page.viewport_size["height"] - 2 if page.viewport_size else 600)
        except Exception:  # noqa: BLE001
            pass
        time.sleep(0.2)
    if roots.count() and required:  # (not required: the next steps click the panel, not the video under them)
        texts = [t.strip()[:80] for t in roots.all_inner_texts()]
        raise AssertionError(
            f"{roots.count()} notification(s) still open after {timeout_s} s: {texts}"
            + (f" (last click: {last_error})" if last_error else "")
        )


# The page's animation frames at most every FRAME_GAP_MS. viser draws on demand, but each request draws on for 250 ms
# (its "settle" window), so a page whose video changes 4 times a second drew 50-60 frames a second: a live robot site's
# idle page took 1.1 cores of the software WebGL at 60 frames/s, 0.34 at 10. Animations in the page are timed by the
# clock, not by frames (viser's camera moves, its damping), so they end when they would, in fewer frames.
# Playwright's own checks (a control steady before a click) run in their own world and keep the real frames.
# tests/e2e/test_interface.py and test_robot.py (9 tests, 3 pages at dpr 1) at a frame every 100 / 250 / 500 ms: the GPU
# process 43.6 / 30.0 / 19.1 s of CPU, the renderer 23.1 / 21.3 / 21.2 s, 71 / 72 / 81 s: at 500 ms the page's waits
# grew, at 250 ms they did not.
FRAME_GAP_MS = 250
KEEPER_URL = "http://127.0.0.1:9/keeper"  # answered by the context itself (port 9: nothing listens there)
PACED_FRAMES_JS = """(() => {
  const gap = FRAME_GAP_MS, raf = window.requestAnimationFrame.bind(window);
  let waiting = new Map(), next = 1, scheduled = false, last = -Infinity;
  function run(t) {
    scheduled = false;
    last = t;
    const due = waiting;
    waiting = new Map();
    for (const cb of due.values()) cb(t);
  }
  window.requestAnimationFrame = (cb) => {
    const id = next++;
    waiting.set(id, cb);
    if (!scheduled) {
      scheduled = true;
      setTimeout(() => raf(run), Math.max(0, last + gap - performance.now()));
    }
    return id;
  };
  window.cancelAnimationFrame = (id) => { waiting.delete(id); };
})();""".replace("FRAME_GAP_MS", str(FRAME_GAP_MS))


def shared_context(browser):
    """The one browser context the interfaces' pages open in (``Interface.open``), made at first use: its pages share
    a renderer process (``--process-per-site``) and its cache. Its cookies are cleared as each interface closes, so
    that no test's page carries another's (they are per host, not per port); a test of cookies or of another site's
    page makes its own context."""
    context = getattr(browser, "_mcit_context", None)
    if context is None:
        context = browser._mcit_context = browser.new_context(viewport=VIEWPORT)
        context.add_init_script(PACED_FRAMES_JS)
        context.add_init_script(BUTTON_CLICKS_JS)
        # A blank page of the interfaces' site (127.0.0.1), kept open: chromium keeps the site's renderer process,
        # and its compiled code, between one test's page and the next (a page opened on 1.5 s of the renderer's
        # CPU against 2.3 s when the renderer is started again).
        context.route(KEEPER_URL, lambda route: route.fulfill(body="<!doctype html><title>keeper</title>"))
        context.new_page().goto(KEEPER_URL)
    return context


# A page kept from one interface to the next (one a browser): when an interface closes, its first page is parked —
# told it has no focus, so that viser's client does not reconnect when the server goes — and the next interface on
# the same address, viewport and DPR takes it: the page connects again, and viser's client resets its GUI and scene
# for the new server, instead of loading viser's page anew (a page taken again on 1.2 s of chromium's CPU against
# 2.5 s for one opened, tests/e2e). Its notifications are closed, its scrolled boxes scrolled back and its panel marked
# old first (READY_JS: until its next connection replaces it, the old panel must not read as the new one, ready).
PARK_JS = """() => {
  document.hasFocus = () => false;
  window.dispatchEvent(new Event("blur"));
  for (const b of document.querySelectorAll(".mantine-Notification-root button")) b.click();
  for (const e of document.querySelectorAll("*")) if (e.scrollTop) e.scrollTop = 0;
  for (const p of document.querySelectorAll("p")) p.dataset.mcitOld = "1";
}"""
TAKE_JS = '() => { delete document.hasFocus; window.dispatchEvent(new Event("focus")); }'
TEST_FAILED = [False]  # the running test's setup or call failed (tests/e2e/conftest.py): its page is not parked


def _take_parked(browser, url: str, viewport: dict, dpr: float):
    """The page parked on ``browser`` for this address, viewport and DPR, told to connect again; None if none."""
    parked, browser._mcit_parked = getattr(browser, "_mcit_parked", None), None  # (page, url, viewport, dpr)
    if parked is None:
        return None
    page = parked[0]
    if page.is_closed() or parked[1:] != (url, viewport, dpr):
        _close_quietly(page)
        return None
    page.evaluate(TAKE_JS)
    return page


def _park(page) -> bool:
    """Keep ``page`` for the next interface (``_take_parked``); False when it cannot be: closed, its browser gone, or
    its test failing (a page left in a failure's state would carry it into the next test)."""
    if TEST_FAILED[0] or sys.exc_info()[0] is not None:  # (an interface closed in a test's ``finally``)
        return False
    try:
        page.evaluate(PARK_JS)
    except Exception:  # noqa: BLE001 - closed meanwhile, or its browser gone
        return False
    browser = page.context.browser
    old = getattr(browser, "_mcit_parked", None)
    if old is not None:
        _close_quietly(old[0])
    browser._mcit_parked = (page, page._mcit_url, page._mcit_viewport, page._mcit_dpr)
    return True


def _close_quietly(page) -> None:
    try:
        page.close()
    except Exception:  # noqa: BLE001 - closed already, or its browser gone
        pass


def launch(playwright):
    """Debian's chromium in headless mode with the flags that work here (DESIGN.md)."""
    return playwright.chromium.launch(executable_path=CHROMIUM, args=ARGS)


# Emulated devices that answer at once (no baud-rate or measurement delays, an instant turret):
# the browser tests drive the real serial protocols without waiting for them.
FAST_DEVICES = dict(rangefinder_baud=0, turret_baud=0, measure_delay_s=0.0, delay_per_m_s=0.0, no_target_delay_s=0.0)


def fast_scene(scene):
    """The scene with a turret that moves (almost) instantly."""
    import dataclasses

    return dataclasses.replace(scene, turret=dataclasses.replace(scene.turret, speed_steps_s=1e6))


def open_fast_devices(scene, frame_t_s: float = FRAME_T_S):
    """Emulated range finder and turret on ``scene`` at scene time ``frame_t_s``, answering at once."""
    from app.devices import open_devices

    return open_devices(scene, clock=lambda: frame_t_s, site_options=FAST_DEVICES)


def prompt_controls(panel) -> list[str]:
    """The labels of the controls the workflow's instruction names now ({action} placeholders)."""
    wf = panel.session.workflow
    if wf is None or wf.finished:
        return []
    step = wf.current_step()
    return [wf.control(a).label for a in step.named()]


def assert_prompt_controls(page, timeout_s: float = 15.0) -> list[str]:
    """Every control the instruction names is a visible, enabled button (or chooser) on the page.

    Returns the labels checked. The prompt's named controls come from the workflow's declared step;
    this checks that the page shows them (the panel hides the controls that do not apply). The step
    is read again on every try: a click sent just before may not have reached the workflow when the
    check starts, and the step it leads to names other controls."""

    def shown(label: str) -> bool:
        button = page.get_by_role("button", name=label).first
        try:
            if button.is_visible() and button.is_enabled():
                return True
        except Exception:  # noqa: BLE001 - not rendered yet
            pass
        return page.get_by_text(label, exact=True).first.is_visible()  # a chooser's label

    deadline = time.monotonic() + timeout_s
    while True:
        labels = prompt_controls(page.panel)
        missing = [label for label in labels if not shown(label)]
        if not missing and prompt_controls(page.panel) == labels:  # the step did not change meanwhile
            return labels
        if time.monotonic() > deadline:
            raise AssertionError(
                f"the instruction names {missing[0] if missing else labels!r} but the page shows "
                f"no such enabled control; the panel: {panel_state(page.panel)}, busy={page.panel.busy}"
            )
        time.sleep(0.1)


def press(page, label: str, timeout_ms: int = 60_000) -> None:
    """Click the visible button named ``label``, with or without its key (e.g. "Solve" for "Solve (R)"; not "Measure
    next" for "Measure", nor "Calibrate camera from robot" for "Calibrate camera")."""

    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    button = page.get_by_role("button", name=re.compile("^" + re.escape(label) + r"( \(.+\))?$")).first
    try:
        button.wait_for(state="visible", timeout=timeout_ms)
    except PlaywrightTimeout:
        panel = getattr(page, "panel", None)
        said = "" if panel is None else f"; the panel: {panel_state(panel)}"
        try:  # what the page shows instead
            shown = [t.strip() for t in page.get_by_role("button").all_inner_texts() if t.strip()]
        except Exception:  # noqa: BLE001 - the page gone
            shown = []
        raise AssertionError(
            f"no visible button {label!r} after {timeout_ms / 1000:.0f} s{said}; the page's buttons: {shown[:40]}"
        ) from None
    click_control(button, timeout_ms)


def click_control(locator, timeout_ms: int = 60_000) -> None:
    """Click a panel control through playwright's checks (visible, enabled, steady over two animation frames), for
    up to ``timeout_ms``: on a heavily loaded machine they took more than playwright's default 30 s. Not forced: a
    click made at once, before the page had hidden the button it was taking down, went to that button.

    A button of an interface's page (viser gives it its element's id) is clicked until its press reaches the server,
    at most three times: on loaded machines a click made as the panel redrew (a selection's text arriving) reached no
    button, and the workflow it was to start never started. A click the page's button took is waited for at the
    server (up to TAKEN_REACH_S: a second press of Accept would be refused, so only a press the page lost is made
    again); one it did not take is made again at once."""
    page = locator.page
    counts = getattr(page, "button_presses", None)  # (Interface.open's pages)
    uuid = locator.get_attribute("id", timeout=timeout_ms) if counts is not None else None
    if not (uuid and _UUID.fullmatch(uuid)):  # not a viser button (a chooser's option, a folder's title)
        locator.click(timeout=timeout_ms)
        return
    for attempt in (1, 2, 3):
        before, taken = counts.get(uuid, 0), page.evaluate("() => window.__mcitButtonClicks.length")
        locator.click(timeout=timeout_ms)
        took = uuid in page.evaluate("(n) => window.__mcitButtonClicks.slice(n)", taken)
        deadline = time.monotonic() + (TAKEN_REACH_S if took else 0.0)
        while counts.get(uuid, 0) <= before and time.monotonic() < deadline:
            time.sleep(0.05)
        if counts.get(uuid, 0) > before:
            return
        if attempt == 3 or not locator.is_visible() or not locator.is_enabled():
            return  # the press's effect is the caller's to wait for (a control the page took down answered)


_UUID = re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")  # a viser element's id
TAKEN_REACH_S = 30.0  # how long a press the page's button took has to reach the server before it is made again
# Clicks the page's buttons took, by their element's id (viser's uuid), in the order they came: read by click_control.
BUTTON_CLICKS_JS = """(() => {
  window.__mcitButtonClicks = [];
  document.addEventListener("click", (e) => {
    const b = e.target && e.target.closest && e.target.closest("button");
    if (b && b.id) window.__mcitButtonClicks.push(b.id);
  }, true);
})();"""


def count_button_presses(server, client_id: int) -> dict[str, int]:
    """A live count of ``client_id``'s button presses as viser's server receives them (before any callback runs)."""
    import viser._messages as messages

    counts: dict[str, int] = {}

    def received(cid, message) -> None:
        if cid == client_id and message.updates.get("value") is True:
            counts[message.uuid] = counts.get(message.uuid, 0) + 1

    server._websock_server.register_handler(messages.GuiUpdateMessage, received)
    return counts


class Interface:
    """A running interface and helpers to reach it from a page.

    devices : None (no range finder and turret), "fast" (emulated, answering at once, closed with
    the interface) or opened devices. busy_timeout_s : how long a write waits for another program
    holding the database (the database's default when None)."""

    def __init__(
        self, scene, frame, db_path, devices=None, frame_t_s: float = FRAME_T_S, busy_timeout_s: float | None = None
    ):
        from app.db import Database, seed_from_scene
        from app.ui.server import InterfaceServer
        from app.video import FrameGrabber, StillSource, VideoSource
        from app.workflows import Site

        self.db = (
            Database.open(db_path) if busy_timeout_s is None else Database.open(db_path, busy_timeout_s=busy_timeout_s)
        )
        seed_from_scene(self.db, scene)
        self._own_devices = None
        if devices == "fast":
            scene = fast_scene(scene)
            devices = self._own_devices = open_fast_devices(scene, frame_t_s)
        self.scene = scene
        self.site = Site(scene, self.db, devices=devices, clock=lambda: frame_t_s)
        # one still per camera ({camera name: image}), or the first camera's alone; a video source instead of an
        # image is played as it is
        frames = frame if isinstance(frame, dict) else {scene.views[0].name: frame}
        grabbers = {
            name: FrameGrabber(image if isinstance(image, VideoSource) else StillSource(image, fps=20))
            for name, image in frames.items()
        }
        self.server = InterfaceServer(self.site, grabbers, port=interface_port()).start()
        self.url = f"http://127.0.0.1:{self.server.port}"
        self.frame_t_s = frame_t_s
        # the pages opened on it, closed with it: a page left open (its test failed before closing it) went on
        # drawing, trying to reconnect, and took the software renderer's CPU from every later test
        self.pages: list = []
        # What the page's Content-Security-Policy refused (app/ui/page.py): every browser test fails on one.
        self.csp_refusals: list[str] = []

    def open(self, browser, viewport: dict | None = None, dpr: float = PAGE_DPR):
        """A new page on the interface (``viewport``, default VIEWPORT; its 3D canvas drawn at ``dpr``), connected,
        fitted, with the software-WebGL notice closed."""
        before = set(self.server.clients)
        viewport = viewport or VIEWPORT
        page = _take_parked(browser, self.url, viewport, dpr)
        if page is None:
            page = shared_context(browser).new_page()
            page.set_viewport_size(viewport)
            page.on("console", lambda m: _refused(page, m.text))
            page.on("pageerror", lambda e: _refused(page, str(e)))
            page.goto(f"{self.url}/?fixedDpr={dpr:g}")
        page._mcit_url, page._mcit_viewport, page._mcit_dpr = self.url, viewport, dpr
        page._mcit_refusals = self.csp_refusals  # what its Content-Security-Policy refuses, told to this interface
        self.pages.append(page)
        panel = wait_for_panel(self.server, before)
        # the database drawn as it is now (its own thread; slow on a loaded machine): clicks that
        # select an object pick what is drawn
        wait_until(lambda: self.server.database_drawn, 20.0, "the database overlay to be drawn")
        wait_for_page_ready(page)
        # the page tells the view's size on the screen within a second of showing its panel: until then the server's
        # radii (a click's pick) are in the canvas's pixels, a quarter of the screen's at PAGE_DPR
        wait_until(lambda: panel.viewport.screen_size is not None, 30.0, "the page to tell its view's size")
        _PAGE_DPRS[panel] = dpr
        wait_for_fit_shown(page, panel)  # clicks are placed through the camera the page reports: let the fit land
        page.panel = panel
        page.button_presses = count_button_presses(self.server.server, panel.client.client_id)
        return page

    def screen_of(self, page, uv):
        """Screen position (x, y) in the canvas of video pixel uv, from the page's viewer camera."""
        return screen_of(self.server, page.panel, uv)

    def on_canvas(self, page, uv) -> tuple[float, float]:
        """Canvas position of video pixel uv, once the page shows the fit the server sent; when it falls off the
        canvas (the page's camera was moving when it was read, on a loaded machine), once the camera has settled."""
        viewport = page.panel.viewport
        if viewport.need_fit or viewport.fit_pending:  # the page does not yet show the view the server holds
            wait_for_steady_camera(page.panel)
        if not _size_agrees(page):  # the view changed size (the panel docked, grew): the server refits it first
            # (a box test's first click landed 75 px right of where it was aimed, the later ones where aimed)
            wait_until(lambda: _size_agrees(page), 30.0, "the server to know the view's new size", panel=page.panel)
            wait_for_steady_camera(page.panel)
        x, y = self.screen_of(page, uv)
        width, height = canvas_size(page.panel)
        if not (0 <= x < width and 0 <= y < height):
            wait_for_steady_camera(page.panel)
            x, y = self.screen_of(page, uv)
        return x, y

    def click_pixel(self, page, uv):
        """A click on video pixel uv, then a wait until the click has reached the server: the page sends its scene
        clicks through viser's 20 ms throttle, which keeps only the newest of the clicks waiting in it; on a loaded
        machine a page took three clicks made 50 ms apart inside one window and dropped the middle one."""
        panel = getattr(page, "panel", None)
        before = None if panel is None else panel.clicks_received
        if self._click(page, uv, double=False) and panel is not None:
            self._reached(page, uv, before + 1, "the click")

    def double_click_pixel(self, page, uv):
        """A double click on video pixel uv (one gesture), then a wait until it reached the server: its first click
        and the page's word that it was a double (static/wheel.js keeps its second press from viser)."""
        panel = getattr(page, "panel", None)
        before = None if panel is None else panel.clicks_received
        if self._click(page, uv, double=True) and panel is not None:
            self._reached(page, uv, before + 2, "the double click")

    def _reached(self, page, uv, count: int, what: str) -> None:
        """Wait until the server has taken ``count`` clicks from the page; else fail saying what the page showed."""
        panel = page.panel
        try:
            wait_until(lambda: panel.clicks_received >= count, 30.0, f"{what} to reach the server", panel=panel)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; the page then: {_click_probe(self, page, uv)}") from None

    def _click(self, page, uv, double: bool) -> bool:
        """Click (or double-click) the canvas at video pixel uv; False where playwright's hit test kept finding the
        page, not the canvas, there (seen on loaded fresh clones only) and the mouse clicked the point all the same,
        as an operator's would (a click that reaches nothing is made again by the callers that wait for its effect)."""
        from playwright.sync_api import TimeoutError as PlaywrightTimeout

        x, y = self.on_canvas(page, uv)
        self._not_a_double(page, uv, (x, y), double)
        canvas = page.locator("canvas").nth(1)
        clear = canvas.evaluate(_CLEAR_JS, [x, y])
        if not clear and close_webgl_notice(page):  # the one notice that stays until closed (it comes late)
            clear = canvas.evaluate(_CLEAR_JS, [x, y])
        if clear:
            # the point is in the window and the canvas is on top there: clicked at once (playwright's checks
            # that it is steady wait for two animation frames, 0.3-1 s a click with software WebGL)
            (canvas.dblclick if double else canvas.click)(position={"x": x, "y": y}, force=True)
            return True
        try:
            (canvas.dblclick if double else canvas.click)(position={"x": x, "y": y}, timeout=60_000)
            return True
        except PlaywrightTimeout:
            box = canvas.bounding_box()
            (page.mouse.dblclick if double else page.mouse.click)(box["x"] + x, box["y"] + y)
            return False

    def _not_a_double(self, page, uv, xy, double: bool) -> None:
        """Two clicks near each other are a double click when quick (static/wheel.js: 500 ms and 5 screen px;
        the server: 0.6 s and 4 image px, app/ui/clicks.py): an operator clicking twice at one place (an edge's
        two ends on a short edge) pauses between them, and so does this."""
        import time

        now = time.monotonic()
        last = getattr(page, "_mcit_last_click", None)
        if last is not None and not double:
            t, uv0, xy0 = last
            near = np.linalg.norm(np.subtract(uv, uv0)) <= 6.0 or np.linalg.norm(np.subtract(xy, xy0)) <= 8.0
            if near and now - t < DOUBLE_GAP_S:
                time.sleep(DOUBLE_GAP_S - (now - t))
        page._mcit_last_click = (time.monotonic(), np.asarray(uv, float), np.asarray(xy, float))

    def screenshot(self, page, path=None) -> np.ndarray:
        import cv2

        png = page.screenshot(path=path)
        return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]

    def close_pages(self, park: bool = True) -> None:
        """Close the pages opened on this interface; the first still open is parked for the next (``_park``) unless
        ``park`` is False (a page that showed planted markup goes on refusing it until it is closed)."""
        kept = next((p for p in self.pages if park and hasattr(p, "_mcit_url") and not p.is_closed()), None)
        if kept is not None and not _park(kept):
            kept = None
        for page in self.pages:
            try:
                if page is not kept:
                    page.close()
                page.context.clear_cookies()
            except Exception:  # noqa: BLE001 - closed already, or its browser gone
                pass
        self.pages.clear()

    def close(self):
        self.close_pages()
        self.server.stop()
        if self._own_devices is not None:
            self._own_devices.close()
        self.db.close()
        if self.csp_refusals:
            raise AssertionError(
                f"the page's Content-Security-Policy refused {len(self.csp_refusals)} thing(s): {self.csp_refusals[:3]}"
            )


class ServedInterface(Interface):
    """``mcit serve``'s own interface (``build_interface``), started, for ``argv`` (serve's flags but the port: a free
    one is taken)."""

    def __init__(self, argv: list[str]):
        import argparse

        from app.ui.serve import add_serve_parser, build_interface
        from app.ui.serve import free_port as serve_port

        parser = argparse.ArgumentParser()
        add_serve_parser(parser.add_subparsers(dest="command"))
        port = interface_port()
        try:  # a port given to serve is that one or none: still held by the last interface, another is taken
            serve_port("127.0.0.1", port, tries=1)
        except ValueError:
            port = free_port()
        args = parser.parse_args(["serve", "--port", str(port), *argv])
        self.server, self.closers = build_interface(args)
        self.server.start()
        self.site = self.server.site
        self.scene = self.site.scene
        self.db = self.site.db
        self._own_devices = None
        self.frame_t_s = FRAME_T_S
        self.url = f"http://127.0.0.1:{self.server.port}"
        self.pages: list = []
        self.csp_refusals: list[str] = []

    def close(self):
        self.close_pages()
        self.server.stop()
        for close in self.closers:
            close()
        if self.csp_refusals:
            raise AssertionError(f"the page's Content-Security-Policy refused: {self.csp_refusals[:3]}")
