"""One browser tab: its panel, its view (video or 3D world), its session and its marks.

Callbacks only change state (the session's workflow, flags) and wake the redraw loop; the loop
(``InterfaceServer.redraw``) calls ``ClientPanel.redraw`` to send this client's marks, texts and
controls. Every callback is guarded: an operator error becomes a yellow notification saying what
to do, anything else a red one, logged; the server never dies from a callback.
"""

from __future__ import annotations

import collections
import concurrent.futures
import functools
import logging
import threading
import time
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
import viser

from app.overlay import nearest_segment, project_wireframe
from app.workflows import Cancelled, Session, WorkflowError
from app.workflows.session import WORKFLOWS

from .controls import CONTROLS, START_BUTTONS, operator_help, report_markdown
from .drawing import draw_marks
from .tracking import TrackFeeder

if TYPE_CHECKING:  # pragma: no cover
    from .server import InterfaceServer

__all__ = ["ClientPanel"]

log = logging.getLogger("mcit.ui")

SELECT_RADIUS_PX = 15.0
NO_SELECTION = "(none)"


class ClientPanel:
    """Per-client state and GUI. ``client`` is viser's handle; ``app`` the server."""

    def __init__(self, app: "InterfaceServer", client: viser.ClientHandle):
        self.app = app
        self.client = client
        self.session = Session(app.site, client=f"browser-{client.client_id}")
        self.lock = threading.RLock()
        self.view = "video"
        self.dirty = True
        self.need_fit = True
        self.fitted_aspect: float | None = None
        self.built_for: Any = None  # the workflow whose controls are on screen
        self.controls: list[Any] = []
        self.candidate_dropdown = None
        self.drawn_revision = -1
        self.worker: threading.Thread | None = None
        self.feeder: TrackFeeder | None = None  # feeds a Track workflow the video
        self.click_t: float | None = None  # arrival (monotonic) of a click not yet answered by a redraw
        self.click_latencies_s: collections.deque = collections.deque(maxlen=1000)  # click → marks sent
        self._build_gui()
        # Clicks are handled one at a time, in the order they arrive (viser runs plain callbacks
        # on a thread pool, where two quick clicks could swap); the event loop is not blocked.
        self._click_worker = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"mcit-click-{client.client_id}")
        guarded_click = self._guard(self._on_click)

        async def on_click(event) -> None:
            self._click_worker.submit(guarded_click, event)

        client.scene.on_click()(on_click)
        self._rect_cb = client.scene.on_rect_select()(self._guard(self._on_rect))
        client.camera.on_update(self._on_camera)

    # ------------------------------------------------------------------ guard and notify
    def _guard(self, fn: Callable) -> Callable:
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            try:
                return fn(*args, **kwargs)
            except WorkflowError as exc:
                self.notify("Cannot do that", str(exc), "yellow")
            except Cancelled:
                self.notify("Cancelled", "The measurement was stopped; nothing was written.", "blue")
            except Exception as exc:  # noqa: BLE001 - the server must survive any callback error
                log.exception("callback %s failed", getattr(fn, "__name__", fn))
                self.notify("Internal error", f"{type(exc).__name__}: {exc}. Nothing was written; the error is logged. "
                            "Cancel the workflow and try again.", "red")
            finally:
                self.dirty = True
                self.app.wake()
        return wrapper

    def notify(self, title: str, body: str, color: str = "yellow") -> None:
        """A notification on this client (errors stay until closed, others close after 6 s)."""
        try:
            self.client.add_notification(title, body, color=color, with_close_button=True,
                                         auto_close_seconds=None if color == "red" else 8.0)
        except Exception:  # noqa: BLE001 - the client may have gone
            log.debug("notification to a departed client dropped", exc_info=True)

    # ------------------------------------------------------------------ GUI
    def _build_gui(self) -> None:
        gui = self.client.gui
        try:  # a docked panel leaves the whole canvas to the video
            gui.main_panel.dock_right()
            gui.main_panel.set_width(340)
        except Exception:  # noqa: BLE001 - layout only
            log.debug("could not dock the panel", exc_info=True)
        self.gui_status = gui.add_markdown("…")
        self.gui_view = gui.add_button_group("View", ("Video", "3D world"))
        self.gui_view.on_click(self._guard(self._on_view))
        self.gui_fit = gui.add_button("Fit view", icon=viser.Icon.ZOOM_RESET, hint="Show the whole image")
        self.gui_fit.on_click(self._guard(lambda _e: self._request_fit()))
        self.gui_object = gui.add_dropdown("Object", (NO_SELECTION,), initial_value=NO_SELECTION)
        self.gui_object.on_update(self._guard(self._on_object))
        self.gui_stale = gui.add_button("Mark stale", hint="The selected object has moved: flag it until its pose is updated")
        self.gui_stale.on_click(self._guard(self._on_stale))
        with gui.add_folder("Workflows"):
            for label, name in START_BUTTONS:
                button = gui.add_button(label)
                button.on_click(self._guard(functools.partial(self._on_start, name)))
            self.gui_shape = gui.add_dropdown("Shape", ("box", "cylinder", "cone"), initial_value="box",
                                              hint="Model object: the shape you see")
            self.gui_vertical = gui.add_checkbox("Vertical", True, hint="Model object: its axis/sides are vertical")
            self.gui_on_table = gui.add_checkbox("Lies on the table", True, hint="Model object: it stands on the table")
            self.gui_snap = gui.add_checkbox("Snap clicks", True, hint="Snap clicked edges and corners to the image "
                                             "(Refuse snap keeps a click as clicked)")
            self.gui_snap.on_update(self._guard(lambda _e: self.session.set_snap(bool(self.gui_snap.value))))
        with gui.add_folder("Current"):
            self.gui_title = gui.add_markdown("**No workflow.** Click an object to select it, or start a workflow.")
            self.gui_progress = gui.add_progress_bar(0.0, visible=False)
            self.gui_controls_folder = gui.add_folder("Actions")
            self.gui_report = gui.add_markdown("")
            self.gui_copy = gui.add_text("Target (m)", "", visible=False, hint="World x y z of the last target: copy it")
        with gui.add_folder("Help", expand_by_default=False):
            gui.add_markdown(operator_help())

    def _rebuild_controls(self) -> None:
        """Buttons of the current workflow (built by the loop when the workflow changes)."""
        for handle in self.controls:
            handle.remove()
        self.controls = []
        self.candidate_dropdown = None
        wf = self.session.workflow
        self.built_for = wf
        if wf is None or wf.finished:
            return
        gui = self.client.gui
        with self.gui_controls_folder:
            if wf.name == "update_pose":
                self.candidate_dropdown = gui.add_dropdown("Candidate", ("—",), initial_value="—")
                self.candidate_dropdown.on_update(self._guard(self._on_candidate))
                self.controls.append(self.candidate_dropdown)
            if wf.name == "history":
                number = gui.add_number("Change #", 0, step=1)
                undo = gui.add_button("Undo change #", color="orange")
                undo.on_click(self._guard(lambda _e: self._act("undo", change_id=int(number.value))))
                self.controls += [number, undo]
            for label, action, kind in CONTROLS.get(wf.name, (("Cancel", "cancel", "button"),)):
                button = gui.add_button(label, color="red" if action == "cancel" else ("green" if action == "accept" else None))
                button.on_click(self._guard(functools.partial(self._on_action, action, kind)))
                self.controls.append(button)

    # ------------------------------------------------------------------ callbacks (state only)
    def _on_start(self, name: str, _event=None) -> None:
        if self.worker is not None and self.worker.is_alive():
            raise WorkflowError("a measurement is running: wait for it or Cancel it first")
        options: dict[str, Any] = {}
        if name == "model_object":
            options = {"shape": self.gui_shape.value, "vertical": bool(self.gui_vertical.value),
                       "on_table": bool(self.gui_on_table.value)}
        if name not in WORKFLOWS:
            raise WorkflowError(f"the {name.replace('_', ' ')} workflow is not available in this build")
        if self.feeder is not None:
            self.feeder.stop()
            self.feeder = None
        wf = self.session.start(name, **options)
        if name == "track":
            self.feeder = TrackFeeder(self, wf, self.app.grabber)

    def _on_action(self, action: str, kind: str, _event=None) -> None:
        wf = self.session.workflow
        if wf is None:
            raise WorkflowError("no workflow is under way")
        if action == "cancel":
            wf.cancel()  # also stops a running measurement
            return
        if kind == "long":
            if self.worker is not None and self.worker.is_alive():
                raise WorkflowError("a measurement is already running: wait, or Cancel")
            self.worker = threading.Thread(target=self._guard(lambda: wf.perform(action)), daemon=True,
                                           name=f"mcit-measure-{self.client.client_id}")
            self.worker.start()
            return
        self._act(action)

    def _act(self, action: str, **kwargs: Any) -> None:
        result = self.session.perform(action, **kwargs)
        wf = self.session.workflow
        if wf is not None and wf.message and action in ("solve", "refine", "accept", "undo", "confirm_match", "restart",
                                                        "refuse_snap"):
            self.notify(wf.title, wf.message, "green" if action == "accept" else "blue")
        return result

    def _on_candidate(self, _event) -> None:
        wf = self.session.workflow
        value = self.candidate_dropdown.value if self.candidate_dropdown is not None else "—"
        if wf is None or wf.name != "update_pose" or value == "—":
            return
        index = int(value.split()[0].lstrip("#")) - 1
        if index != getattr(wf, "chosen", None):
            wf.choose_candidate(index)

    def _on_object(self, _event) -> None:
        value = self.gui_object.value
        self.session.select(None if value == NO_SELECTION else value)

    def _on_stale(self, _event) -> None:
        name = self.session.selected
        if name is None:
            raise WorkflowError("select an object first (click its wireframe, or choose it in the list)")
        self.app.site.set_status(name, "stale", method="operator", client=self.session.client)
        self.notify("Marked stale", f"{name} is drawn orange until its pose is updated.", "blue")

    def _on_view(self, event) -> None:
        self.view = "3d" if event.target.value == "3D world" else "video"
        self.need_fit = True

    def _request_fit(self) -> None:
        self.need_fit = True

    def on_pixel_click(self, uv: np.ndarray) -> None:
        """A click at pixel uv of the video: the workflow's, or else select the nearest object."""
        wf = self.session.workflow
        if wf is not None and not wf.finished and "click" in wf.actions:
            wf.click(uv)
            return
        name = self._object_at(uv)
        if name is None:
            self.session.select(None)
            return
        self.session.select(name)

    def _on_click(self, event) -> None:
        arrival = time.monotonic()
        try:
            self._handle_click(event)
        finally:
            self.click_t = arrival  # answered by the first redraw after this callback (for the benchmark)

    def _handle_click(self, event) -> None:
        if self.view != "video":
            raise WorkflowError("clicks work on the video: switch the view to Video")
        uv = self.app.pixel_world.pixel_from_ray(np.array(event.ray_origin), np.array(event.ray_direction))
        if uv is None:
            raise WorkflowError("that click missed the image plane; click on the video")
        w, h = self.app.pixel_world.width, self.app.pixel_world.height
        if not (-0.5 <= uv[0] <= w - 0.5 and -0.5 <= uv[1] <= h - 0.5):
            raise WorkflowError(f"the click ({uv[0]:.0f}, {uv[1]:.0f}) is outside the {w}×{h} image; click on the video")
        self.on_pixel_click(uv)

    def _on_rect(self, event) -> None:
        """A left drag on the video zooms to the dragged rectangle (and never rotates the view)."""
        if self.view != "video":
            return
        cam = self.client.camera
        corners = [self._screen_to_pixel(cam, s) for s in (event.screen_min, event.screen_max)]
        if any(c is None for c in corners):
            return
        (u0, v0), (u1, v1) = corners
        if abs(u1 - u0) < 4 or abs(v1 - v0) < 4:
            return
        self.zoom_rect = (min(u0, u1), min(v0, v1), max(u0, u1), max(v0, v1))
        self.need_fit = True

    def _screen_to_pixel(self, cam, screen_xy) -> np.ndarray | None:
        R = viser.transforms.SO3(np.asarray(cam.wxyz)).as_matrix()
        t = np.tan(cam.fov / 2.0)
        sx, sy = screen_xy
        d_cam = np.array([(2 * sx - 1) * t * cam.aspect, (2 * sy - 1) * t, 1.0])
        return self.app.pixel_world.pixel_from_ray(np.asarray(cam.position), R @ d_cam)

    def _on_camera(self, cam) -> None:
        try:
            aspect = cam.aspect
        except (AssertionError, ZeroDivisionError):
            return
        if self.fitted_aspect is None or abs(aspect - self.fitted_aspect) > 1e-3:
            self.need_fit = True
            self.app.wake()

    # ------------------------------------------------------------------ helpers
    def _object_at(self, uv: np.ndarray) -> str | None:
        cam = self.app.site.camera
        best, best_d = None, SELECT_RADIUS_PX
        for obj in self.app.site.objects():
            pw = project_wireframe(cam, obj.model, obj.T_world_obj)
            _, d = nearest_segment(pw.seg_uv[pw.visible], uv)
            if d < best_d:
                best, best_d = obj.name, d
        return best

    # ------------------------------------------------------------------ drawing (loop only)
    def fit(self) -> None:
        cam = self.client.camera
        try:
            aspect, fov = cam.aspect, cam.fov
        except (AssertionError, ZeroDivisionError):
            return  # the browser has not reported its camera yet
        self.need_fit = False
        self.fitted_aspect = aspect
        pw = self.app.pixel_world
        if self.view == "video":
            rect = getattr(self, "zoom_rect", None)
            self.zoom_rect = None
            if rect is not None:
                u0, v0, u1, v1 = rect
                sub = type(pw)(int(round(u1 - u0)) + 1, int(round(v1 - v0)) + 1, pw.k)
                position, look_at, up = sub.fit_camera(aspect, fov, margin=1.0)
                shift = np.array([u0 * pw.k, v0 * pw.k, 0.0])
                position, look_at = position + shift, look_at + shift
            else:
                position, look_at, up = pw.fit_camera(aspect, fov)
            self._ensure_rect_select(True)
        else:
            position, look_at, up = self.app.world3d_view()
            self._ensure_rect_select(False)
        with self.client.atomic():
            cam.near = 0.05
            cam.far = 2000.0
            cam.up_direction = up
            cam.look_at = look_at
            cam.position = position
            cam.look_at = look_at

    def _ensure_rect_select(self, on: bool) -> None:
        registered = self._rect_cb is not None
        if on and not registered:
            self._rect_cb = self.client.scene.on_rect_select()(self._guard(self._on_rect))
        elif not on and registered:
            self.client.scene.remove_rect_select_callback(self._rect_cb)
            self._rect_cb = None

    def redraw(self, site_changed: bool) -> bool:
        """Send this client's marks and texts if anything changed; True if something was sent."""
        if self.need_fit:
            self.fit()
        wf = self.session.workflow
        if wf is not self.built_for or (wf is not None and wf.finished and self.controls):
            self._rebuild_controls()
        busy = self.worker is not None and self.worker.is_alive()
        progress = getattr(wf, "progress", None) if wf is not None else None
        self.gui_progress.visible = bool(busy or (progress is not None and 0 < progress < 1))
        if progress is not None:
            self.gui_progress.value = float(np.clip(progress * 100.0, 0, 100))
        if not (self.dirty or site_changed or busy):
            return False
        self.dirty = False
        site = self.app.site
        objects = {o.name: o for o in site.objects()}
        if site_changed or self.drawn_revision != site.revision:
            options = (NO_SELECTION,) + tuple(objects)
            if tuple(self.gui_object.options) != options:
                self.gui_object.options = options
            self.drawn_revision = site.revision
        if self.session.selected is not None and self.session.selected not in objects:
            self.session.selected = None
        selected = self.session.selected or NO_SELECTION
        if self.gui_object.value != selected:
            self.gui_object.value = selected
        marks = wf.marks() if wf is not None and not wf.finished else None
        if marks is None:
            from app.workflows.base import Marks

            marks = Marks()
        pw = self.app.pixel_world
        batch, labels = draw_marks(site.camera, marks, objects, pw.width, pw.height, selected=self.session.selected)
        self.app.send_client_overlay(self.client, batch, labels)
        self._update_texts(wf)
        if self.click_t is not None:
            self.click_latencies_s.append(time.monotonic() - self.click_t)
            self.click_t = None
        return True

    def _update_texts(self, wf) -> None:
        if wf is None:
            title = "**No workflow.** Click an object to select it, or start a workflow."
            report = ""
        else:
            state = " (accepted)" if wf.accepted else (" (cancelled)" if wf.cancelled else "")
            subject = getattr(wf, "object_name", None)
            head = f"**{wf.title}{': ' + subject if subject else ''}**{state}"
            title = f"{head}\n\n{wf.next_step}" + (f"\n\n_{wf.message}_" if wf.message else "")
            report = report_markdown(wf.summary())
        if self.gui_title.content != title:
            self.gui_title.content = title
        if self.gui_report.content != report:
            self.gui_report.content = report
        targets = getattr(wf, "targets", None) if wf is not None else None
        self.gui_copy.visible = bool(targets)
        if targets:
            text = targets[-1].text()
            if self.gui_copy.value != text:
                self.gui_copy.value = text
        if self.candidate_dropdown is not None and wf is not None:
            cands = getattr(wf, "candidate_labels", lambda: [])()
            options = tuple(cands) if cands else ("—",)
            if tuple(self.candidate_dropdown.options) != options:
                self.candidate_dropdown.options = options
            chosen = getattr(wf, "chosen", None)
            if cands and chosen is not None and self.candidate_dropdown.value != options[chosen]:
                self.candidate_dropdown.value = options[chosen]

    def close(self) -> None:
        """The browser left: stop its click worker and tracking, and cancel its workflow."""
        self._click_worker.shutdown(wait=False, cancel_futures=True)
        if self.feeder is not None:
            self.feeder.stop()
        self.session.cancel()

    def set_status(self, text: str) -> None:
        if self.gui_status.content != text:
            self.gui_status.content = text
