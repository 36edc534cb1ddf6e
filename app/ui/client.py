"""One browser tab: its panel, its view (video or 3D world), its session, its frozen frame and marks.

The panel sends the operator's intents and draws what it is given. Clicks and double clicks on the video
go to the session as clicks in the camera shown (``Session.click`` / ``double_click``), which decides what
they mean; a button or its shortcut presses the workflow's action (``press``), asking once more where the
workflow says so. The workflow under way declares what the panel shows (``Workflow.controls``,
``current_step()``, ``marks_in``, ``summary``): the panel knows no workflow by name. Callbacks only change
state and wake the redraw loop; the loop (``InterfaceServer.redraw``) calls ``ClientPanel.redraw`` to
send this client's marks, texts and controls. Every callback is guarded: an operator error is said in
the panel, anything else in a red notification and the log; the server never dies from a callback.

Parts: ``Viewport`` (app/ui/viewport.py: fit, zoom, screen to pixel), ``FrozenFrames`` (app/ui/frozen.py:
the frame the clicks use), ``WorkflowControls`` (app/ui/workflow_controls.py), ``PanelText``
(app/ui/panel_text.py), ``ClickTimer`` (app/ui/clicks.py: which clicks are one gesture), ``build_panel``
(app/ui/layout.py).
"""

from __future__ import annotations

import collections
import concurrent.futures
import functools
import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from app.db import DatabaseRefused, DatabaseUnavailable
from app.markup import Md, escape
from app.workflows import Cancelled, Session, WorkflowError
from app.workflows.base import Marks

from .clicks import ClickTimer, Gesture
from .drawing import draw_marks, spread_labels
from .frozen import FrozenFrames
from .layout import NO_SELECTION, build_panel
from .panel_text import PanelText, show
from .robot_overlay import RobotGhost3D
from .tracking import TrackFeeder
from .viewport import Viewport
from .workflow_controls import WorkflowControls

if TYPE_CHECKING:  # pragma: no cover
    from .server import InterfaceServer

__all__ = ["ClientPanel"]

log = logging.getLogger("mcit.ui")

# a click this near an object's drawn wireframe selects it, in screen pixels (15 video pixels, 35 on the
# screen at the fitted view, had let the table's edges take clicks meant to clear the selection)
SELECT_RADIUS_SCREEN_PX = 10.0


