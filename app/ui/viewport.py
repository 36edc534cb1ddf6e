"""A page's view: the video (every camera's image in one pixel world, z = 0) or the 3D world, and how the
browser's camera looks at it — fitted, zoomed onto a dragged rectangle, zoomed by the wheel about the
cursor — and which camera pixel a click's ray meets."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import viser

from app.workflows import WorkflowError

if TYPE_CHECKING:  # pragma: no cover
    from .client import ClientPanel

__all__ = ["CameraNow", "Viewport", "WHEEL_ZOOM_PER_DELTA", "camera_now"]

WHEEL_ZOOM_PER_DELTA = 0.0015  # a wheel notch (deltaY 100) zooms by 14 %


class CameraNow(NamedTuple):
    """A client's camera as one report of its page: viewer position, look-at point, orientation, vertical field of
    view (rad), and the canvas's size in its own pixels."""

    position: np.ndarray
    look_at: np.ndarray
    wxyz: np.ndarray
    fov: float
    image_width: int
    image_height: int

    @property
    def aspect(self) -> float:
        return self.image_width / self.image_height


def camera_now(cam) -> CameraNow | None:
    """``cam`` (a viser client's camera) read whole, or None before the page's first report. viser replaces the state
    behind it at each of the page's reports, in its event loop, while the panel's callbacks read it property by
    property in other threads: a position of one report with the look-at or orientation of the next is a camera the
    page never had. Read until two readings agree."""
    last = None
    for _ in range(10):
        try:
            now = CameraNow(
                np.array(cam.position, float),
                np.array(cam.look_at, float),
                np.array(cam.wxyz, float),
                float(cam.fov),
                int(cam.image_width),
                int(cam.image_height),
            )
        except (AssertionError, TypeError):
            return None
        if now.image_height <= 0 or now.image_width <= 0:
            return None
        if last is not None and all(np.array_equal(a, b) for a, b in zip(now, last)):
            return now
        last = now
    return last