class ClientPanel:
    """Per-client state and GUI. ``client`` is viser's handle; ``app`` the server."""

    def __init__(self, app: InterfaceServer, client: viser.ClientHandle):
        self.app = app
        self.client = client
        self.session = Session(app.site, client=f"browser-{client.client_id + getattr(app, 'client_number_offset', 0)}")
        self.camera_view = app.site.views[0]  # the camera whose image this page shows (and is clicked in)
        self.dirty = True
        self._wf_seen: Any = None  # what the workflow looked like at the last draw (its own thread may change it)
        self.confirm_pending: tuple | None = None  # (action, args) waiting for its second press
        self.asked_at = 0.0  # when it was asked (monotonic): a click that arrived before it leaves it
        self.warning = ""  # a weak result's reasons, or a question, shown under the buttons
        self.error = ""  # the last refused action, said in the panel until the next action or step
        self.error_step: str | None = None  # the step it was said in
        self.worker: threading.Thread | None = None  # a long action (a measurement) under way
        self._performing = False  # a long action runs now (its worker has not returned from it)
        self.feeder: TrackFeeder | None = None  # feeds a workflow that follows the video
        self.click_t: float | None = None  # arrival (monotonic) of a click not yet answered by a redraw
        self.clicks_received = 0  # the page's clicks and told double clicks on the video that reached the server
        self.keys_received = 0  # the page's shortcuts that reached the server (a key the page had none for sends none)
        self.click_latencies_s: collections.deque = collections.deque(maxlen=1000)  # click → marks sent
        self.seen_change = app.site.change_seq
        self._double_at: str | None = None  # where the double click that pressed Find was, for its refusal
        self._labels_sent: dict = {}
        self.clicks = ClickTimer()
        # Clicks are handled one at a time, in the order they arrive (viser runs plain callbacks on a thread
        # pool, where two quick clicks could swap); the event loop is not blocked.
        self.click_worker = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix=f"mcit-click-{client.client_id}"
        )
        self.viewport = Viewport(self)
        self.frozen_frames = FrozenFrames(self)
        self.ghost3d = RobotGhost3D(client.scene, app.world3d.offset)
        self.texts = PanelText(self)
        self.session.on_start = self._started
        build_panel(self)
        self.workflow_controls = WorkflowControls(self)
        on_click = self.guard(self._on_click)

        async def clicked(event) -> None:  # its arrival time read here: a busy worker does not split a double click
            self.clicks_received += 1
            self.click_worker.submit(on_click, event, time.monotonic())

        client.scene.on_click()(clicked)

    @property
    def feed(self):
        """The shown camera's video in the interface (app.ui.server.ViewFeed)."""
        return self.app.views[self.camera_view]

    @property
    def frozen(self):
        """The frozen frame (FrameRef), or None: the live video."""
        return self.frozen_frames.frame

    @property
    def busy(self) -> bool:
        """A long action (a measurement) runs on this page's worker."""
        return self.worker is not None and self.worker.is_alive()

    @property
    def asking(self) -> str | None:
        """The action whose button asks once more now (Accept of a weak result, Redo, …), or None."""
        return None if self.confirm_pending is None else self.confirm_pending[0]

    def show_camera(self, name: str | None = None, keep_view: bool = False) -> None:
        """Show camera ``name`` (the next one for None): its image fitted (``keep_view``: the view stays where
        the operator put it, the camera clicked in beside it), its clicks taken."""
        names = list(self.app.views)
        if name is None:
            name = names[(names.index(self.camera_view) + 1) % len(names)]
        if name not in self.app.views:
            raise WorkflowError(f"no camera named {name!r} here; the cameras: {', '.join(names)}")
        if name == self.camera_view:
            return
        if not keep_view:
            if self.frozen is not None and self.frozen_frames.by is None:
                self.frozen_frames.unfreeze()  # a frame frozen to look at belongs to the camera it was frozen in
            self.viewport.request_fit(again=False)
        self.camera_view, self.dirty = name, True
        if self.gui_camera is not None and self.gui_camera.value != name:
            self.gui_camera.value = name

    # ------------------------------------------------------------------ guard and notify
    def guard(self, fn: Callable) -> Callable:
        """``fn`` as a callback: an operator error said in the panel, any other logged; the page redrawn."""

        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            try:
                return fn(*args, **kwargs)
            except WorkflowError as exc:
                # Said in the panel, at the top (no toast: toasts stack over the video's corner and close under
                # the cursor), until the next action or until the workflow moves on to another step.
                self.error, self.error_step = _sentence(str(exc)), self._step_name()
            except Cancelled:
                self.error = ""
                self.notify("Stopped", "The measurement was stopped; nothing was kept.", "blue")
            except (DatabaseUnavailable, DatabaseRefused) as exc:
                # The disk or another program refused the write: its transaction was rolled back and the
                # workflow is as before the press, so the same press writes once the cause is gone. Not mcit's
                # fault: one line in the log, without a traceback.
                log.warning("database write refused: %s", exc)
                wf = self.session.workflow
                kept = f" Your work in {wf.title} is kept." if wf is not None and not wf.finished else ""
                self.error, self.error_step = _sentence(str(exc)) + kept, self._step_name()
            except Exception as exc:  # noqa: BLE001 - the server must survive any callback error
                log.exception("callback %s failed", getattr(fn, "__name__", fn))
                self.error = "Something went wrong inside mcit; nothing was written. Cancel the workflow and try again."
                self.notify(
                    "Internal error", f"{self.error} ({type(exc).__name__}: {exc}; the error is logged.)", "red"
                )
            finally:
                self.dirty = True
                self.app.wake()

        return wrapper

    def _step_name(self) -> str | None:
        """The current workflow's step name (None: no workflow, or it cannot say)."""
        wf = self.session.workflow
        try:
            return None if wf is None else wf.current_step().name
        except Exception:  # noqa: BLE001 - only used to tell when a message went stale
            return None

    def notify(self, title: str, body: str, color: str = "yellow", stays: bool = False) -> Any:
        """A notification on this client (errors and ``stays`` ones stay until closed, others close after a
        few seconds)."""
        try:
            return self.client.add_notification(
                title,
                body,
                color=color,
                with_close_button=True,
                auto_close_seconds=None if (color == "red" or stays) else 6.0,
            )
        except Exception:  # noqa: BLE001 - the client may have gone
            log.debug("notification to a departed client dropped", exc_info=True)
            return None

    # ------------------------------------------------------------------ intents: start, press, select
    def start(self, name: str, _event=None) -> None:
        """A Start button: the workflow ``name`` in the camera shown, with the form's options."""
        if _running(self):
            raise WorkflowError("a measurement is running: wait for it or Cancel it first")
        self.error = ""
        form = {"shape": self.gui_shape.value, "vertical": bool(self.gui_vertical.value)}
        form["on_table"] = bool(self.gui_on_table.value)
        self.session.start(name, view=self.camera_view, form=form)

    def _started(self, wf, frame: Any) -> None:
        """The session started ``wf`` (by a button or a double click): fed the video if it follows it, on a
        frozen frame if it takes one."""
        if self.feeder is not None:
            self.feeder.stop()
        start = self.frozen_frames.looked_at_frame()  # Track's first frame (the video moved on since); None: newest
        self.feeder = TrackFeeder(self, wf, self.feed.grabber, self.feed.recent, start) if wf.follows_video else None
        self.frozen_frames.started(wf, frame)

    def reset_scrubber(self) -> None:
        if self.gui_scrub.value != 0.0:  # the newest frame or the live video: the scrubber says 0 s back
            self.gui_scrub.value = 0.0

    def on_scrub(self, event) -> None:
        if event.client_id is not None:  # not the panel setting it back to 0 itself
            self.frozen_frames.scrub(float(self.gui_scrub.value))

    def press_event(self, action: str, _event=None) -> None:
        self.press(action)

    def press(self, action: str) -> None:
        """The operator pressed the control of ``action`` (button or shortcut)."""
        wf = self.session.workflow
        if wf is None or wf.finished:
            raise WorkflowError("no workflow is under way: start one first")
        c = wf.control(action)
        if c is None:
            raise WorkflowError(f"{wf.title} has no such control")
        if action not in wf.current_step().enabled:
            raise WorkflowError(f"{c.label} does not apply now. {wf.prompt_text(markdown=False)}")
        if action == "cancel":
            self._cancel(wf, c)
            return
        if _running(self):
            raise WorkflowError("a measurement is running: wait for it, or Cancel")
        args: tuple = ()
        if c.arg is not None:
            value = self.workflow_controls.choice_values.get(c.arg)
            if value is None:
                chooser = wf.control(c.arg)
                raise WorkflowError(f"choose the {chooser.label.lower() if chooser else 'item'} first, then {c.label}")
            args = (value,)
        # A question asked once more: Redo forgets every click; an undo that discards later changes; Accept of
        # a weak result.
        if (action, args) != self.confirm_pending and self._ask(wf, c, args):
            return
        self.confirm_pending, self.warning, self.error = None, "", ""
        # old messages go; what runs is said until the action says what it did (a refinement on a loaded
        # machine took 20 s, and a new operator saw nothing happen)
        wf.message = f"{c.label}: working…"
        self.app.wake()
        if c.kind == "long":
            act = self.guard(lambda: self._act(wf, c, args))
            self.worker = threading.Thread(target=act, daemon=True, name=f"mcit-measure-{self.client.client_id}")
            self.worker.start()
            return
        self._act(wf, c, args)

    def _ask(self, wf, c, args: tuple) -> bool:
        """Ask once more before ``c`` runs when the workflow has a question (True: asked)."""
        question = wf.question(c.action, *args)  # plain text
        again = Md(" Press **{}** again to confirm.").format(c.label)
        if c.action == "accept":
            weak = wf.weaknesses()
            if weak:
                question = Md("**Weak result — check before accepting:** {}.").format("; ".join(weak))
                again = Md(" Press **Accept** again to write it anyway, or improve it first.")
        if not question:
            return False
        self.confirm_pending, self.warning, self.error = (c.action, args), escape(question) + again, ""
        self.asked_at = time.monotonic()
        return True

    def _cancel(self, wf, c) -> None:
        """A running measurement (or search) is stopped alone, at once: the workflow and what was done before
        it stay; work done is asked about once more."""
        if self._performing or wf.progress is not None:  # (its worker may still be saying what it did: done)
            self.confirm_pending, self.warning, self.error = None, "", ""
            wf.stop_measurement()
            return
        if wf.has_work() and self.confirm_pending != ("cancel", ()):
            self.confirm_pending, self.error, self.asked_at = ("cancel", ()), "", time.monotonic()
            self.warning = Md(
                "Cancel throws away what you did in {} (your clicks and measurements; nothing was "
                "written). Press **Cancel** again to throw it away, or go on."
            ).format(wf.title)
            return
        self.confirm_pending, self.warning, self.error = None, "", ""
        wf.cancel()  # also stops a running measurement

    def _act(self, wf, c, args: tuple) -> Any:
        where, self._double_at = (self._double_at, None) if c.action == "find" else (None, self._double_at)
        working = f"{c.label}: working…"
        self._performing = c.kind == "long"  # a measurement: Cancel stops it alone
        try:
            result = self.session.act(wf, c.action, *args)  # (a Detour starts its workflow)
        except BaseException as exc:
            if wf.message == working:
                wf.message = ""
            if not isinstance(exc, WorkflowError) or where is None:
                raise
            said = str(exc).rstrip(".")
            raise WorkflowError(
                f"{said}. {where[0].upper()}{where[1:]}" if where.startswith("your") else f"{said} ({where})"
            ) from None
        finally:
            self._performing = False
        if not wf.message or wf.message == working:
            # a finished workflow says its own end ("Done." — "Done: done." said it twice)
            wf.message = "" if wf.finished or c.action in ("resume", "pause", "restart") else f"{c.label}: done."
        return result

    def select(self, value: str) -> None:
        self.session.select(None if value == NO_SELECTION else value)

    def mark_stale(self, _event=None) -> None:
        name = self.session.selected
        if name is None:
            raise WorkflowError("select an object first (click it in the video, or choose it in the list)")
        self.app.site.set_status(name, "stale", method="operator", client=self.session.client)
        self.error = ""
        self.notify(
            "Marked stale", f"{name} is drawn orange (yellow while selected) until its pose is updated.", "blue"
        )

    # ------------------------------------------------------------------ intents: clicks
    def on_pixel_click(self, uv: np.ndarray, at: float | None = None, double: bool | None = None) -> None:
        """A click at pixel uv of the camera shown, arrived at ``at`` (monotonic; default now). ``double``:
        the page told it is a double click's second click (True) or not; None: the server tells."""
        at = time.monotonic() if at is None else float(at)
        gesture = self.clicks.arrive(uv, at, double, self.session.selected, self.feed.grabber.latest())
        if gesture is not None:
            self.send_click(gesture, at)

    def send_click(self, g: Gesture, at: float | None = None) -> None:
        """A click gesture (arrived at ``at``, monotonic) to the session, in the camera shown; a double click that
        presses an action (Find) presses it, its refusal saying where the double click was."""
        on = self._object_at(g.uv)
        live_shown = self.frozen_frames.show_live and self.frozen is not None
        if at is None or at >= self.asked_at:  # a question asked after the click arrived stays (Esc after it)
            self.confirm_pending, self.warning = None, ""
        self.error = ""
        if not g.double:
            self.session.click(
                self.camera_view,
                g.uv,
                on=on,
                live_shown=live_shown,
                px_per_screen_px=self.viewport.image_px_per_screen_px(),
            )
            return
        frame = None if self.frozen_frames.looked_at else g.frame
        press = self.session.double_click(
            self.camera_view, g.uv, before=g.before, on=on, frame=frame, live_shown=live_shown
        )
        if press is None:
            return
        subject = self.session.workflow.object_name
        # where it was and when (a new operator double-clicked another object, read the same refusal three
        # times, not knowing whether a click was taken)
        self._double_at = (
            f"your double click is on {on} as the database draws it: to update {on}, Cancel (Esc), "
            "click it to select it, then double-click where it is in the video"
            if on not in (None, subject) and not self.session.is_table(on)
            else f"double click at {time.strftime('%H:%M:%S')}"
        )
        self.press(press)

    def _on_click(self, event, arrival: float | None = None) -> None:
        arrival = time.monotonic() if arrival is None else arrival
        try:
            if self.viewport.view != "video":
                raise WorkflowError("clicks work on the video: switch the view to Video")
            uv = self.viewport.pixel_of_ray(np.array(event.ray_origin), np.array(event.ray_direction))
            self.on_pixel_click(uv, arrival)
        finally:
            self.click_t = arrival  # answered by the first redraw after this callback (for the benchmark)

    def on_double(self, value: str, arrival: float) -> None:
        """A double click on the video, told by static/wheel.js as "x y n" (x, y in 0..1 of the canvas): its
        second click, at that point. Its first click came as an ordinary click."""
        try:
            sx, sy = (float(v) for v in value.split()[:2])
        except ValueError:
            return  # cleared, or typed into the hidden field: not a double click
        if not (np.isfinite(sx) and np.isfinite(sy)) or self.viewport.view != "video":
            return
        uv = self.viewport.pixel_at((sx, sy))
        if uv is not None:
            self.on_pixel_click(uv, arrival, double=True)
            self.click_t = arrival

    def _object_at(self, uv: np.ndarray) -> str | None:
        """The object a click at uv picks (the overlay's own projections: nothing projected here)."""
        return self.app.object_at(uv, self.select_radius_px(), self.camera_view)

    def select_radius_px(self) -> float:
        """How near a wireframe a click picks its object, in video pixels at this client's zoom."""
        return SELECT_RADIUS_SCREEN_PX * self.viewport.image_px_per_screen_px()

    # ------------------------------------------------------------------ drawing (loop only)
    def redraw(self, site_changed: bool) -> bool:
        """Send this client's marks and texts if anything changed; True if something was sent."""
        if self.viewport.need_fit:
            self.viewport.fit()
        self._announce()
        wf = self.session.workflow
        controls = self.workflow_controls
        if wf is not controls.built_for or (wf is not None and wf.finished and controls.handles):
            ended = controls.built_for
            if ended is not None and ended.finished and ended.progress is None and ended.shows_beam:
                self.app.site.set_beam(None)  # the range finder's spot of a closed workflow would go stale
            self.confirm_pending, self.warning = None, ""
            controls.rebuild(wf)
        idle = wf is None or wf.finished
        if self.gui_start.visible != idle:
            self.gui_start.visible = idle
        busy = self.busy  # what this pass draws: a worker that starts or ends meanwhile changes ``seen``, drawn next
        progress = wf.progress if wf is not None else None
        self.gui_progress.visible = bool(busy or (progress is not None and 0 < progress < 1))
        if progress is not None:
            self.gui_progress.value = float(np.clip(progress * 100.0, 0, 100))
        followed = self.frozen_frames.follow(wf)  # (before the tick, which may change the workflow's frame)
        if (wf is not None and not wf.finished and wf.tick()) or followed:
            self.dirty = True
        # a workflow's own thread may change it (a search, a look, a solve ending; a long action's worker ends after
        # its last wake-up): drawn when it shows (a new operator waited 4 minutes on "Looking for … in the video")
        seen = None if wf is None else (id(wf), wf.state, wf.message, wf.finished, wf.progress, busy)
        if seen != self._wf_seen:
            self._wf_seen = seen
            self.dirty = True
        self.frozen_frames.send()
        if not (self.dirty or site_changed or busy):
            return False
        self.dirty = False
        self._draw(wf)
        self.texts.update(wf, busy)
        if self.click_t is not None:
            self.click_latencies_s.append(time.monotonic() - self.click_t)
            self.click_t = None
        return True

    def _draw(self, wf) -> None:
        """The object list and the marks on the shown camera's image."""
        site = self.app.site
        objects = {o.name: o for o in site.objects()}
        options = (NO_SELECTION,) + tuple(objects)
        if tuple(self.gui_object.options) != options:
            self.gui_object.options = options
        if self.session.selected is not None and self.session.selected not in objects:
            self.session.selected = None
        selected = self.session.selected or NO_SELECTION
        if self.gui_object.value != selected:
            self.gui_object.value = selected
        # what the workflow draws on the shown camera's image (nothing there for one working in another camera)
        marks = wf.marks_in(self.camera_view) if wf is not None and not wf.finished else Marks()
        camera, pw = site.camera_of(self.camera_view), self.feed.pixel_world
        X = site.beam_X_world  # the range finder's last spot, for everyone
        if marks.beam_uv is None and X is not None and np.all(np.isfinite(X)) and camera.depth(X) > 0:
            marks.beam_uv = camera.project(np.asarray(X, float))
        scale = self.viewport.update_marks_scale()
        batch, labels = draw_marks(
            camera, marks, objects, pw.width, pw.height, selected=self.session.selected, scale=scale
        )
        labels = spread_labels(labels, self.viewport.image_px_per_screen_px())
        self._labels_sent = self.app.send_client_overlay(self.client, batch, labels, self._labels_sent, pw)
        self.ghost3d.show(marks.robot_ghost)  # the previewed motion's end in the 3D world too

    def _announce(self) -> None:
        """Tell this operator of database changes made by others (who, what, when)."""
        site = self.app.site
        if site.change_seq == self.seen_change:
            return
        changes = site.changes_since(self.seen_change)
        self.seen_change = site.change_seq
        others = [c for c in changes if c.who != self.session.client]
        for c in others[-3:]:
            when = time.strftime("%H:%M:%S", time.localtime(c.when))
            self.notify("Changed by another operator", f"{c.who} {c.what} at {when}.", "blue")
        if len(others) > 3:
            self.notify("Changed by other operators", f"{len(others) - 3} more changes: see History.", "blue")

    def close(self) -> None:
        """The browser left: stop its click worker and tracking, and cancel its workflow."""
        self.click_worker.shutdown(wait=False, cancel_futures=True)
        if self.feeder is not None:
            self.feeder.stop()
        self.session.cancel()

    def set_status(self, text: str) -> None:
        show(self.gui_status, text)

    def set_notice(self, text: str) -> None:
        """The server's notice at the panel's top ("" hides it)."""
        if self.gui_notice.visible != bool(text):
            self.gui_notice.visible = bool(text)
        show(self.gui_notice, text)


def _sentence(text: str) -> str:
    """An operator message as a sentence: capitalised, ending with a full stop."""
    text = text.strip()
    if not text:
        return text
    first = text.split(" ", 1)[0]
    if not any(ch == "_" or ch.isdigit() for ch in first):  # an object's name ("cylinder_1 has …") keeps its case
        text = text[0].upper() + text[1:]
    return text if text.endswith((".", "!", "?")) else text + "."


def _running(panel: ClientPanel, timeout_s: float = 0.25) -> bool:
    """Whether a long action runs on ``panel``'s worker, for a press. One that has returned leaves its worker a moment
    to say what it did: the press then waits (at most ``timeout_s``) for it to end, rather than being refused as "a
    measurement is running" (Measure next pressed as the last measurement's result showed, on a loaded machine)."""
    worker = panel.worker
    if worker is not None and worker.is_alive() and not panel._performing:
        worker.join(timeout_s)
    return panel.busy