class Viewport:
    """``view``: "video" or "3d"; ``need_fit``: the browser's camera is to be fitted at the next redraw;
    ``marks_scale``: the marks are drawn this much smaller than at the fitted view (constant on screen)."""

    def __init__(self, panel: ClientPanel):
        self.panel = panel
        self.client = panel.client
        self.view = "video"
        self.need_fit = True
        self.fitted_aspect: float | None = None
        self.zoom_rect: tuple | None = None
        self.marks_scale = 1.0
        self._moving = threading.Lock()  # held while the camera is read and moved (the wheel's thread, the redraw's)
        self.all_cameras = False  # the fit shows every camera's image side by side (Fit view pressed again)
        self._fitted_at: np.ndarray | None = None  # where the last fit put the browser's camera
        # The page has not yet reported its camera where the last fit put it: the camera the server holds is the fit's,
        # the page still shows the view before it (a click now lands through the old view).
        self.fit_pending = False
        self._moved = False  # the operator moved the view since the last fit (the page's own controls, the wheel)
        self._page_position: np.ndarray | None = None  # the camera position the page last reported
        try:  # the page's report at its connection (viser connects a page at its first report): a page that connects
            # again already at the fit never reports it again, and its fit stayed pending
            self._page_position = np.asarray(self.client.camera.position, float).copy()
        except AssertionError:  # no report yet
            pass
        # The view's size on the screen (CSS pixels), as the page tells it (static/wheel.js); None until it has.
        self.screen_size: tuple[int, int] | None = None
        self._rect_cb = self.client.scene.on_rect_select()(panel.guard(self.on_rect))
        self.client.camera.on_update(self.on_camera)

    @property
    def pixel_world(self):
        return self.panel.feed.pixel_world

    def request_fit(self, again: bool = True) -> None:
        """Fit the shown camera's image; ``again`` (Fit view pressed) with the view still where the last fit
        put it and several cameras: every camera's image side by side."""
        unmoved = self._fitted_at is not None and not self._moved  # (not: the page has reported the fit back)
        self.all_cameras = again and unmoved and not self.all_cameras and len(self.panel.app.views) > 1
        self.zoom_rect = None
        self.need_fit = True

    def set_view(self, view: str) -> None:
        self.view, self.need_fit = view, True

    # ------------------------------------------------------------------ from the screen to the image
    @staticmethod
    def screen_ray(cam, screen_xy) -> tuple[np.ndarray, np.ndarray]:
        """The viewer ray (origin, direction) through screen point (x, y) in 0..1 of the canvas."""
        R = viser.transforms.SO3(np.asarray(cam.wxyz)).as_matrix()
        t = np.tan(cam.fov / 2.0)
        sx, sy = screen_xy
        d_cam = np.array([(2 * sx - 1) * t * cam.aspect, (2 * sy - 1) * t, 1.0])
        return np.asarray(cam.position), R @ d_cam

    def pixel_of_ray(self, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """The pixel a click's ray meets: on the shown camera's image, or on another camera's (seen beside
        it when zoomed out), which is then the camera shown; a WorkflowError when it meets no image."""
        hit = self.panel.app.view_at(origin, direction)
        if hit is not None and hit[0] != self.panel.camera_view:
            self.panel.show_camera(hit[0], keep_view=True)
        if hit is None:
            raise WorkflowError("that click missed the image: click on the video")
        uv, pw = hit[1], self.pixel_world
        if not (-0.5 <= uv[0] <= pw.width - 0.5 and -0.5 <= uv[1] <= pw.height - 0.5):
            raise WorkflowError(f"that click is outside the {pw.width}×{pw.height} image: click on the video")
        return uv

    def pixel_at(self, screen_xy) -> np.ndarray | None:
        """The camera pixel under screen point (x, y) in 0..1 of the canvas (None: the page has not
        reported its camera yet); switches to the camera whose image it is on."""
        cam = camera_now(self.client.camera)
        return None if cam is None else self.pixel_of_ray(*self.screen_ray(cam, screen_xy))

    def on_rect(self, event) -> None:
        """A left drag on the video zooms to the dragged rectangle (and never rotates the view)."""
        cam = camera_now(self.client.camera)
        if self.view != "video" or cam is None:
            return
        corners = [
            self.pixel_world.pixel_from_ray(*self.screen_ray(cam, s)) for s in (event.screen_min, event.screen_max)
        ]
        if any(c is None for c in corners):
            return
        (u0, v0), (u1, v1) = corners
        if abs(u1 - u0) < 4 or abs(v1 - v0) < 4:
            return
        self.zoom_rect = (min(u0, u1), min(v0, v1), max(u0, u1), max(v0, v1))
        self.need_fit, self.all_cameras = True, False

    # ------------------------------------------------------------------ zoom
    def on_wheel(self, value: str) -> None:
        """Zoom about the point under the cursor: "x y deltaY n" from static/wheel.js (x, y in 0..1)."""
        try:
            sx, sy, dy = (float(v) for v in value.split()[:3])
        except ValueError:
            return  # not a wheel message (cleared, or typed): ignore
        if not (np.isfinite(sx) and np.isfinite(sy) and np.isfinite(dy)):
            return
        with self._moving:  # one move at a time, each from the camera the last left (a fit, another notch)
            if not self._zoom(sx, sy, dy):
                return
        self._fitted_at = None  # zoomed: Fit view fits the shown image first
        self.fit_pending = False
        self.panel.dirty = True

    def _zoom(self, sx: float, sy: float, dy: float) -> bool:
        cam = camera_now(self.client.camera)
        if cam is None:
            return False
        position, look_at, aspect = cam.position, cam.look_at, cam.aspect
        R = viser.transforms.SO3(cam.wxyz).as_matrix()
        t = np.tan(cam.fov / 2.0)
        ray = R @ np.array([(2 * sx - 1) * t * aspect, (2 * sy - 1) * t, 1.0])
        if self.view == "video":  # the point of the image plane (z = 0) under the cursor
            if abs(ray[2]) < 1e-9:
                return False
            X = position + (-position[2] / ray[2]) * ray
        else:  # the 3D world: the point under the cursor at the distance of the orbit's centre
            X = position + np.linalg.norm(look_at - position) * ray / np.linalg.norm(ray)
        f = float(np.clip(np.exp(dy * WHEEL_ZOOM_PER_DELTA), 0.5, 2.0))
        if self.view == "video":  # between 200× in and a little beyond the whole image (every camera's)
            fit = max(
                abs(float(self.pixel_world.fit_camera(aspect, cam.fov)[0][2])),
                abs(float(self.panel.app.all_images.fit_camera(aspect, cam.fov)[0][2])) / 2.0,
            )
            dist = abs(float(position[2]))
            if not dist > 1e-9:  # a camera in the image's plane (a page can report one): nothing to zoom about
                return False
            f = float(np.clip(f, 0.005 * fit / dist, 2.0 * fit / dist))
        with self.client.atomic():
            place_camera(self.client.camera, X + f * (position - X), X + f * (look_at - X))
        return True

    def on_camera(self, cam) -> None:
        """The page reported its camera (viser calls this for the page's reports only)."""
        self._page_position = np.asarray(cam.position, float).copy()
        if self.fit_pending and self._fitted_at is not None and self._page_at(self._fitted_at):
            self.fit_pending = False
        elif not self.fit_pending and self._fitted_at is not None and not self._page_at(self._fitted_at):
            self._moved = True  # the page shows the fit no more: moved by its own controls
        now = camera_now(cam)
        if now is None:
            return
        aspect = now.aspect
        if self.fitted_aspect is None or abs(aspect - self.fitted_aspect) > 1e-3:
            self.need_fit = True
            self.panel.app.wake()
            return
        scale = self.zoom_scale()
        if scale is not None and abs(np.log(scale / self.marks_scale)) > 0.1:  # zoomed: marks keep their screen size
            self.panel.dirty = True
            self.panel.app.wake()

    def zoom_scale(self) -> float | None:
        """Image pixels per screen pixel now, relative to the fitted view (1 at fit, 0.1 at 10× zoom)."""
        cam = camera_now(self.client.camera)
        if cam is None:
            return None
        dist = abs(float(cam.position[2]))  # the image plane is z = 0 in the pixel world
        fit = abs(float(self.pixel_world.fit_camera(cam.aspect, cam.fov)[0][2]))
        return float(np.clip(dist / fit, 0.02, 4.0)) if fit > 0 else None

    def on_canvas_size(self, value: str) -> None:
        """The page told the view's size on the screen: "width height" in CSS pixels (static/wheel.js)."""
        try:
            w, h = (int(v) for v in value.split()[:2])
        except ValueError:
            return  # cleared, or typed into the hidden field
        if 0 < w <= 100_000 and 0 < h <= 100_000:
            self.screen_size = (w, h)

    def image_px_per_screen_px(self) -> float:
        """Video pixels per screen pixel (CSS pixel: the page's, whatever its pixel ratio) in this client's view now
        (1 when it is not known). viser reports the camera's image in the canvas's own pixels, the screen's times
        the page's pixel ratio; the page's own report of the view's size is used when it has come."""
        cam = camera_now(self.client.camera)
        if cam is None:
            return 1.0
        dist = abs(float(cam.position[2]))
        visible = 2.0 * dist * np.tan(cam.fov / 2.0) / self.pixel_world.k  # video px across the height
        k = visible / float(cam.image_height if self.screen_size is None else self.screen_size[1])
        return k if np.isfinite(k) and k > 0 else 1.0

    def update_marks_scale(self) -> float:
        """The marks' scale for the view now (1 in the 3D world)."""
        scale = self.zoom_scale() if self.view == "video" else None
        self.marks_scale = 1.0 if scale is None else scale
        return self.marks_scale

    # ------------------------------------------------------------------ fit
    def fit(self) -> None:
        """Fit the browser's camera to the shown camera's image (or the dragged rectangle), or to the 3D world."""
        with self._moving:
            self._fit()

    def _fit(self) -> None:
        cam, now = self.client.camera, camera_now(self.client.camera)
        if now is None:
            return  # the browser has not reported its camera yet
        aspect, fov = now.aspect, now.fov
        self.need_fit = False
        self.fitted_aspect = aspect
        pw = self.pixel_world
        if self.view == "video":
            rect, self.zoom_rect = self.zoom_rect, None
            self.all_cameras = self.all_cameras and rect is None
            if rect is not None:
                u0, v0, u1, v1 = rect
                sub = type(pw)(int(round(u1 - u0)) + 1, int(round(v1 - v0)) + 1, pw.k)
                position, look_at, up = sub.fit_camera(aspect, fov, margin=1.0)
                shift = np.array([u0 * pw.k, v0 * pw.k, 0.0])
                position, look_at = position + shift, look_at + shift
            else:
                position, look_at, up = (self.panel.app.all_images if self.all_cameras else pw).fit_camera(aspect, fov)
        else:
            position, look_at, up = self.panel.app.world3d_view()
        self._rect_select(self.view == "video")
        with self.client.atomic():
            cam.near = 0.05
            cam.far = 2000.0
            cam.up_direction = up
            place_camera(cam, position, look_at)
        self._fitted_at = np.asarray(position, float).copy()
        self.fit_pending, self._moved = not self._page_at(self._fitted_at), False
        self.panel.dirty = True

    def _page_at(self, position: np.ndarray) -> bool:
        """Whether the page last reported its camera at ``position`` (its camera controls settle it: within 2 % of
        the distance)."""
        at = self._page_position
        return at is not None and float(np.linalg.norm(at - position)) <= 0.02 * max(abs(float(position[2])), 1e-9)

    def _rect_select(self, on: bool) -> None:
        """A left drag zooms on the video; in the 3D world it orbits (viser's own)."""
        registered = self._rect_cb is not None
        if on and not registered:
            self._rect_cb = self.client.scene.on_rect_select()(self.panel.guard(self.on_rect))
        elif not on and registered:
            self.client.scene.remove_rect_select_callback(self._rect_cb)
            self._rect_cb = None


# place_camera's step aside, relative: beyond viser's sameness test (numpy's allclose, 1e-5); about 0.04 video pixel
# (PixelWorld.k: 0.01 viewer unit a pixel), for one message
_NUDGE = 1e-4


def place_camera(cam, position: np.ndarray, look_at: np.ndarray) -> None:
    """Move a client's camera. The position first: viser moves the look-at point with it, and refuses a
    look-at point equal to the position the camera has at that moment (whatever the page reported).

    Sent even when it equals the camera the page last reported: viser sends nothing then, yet a move sent before
    and still on its way can take the page elsewhere (a page connecting again reported its old camera, equal to
    the refit after its panel docked, and then showed the first fit, zoomed in: its clicks landed off the image)."""
    position, look_at = np.asarray(position, float), np.asarray(look_at, float)
    if np.allclose(position, cam.position):
        cam.position = position + _NUDGE * (1.0 + np.abs(position))  # replaced by the next message at once
    cam.position = position
    if np.allclose(look_at, cam.look_at):
        cam.look_at = look_at + _NUDGE * (1.0 + np.abs(look_at))
    cam.look_at = look_at
