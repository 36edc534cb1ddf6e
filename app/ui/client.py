"""One browser tab: its panel, its view (video or 3D world), its session, its frozen frame and marks.

The panel renders the workflow under way from what the workflow declares (``Workflow.controls``
and ``Workflow.current_step()``): its instruction (which names controls by their labels), one
button or chooser per control — hidden while it does not apply — and a keyboard shortcut per
button (viser commands). Callbacks only change state and wake the redraw loop; the loop
(``InterfaceServer.redraw``) calls ``ClientPanel.redraw`` to send this client's marks, texts and
controls. Every callback is guarded: an operator error is said in the panel and in a notification,
anything else in a red notification and the log; the server never dies from a callback.

Clicks, snapping and solving use one frame per workflow: the latest frame is frozen when a workflow
that takes clicks starts (or by Freeze, or by the scrubber over the recent frames) and shown in
place of the live video, sharp (nearest-neighbour upscaled PNG) so that zooming shows pixels;
"Show live" looks at the live video meanwhile.
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
from app.markup import Md, as_markdown, escape
from app.workflows import Cancelled, Session, WorkflowError
from app.workflows.base import KEY_TEXT, MOTION_GAP_S, FrameRef, Marks
from app.workflows.session import WORKFLOWS

from .controls import START_BUTTONS, operator_help, report_markdown
from .drawing import draw_marks, spread_labels
from .tracking import TrackFeeder

if TYPE_CHECKING:  # pragma: no cover
    from .server import InterfaceServer

__all__ = ["ClientPanel"]

log = logging.getLogger("mcit.ui")

# a click this near an object's drawn wireframe selects it, in screen pixels (15 video pixels, 35 on the
# screen at the fitted view, had let the table's edges take clicks meant to clear the selection)
SELECT_RADIUS_SCREEN_PX = 10.0
NO_SELECTION = "(none)"
NO_CHOICE = "—"
Z_FROZEN = -0.0005  # the frozen frame: in front of the live video, behind the overlays
FROZEN_MAX_SIDE = 2048  # the frozen frame is upscaled (nearest neighbour) up to this many pixels a side
# Workflows that do not take a frozen frame: tracking follows the live video; history has no clicks.
LIVE_WORKFLOWS = ("track", "history")
GLOBAL_KEYS = {"f", "l", "h", "n"}  # the panel's own shortcuts (Freeze, Show live, Fit view, Next camera), always live
DOUBLE_CLICK_S = 0.6  # two clicks this close in time and place are a double click
DOUBLE_CLICK_PX = 4.0
LATE_FIRST_CLICK_S = 3.0  # a click by a page-told double click soon after it is its first click, arriving late
LATE_FIRST_CLICK_PX = 12.0  # the page tells a double within 5 screen px: more image px when the view is zoomed out
WHEEL_FIELD = "mcit-wheel"  # the hidden text field static/wheel.js writes the wheel into
DOUBLE_FIELD = "mcit-dblclick"  # the hidden text field static/wheel.js writes a double click into
WHEEL_ZOOM_PER_DELTA = 0.0015  # a wheel notch (deltaY 100) zooms by 14 %


class ClientPanel:
    """Per-client state and GUI. ``client`` is viser's handle; ``app`` the server."""

    def __init__(self, app: InterfaceServer, client: viser.ClientHandle):
        self.app = app
        self.client = client
        self.session = Session(app.site, client=f"browser-{client.client_id + getattr(app, 'client_number_offset', 0)}")
        self.lock = threading.RLock()
        self.view = "video"
        self.camera_view = app.site.views[0]  # the camera whose image this page shows (and is clicked in)
        self.dirty = True
        self.need_fit = True
        self.fitted_aspect: float | None = None
        self.zoom_rect: tuple | None = None
        self.marks_scale = 1.0  # marks are drawn this much smaller than at the fitted view (constant on screen)
        self.built_for: Any = None  # the workflow whose controls are on screen
        self.controls: dict[str, Any] = {}  # action → its button or dropdown
        self.commands: list[Any] = []  # the workflow's keyboard shortcuts (viser commands)
        self._command_of: dict[str, Any] = {}  # action → its shortcut
        self.choice_values: dict[str, Any] = {}  # choice control → the value chosen
        self._choice_options: dict[str, dict[str, Any]] = {}
        self.confirm_pending: tuple | None = None  # (action, args) waiting for its second press
        self.warning = ""  # a weak result's reasons, or a question, shown under the buttons
        self._finished_at: tuple | None = (
            None  # (the finished workflow, when this page saw it finish, the selection then)
        )
        self.error = ""  # the last refused action, said in the panel until the next action or step
        self.error_step: str | None = None  # the step it was said in
        self.frozen: FrameRef | None = None
        self.frozen_by: Any = None  # the workflow the frozen frame is for (None: frozen to look at it)
        self.show_live = False
        self._frozen_sent: Any = None
        self._labels_sent: dict = {}
        self.worker: threading.Thread | None = None
        self.feeder: TrackFeeder | None = None  # feeds a Track workflow the video
        self.click_t: float | None = None  # arrival (monotonic) of a click not yet answered by a redraw
        self.click_latencies_s: collections.deque = collections.deque(maxlen=1000)  # click → marks sent
        self.seen_change = app.site.change_seq
        self._double_at: str | None = None  # where the double click that pressed Find was, for its refusal
        self._last_double: tuple | None = None  # (arrival, uv) of a told double click whose first click is awaited
        self._build_gui()
        self._foreign_keys(None)
        # Clicks are handled one at a time, in the order they arrive (viser runs plain callbacks
        # on a thread pool, where two quick clicks could swap); the event loop is not blocked.
        self._click_worker = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix=f"mcit-click-{client.client_id}"
        )
        guarded_click = self._guard(self._on_click)

        async def on_click(event) -> None:  # its arrival time read here: a busy worker does not split a double click
            self._click_worker.submit(guarded_click, event, time.monotonic())

        client.scene.on_click()(on_click)
        self._rect_cb = client.scene.on_rect_select()(self._guard(self._on_rect))
        client.camera.on_update(self._on_camera)

    @property
    def feed(self):
        """The shown camera's video in the interface (app.ui.server.ViewFeed)."""
        return self.app.views[self.camera_view]

    def show_camera(self, name: str | None = None) -> None:
        """Show camera ``name`` (the next one for None): its image fitted, its clicks taken."""
        names = list(self.app.views)
        if name is None:
            name = names[(names.index(self.camera_view) + 1) % len(names)]
        if name not in self.app.views:
            raise WorkflowError(f"no camera named {name!r} here; the cameras: {', '.join(names)}")
        if name == self.camera_view:
            return
        if self.frozen is not None and self.frozen_by is None:
            self._unfreeze()  # a frame frozen to look at belongs to the camera it was frozen in
        self.camera_view, self.zoom_rect, self.need_fit, self.dirty = name, None, True, True
        if getattr(self, "gui_camera", None) is not None and self.gui_camera.value != name:
            self.gui_camera.value = name

    @property
    def asking(self) -> str | None:
        """The action whose button asks once more now (Accept of a weak result, Redo, …), or None."""
        return None if self.confirm_pending is None else self.confirm_pending[0]

    # ------------------------------------------------------------------ guard and notify
    def _guard(self, fn: Callable) -> Callable:
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            try:
                return fn(*args, **kwargs)
            except WorkflowError as exc:
                # Said in the panel, at the top (no toast: toasts stack over the video's corner and
                # close under the cursor, so that a click meant for one lands on the video), until the
                # next action or until the workflow moves on to another step.
                self.error = _sentence(str(exc))
                self.error_step = self._step_name()
            except Cancelled:
                self.error = ""
                self.notify("Stopped", "The measurement was stopped; nothing was kept.", "blue")
            except (DatabaseUnavailable, DatabaseRefused) as exc:
                # The disk or another program refused the write (a full disk, a lock, a read-only file):
                # its transaction was rolled back and the workflow is as before the press, so the same
                # press writes once the cause is gone. Said like a WorkflowError; not mcit's fault, so
                # one line in the log, without a traceback.
                log.warning("database write refused: %s", exc)
                wf = self.session.workflow
                kept = f" Your work in {wf.title} is kept." if wf is not None and not wf.finished else ""
                self.error = _sentence(str(exc)) + kept
                self.error_step = self._step_name()
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
        """A notification on this client (errors and ``stays`` ones stay until closed, others close
        after a few seconds)."""
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

    # ------------------------------------------------------------------ GUI
    def _build_gui(self) -> None:
        gui = self.client.gui
        try:  # a docked panel leaves the whole canvas to the video
            gui.main_panel.dock_right()
            gui.main_panel.set_width(340)
        except Exception:  # noqa: BLE001 - layout only
            log.debug("could not dock the panel", exc_info=True)
        # The workflow under way comes first: its instruction and actions are always above the fold.
        self.gui_title = gui.add_markdown(
            Md("**No workflow.** Click an object to select it, or start a workflow below.")
        )
        self.gui_progress = gui.add_progress_bar(0.0, visible=False)
        self.gui_actions = gui.add_folder(None)
        # A question asked once more (a weak result, Redo) goes under the buttons: shown above them it
        # pushed the button just pressed down, away from the cursor about to press it again.
        self.gui_warning = gui.add_markdown("", visible=False)
        self.gui_copy = gui.add_text("Target (m)", "", visible=False, hint="World x y z of the last target: copy it")
        # Hidden while a workflow is under way (Cancel it to start another): at 1280×720 its buttons
        # pushed the frame's controls (Freeze, Seconds back) below the fold (a new operator's run).
        self.gui_start = gui.add_folder("Start a workflow")
        with self.gui_start:
            for label, name in START_BUTTONS:
                button = gui.add_button(label)
                button.on_click(self._guard(functools.partial(self._on_start, name)))
            self.gui_shape = gui.add_dropdown(
                "Shape",
                ("box", "cylinder", "cone", "wedge", "pyramid"),
                initial_value="box",
                hint="Model object: the shape you see",
            )
            self.gui_vertical = gui.add_checkbox("Vertical", True, hint="Model object: its axis/sides are vertical")
            self.gui_on_table = gui.add_checkbox("Lies on the table", True, hint="Model object: it stands on the table")
            self.gui_snap = gui.add_checkbox(
                "Snap clicks",
                True,
                hint="Snap clicked edges and corners to the image (Refuse snap keeps a click as clicked)",
            )
            self.gui_snap.on_update(self._guard(lambda _e: self.session.set_snap(bool(self.gui_snap.value))))
        with gui.add_folder("Frame and view"):
            self.gui_frame = gui.add_markdown("")
            self.gui_freeze = gui.add_button(
                "Freeze (F)", hint="Freeze the newest frame: clicks, snapping and solving use it"
            )
            self.gui_freeze.on_click(self._guard(lambda _e: self._freeze_back(0)))
            self.gui_live = gui.add_button(
                "Show live (L)",
                hint="Look at the live video (clicks still go to the frozen frame: switch back to click)",
            )
            self.gui_live.on_click(self._guard(lambda _e: self._toggle_live()))
            self.gui_scrub = gui.add_slider("Seconds back", 0.0, float(self.feed.recent.seconds), 0.5, 0.0)
            self.gui_scrub.on_update(self._guard(self._on_scrub))
            self.gui_camera = None
            if len(self.app.views) > 1:  # which camera's image is shown and clicked in (N: the next one)
                self.gui_camera = gui.add_dropdown(
                    "Camera (N)", tuple(self.app.views), initial_value=self.camera_view, hint="The camera shown"
                )
                self.gui_camera.on_update(self._guard(lambda _e: self.show_camera(str(self.gui_camera.value))))
            self.gui_view = gui.add_button_group("View", ("Video", "3D world"))
            self.gui_view.on_click(self._guard(self._on_view))
            self.gui_fit = gui.add_button(
                "Fit view (H)",
                icon=viser.Icon.ZOOM_RESET,
                hint="Show the whole image (a left drag zooms onto a rectangle)",
            )
            self.gui_fit.on_click(self._guard(lambda _e: self._request_fit()))
        with gui.add_folder("Object"):
            self.gui_object = gui.add_dropdown("Object", (NO_SELECTION,), initial_value=NO_SELECTION)
            self.gui_object.on_update(self._guard(self._on_object))
            self.gui_stale = gui.add_button(
                "Mark stale", hint="The selected object has moved: flag it until its pose is updated"
            )
            self.gui_stale.on_click(self._guard(self._on_stale))
        with gui.add_folder("Result"):
            self.gui_report = gui.add_markdown("")
        self.gui_status = gui.add_markdown("…")
        with gui.add_folder("Help", expand_by_default=False):
            gui.add_markdown(Md(operator_help()))  # static/help.md: the project's own file
        # Wheel zoom about the cursor (static/wheel.js, run by the page: app/ui/page.py): viser zooms to the centre;
        # the page script sends the cursor and the wheel through this hidden field instead.
        self.gui_wheel = gui.add_text(WHEEL_FIELD, "")
        self.gui_wheel.on_update(self._guard(self._on_wheel))
        # Double clicks are told by the page (static/wheel.js), timed by the browser: at the server a
        # double click's two messages arrived 0.3–2.7 s apart on a loaded machine. Two clicks close in time
        # and place at the server are a double click too (a page whose script did not run).
        self.gui_double = gui.add_text(DOUBLE_FIELD, "")
        guarded_double = self._guard(self._on_double)

        async def on_double(_event) -> None:  # after the click before it, in the order they arrive
            self._click_worker.submit(guarded_double, str(self.gui_double.value), time.monotonic())

        self.gui_double.on_update(on_double)
        for label, key, fn in (
            ("Freeze", "F", lambda: self._freeze_back(0)),
            ("Show live / frozen", "L", self._toggle_live),
            ("Fit view", "H", self._request_fit),
            *((("Next camera", "N", self.show_camera),) if len(self.app.views) > 1 else ()),
        ):  # GLOBAL_KEYS
            cmd = gui.add_command(label, hotkey=key)
            cmd.on_trigger(self._guard(lambda _e, fn=fn: fn()))

    def _rebuild_controls(self) -> None:
        """The current workflow's controls, as it declares them (built by the loop when it changes)."""
        for handle in list(self.controls.values()) + self.commands:
            handle.remove()
        self.controls, self.commands, self._command_of = {}, [], {}
        self.choice_values, self._choice_options = {}, {}
        self.confirm_pending, self.warning = None, ""
        wf = self.session.workflow
        self.built_for = wf
        self._foreign_keys(None if wf is None or wf.finished else wf)
        if wf is None or wf.finished:
            return
        gui = self.client.gui
        live_keys = _live_shortcuts(wf.controls, wf.current_step().enabled)  # live from the start, no gap
        with self.gui_actions:
            for c in wf.controls:
                if c.kind == "choice":
                    handle = gui.add_dropdown(
                        c.label, (NO_CHOICE,), initial_value=NO_CHOICE, hint=c.hint or None, visible=False
                    )
                    handle.on_update(self._guard(functools.partial(self._on_choice, c.action)))
                else:
                    handle = gui.add_button(c.button_label, color=c.color, hint=c.hint or None, visible=False)
                    handle.on_click(self._guard(functools.partial(self._press_event, c.action)))
                    if c.key is not None:
                        cmd = gui.add_command(
                            f"{wf.title}: {c.label}",
                            hotkey=c.key,
                            description=c.hint or None,
                            disabled=live_keys.get(c.key) != c.action,
                        )
                        cmd.on_trigger(self._guard(functools.partial(self._press_event, c.action)))
                        self.commands.append(cmd)
                        self._command_of[c.action] = cmd
                self.controls[c.action] = handle

    def _foreign_keys(self, wf) -> None:
        """The keys of other workflows' controls, live here so that pressing one says it does nothing now
        and which keys do (a new operator pressed P, Solve in Update pose, in Designate: nothing said)."""
        own = {c.key.lower() for c in (wf.controls if wf is not None else ()) if c.key}
        uses: dict[str, list[str]] = {}
        for cls in WORKFLOWS.values():
            for c in getattr(cls, "controls", ()):
                if (
                    c.key
                    and c.key.lower() not in own
                    and c.key.lower() not in GLOBAL_KEYS
                    and (wf is not None or c.key != "escape")
                ):
                    uses.setdefault(c.key, [])
                    if f"{c.label} in {cls.title}" not in uses[c.key]:
                        uses[c.key].append(f"{c.label} in {cls.title}")
        here = (
            f"{wf.title}'s keys: " + ", ".join(f"{c.key_text} {c.label}" for c in wf.controls if c.key)
            if wf is not None
            else "start a workflow first"
        )
        for key, where in sorted(uses.items()):
            name = KEY_TEXT.get(key, key.upper())

            def said(_event, name=name, where=where) -> None:
                raise WorkflowError(
                    f"{name} does nothing {'in ' + wf.title if wf is not None else 'now'} "
                    f"(it is {', '.join(where[:2])}): {here}"
                )

            cmd = self.client.gui.add_command(f"{name}: {', '.join(where[:2])}", hotkey=key)
            cmd.on_trigger(self._guard(said))
            self.commands.append(cmd)

    # ------------------------------------------------------------------ callbacks (state only)
    def _on_start(self, name: str, _event=None, frame: Any = None) -> None:
        if self.worker is not None and self.worker.is_alive():
            raise WorkflowError("a measurement is running: wait for it or Cancel it first")
        options: dict[str, Any] = {}
        if name == "model_object" and self.gui_shape.value in ("wedge", "pyramid"):
            # A polyhedron the operator names: its own workflow (faces identified, sides assigned to edges).
            name, options = (
                "model_polyhedron",
                {"shape": self.gui_shape.value, "on_table": bool(self.gui_on_table.value)},
            )
        elif name == "model_object":
            options = {
                "shape": self.gui_shape.value,
                "vertical": bool(self.gui_vertical.value),
                "on_table": bool(self.gui_on_table.value),
            }
        if name not in WORKFLOWS:
            raise WorkflowError(f"the {name.replace('_', ' ')} workflow is not available in this build")
        if self.feeder is not None:
            self.feeder.stop()
            self.feeder = None
        self.error = ""
        wf = self.session.start(name, view=self.camera_view, **options)
        if name == "track":
            self.feeder = TrackFeeder(self, wf, self.feed.grabber)
        if (
            name not in LIVE_WORKFLOWS
            and frame is None
            and self.frozen is not None
            and self.frozen_by is None
            and not self.show_live
        ):
            # a frame the operator froze (F, Seconds back) before starting: the workflow's clicks use it (a
            # new operator froze t = 3.4 s, started a workflow, and found the newest frame frozen instead)
            self._adopt_frozen(wf)
            return
        if name not in LIVE_WORKFLOWS:
            self._freeze(frame if frame is not None else self.feed.grabber.latest(), "live")
        else:
            self._unfreeze()
        if self.gui_scrub.value != 0.0:  # the newest frame is frozen: the scrubber says 0 s back
            self.gui_scrub.value = 0.0

    def _press_event(self, action: str, _event=None) -> None:
        self.press(action)

    def press(self, action: str) -> None:
        """The operator pressed the control of ``action`` (button or shortcut)."""
        wf = self.session.workflow
        if wf is None or wf.finished:
            raise WorkflowError("no workflow is under way: start one first")
        c = wf.control(action)
        if c is None:
            raise WorkflowError(f"{wf.title} has no such control")
        step = wf.current_step()
        if action not in step.enabled:
            raise WorkflowError(f"{c.label} does not apply now. {wf.prompt_text(markdown=False)}")
        if action == "cancel":
            # a running measurement (or search) is stopped alone, at once: the workflow and what was done
            # before it stay (a new operator's Esc while Designate checked a target lost the targets before);
            # work done (clicks, measurements: Remove last applies) is asked about once more
            busy = (self.worker is not None and self.worker.is_alive()) or getattr(wf, "progress", None) is not None
            if busy:
                self.confirm_pending, self.warning, self.error = None, "", ""
                wf.stop_measurement()
                return
            targets = bool(getattr(wf, "targets", None))  # Designate's: nothing written, but the list goes
            if (self._workflow_has_clicks() or targets) and self.confirm_pending != ("cancel", ()):
                self.confirm_pending, self.error = ("cancel", ()), ""
                self.warning = Md(
                    "Cancel throws away what you did in {} (your clicks and measurements; nothing was "
                    "written). Press **Cancel** again to throw it away, or go on."
                ).format(wf.title)
                self._relabel("cancel", f"Cancel: confirm ({c.key_text})" if c.key else "Cancel: confirm")
                return
            self.confirm_pending, self.warning, self.error = None, "", ""
            wf.cancel()  # also stops a running measurement
            return
        if self.worker is not None and self.worker.is_alive():
            raise WorkflowError("a measurement is running: wait for it, or Cancel")
        args: tuple = ()
        if c.arg is not None:
            value = self.choice_values.get(c.arg)
            if value is None:
                chooser = wf.control(c.arg)
                raise WorkflowError(f"choose the {chooser.label.lower() if chooser else 'item'} first, then {c.label}")
            args = (value,)
        # A question asked once more: Redo forgets every click; an undo that discards later changes;
        # Accept of a weak result.
        if (action, args) != self.confirm_pending:
            question = wf.question(action, *args)  # plain text
            again = Md(" Press **{}** again to confirm.").format(c.label)
            if action == "accept":
                weak = wf.weaknesses()
                if weak:
                    question = Md("**Weak result — check before accepting:** {}.").format("; ".join(weak))
                    again = Md(" Press **Accept** again to write it anyway, or improve it first.")
            if question:
                self.confirm_pending, self.warning, self.error = (action, args), escape(question) + again, ""
                again_label = "Accept anyway" if action == "accept" else f"{c.label}: confirm"
                self._relabel(action, f"{again_label} ({c.key_text})" if c.key else again_label)
                return
        self.confirm_pending, self.warning, self.error = None, "", ""
        wf.message = ""  # old messages go: the action says what it did
        if c.kind == "long":
            self.worker = threading.Thread(
                target=self._guard(lambda: self._act(wf, c, args)),
                daemon=True,
                name=f"mcit-measure-{self.client.client_id}",
            )
            self.worker.start()
            return
        self._act(wf, c, args)

    def _act(self, wf, c, args: tuple) -> Any:
        where, self._double_at = (self._double_at, None) if c.action == "find" else (None, self._double_at)
        try:
            result = wf.perform(c.action, *args)
        except WorkflowError as exc:
            if where is None:
                raise
            said = str(exc).rstrip(".")
            raise WorkflowError(
                f"{said}. {where[0].upper()}{where[1:]}" if where.startswith("your") else f"{said} ({where})"
            ) from None
        if not wf.message:
            wf.message = f"{c.label}: done." if c.action not in ("resume", "pause", "restart") else ""
        # (an accepted result is said at the top of the panel: no toast over the video's corner)
        return result

    def _relabel(self, action: str, label: str) -> None:
        handle = self.controls.get(action)
        if handle is not None and hasattr(handle, "label"):
            handle.label = label

    def _on_choice(self, action: str, _event=None) -> None:
        handle = self.controls.get(action)
        wf = self.session.workflow
        if handle is None or wf is None or wf.finished:
            return
        options = self._choice_options.get(action, {})
        if handle.value not in options:
            return
        value = options[handle.value]
        self.choice_values[action] = value
        if self.confirm_pending is not None:  # a question about the item chosen before: it no longer applies
            asked = wf.control(self.confirm_pending[0])
            if asked is not None and asked.arg == action and self.confirm_pending[1] != (value,):
                self.confirm_pending, self.warning = None, ""
        if action in wf.actions and value != wf.choice_value(action):  # a chooser that acts (candidate, method)
            wf.message = ""
            wf.perform(action, value)

    def _on_object(self, _event) -> None:
        value = self.gui_object.value
        self.session.select(None if value == NO_SELECTION else value)

    def _on_stale(self, _event) -> None:
        name = self.session.selected
        if name is None:
            raise WorkflowError("select an object first (click it in the video, or choose it in the list)")
        self.app.site.set_status(name, "stale", method="operator", client=self.session.client)
        self.error = ""
        self.notify("Marked stale", f"{name} is drawn orange until its pose is updated.", "blue")

    def _on_view(self, event) -> None:
        self.view = "3d" if event.target.value == "3D world" else "video"
        self.need_fit = True

    def _request_fit(self) -> None:
        self.zoom_rect = None
        self.need_fit = True

    # ------------------------------------------------------------------ the frozen frame
    def _freeze(self, frame: Any, source: str) -> None:
        if frame is None:
            self.frozen = None
            return
        earlier = self.feed.recent.before(frame, MOTION_GAP_S)  # to see whether what is clicked on was moving
        # the other cameras' frames shown at the same moment: clicks made in them use these
        at = self.feed.recent.arrival(frame)
        at = time.monotonic() if at is None else at
        others = {}
        for name, feed in self.app.views.items():
            hit = None if name == self.camera_view else feed.recent.nearest(at)
            if hit is not None:
                f, arrived = hit
                others[name] = FrameRef(f.image, float(f.t_s), int(f.index), source, view=name, gap_s=arrived - at)
        self.frozen = FrameRef(
            frame.image,
            float(frame.t_s),
            int(frame.index),
            source,
            previous=None if earlier is None else earlier.image,
            view=self.camera_view,
            others=others,
        )
        self.show_live = False
        wf = self.session.workflow
        # a workflow's frozen frame goes with it; one frozen with no workflow under way (to look at
        # it) stays until Show live, or until a workflow freezes its own
        self._adopt_frozen(wf)

    def _adopt_frozen(self, wf) -> None:
        """The frozen frame becomes the workflow's (None or finished: frozen to look at it)."""
        self.frozen_by = wf if wf is not None and not wf.finished else None
        if wf is not None and not wf.finished:
            wf.use_frame(self.frozen)
            if wf.name == "update_pose":  # its auto match and search read the frame's edges: ready them now
                threading.Thread(
                    target=_prepare_frame, args=(self.frozen.image,), daemon=True, name="mcit-frame-edges"
                ).start()

    def _unfreeze(self) -> None:
        self.frozen = None
        self.frozen_by = None
        self.show_live = False

    def _workflow_has_clicks(self) -> bool:
        wf = self.session.workflow
        return wf is not None and not wf.finished and "remove_last" in wf.current_step().enabled

    def _freeze_back(self, seconds: float) -> None:
        """Freeze the frame shown ``seconds`` before the newest (0: the newest)."""
        wf = self.session.workflow
        if (
            wf is not None
            and not wf.finished
            and (wf.name == "history" or (wf.name == "track" and wf.current_step().name in ("tracking", "waiting")))
        ):
            raise WorkflowError(
                f"{wf.title} follows the live video: nothing to freeze"
                + (" (Pause it first)" if wf.name == "track" else "")
            )
        if wf is not None and wf.finished and self._finished_at is not None and self._finished_at[0] is wf:
            self._finished_at = (wf, self._finished_at[1], object())  # the operator moved on: its text goes
        if self._workflow_has_clicks():
            raise WorkflowError(
                "your clicks were made on the frozen frame: every click of a workflow uses one frame. "
                "Remove them (Remove last) or Cancel before freezing another frame"
            )
        frame = self.feed.recent.seconds_back(seconds) if seconds > 0 else self.feed.grabber.latest()
        if frame is None:
            raise WorkflowError("no video frame has arrived yet: check the video source")
        self._freeze(frame, "scrubbed" if seconds > 0 else "live")
        self.error = ""

    def _follow_frame(self, wf) -> None:
        """Which frame to show now: a finished workflow's frozen frame goes (back to the live video);
        Track freezes the frame where it paused or was lost (its clicks and re-initialisation use
        it) and lets it go when it follows the video again."""
        if wf is None or wf.finished:
            if self.frozen is not None and getattr(self, "frozen_by", None) is not None:
                self._unfreeze()
                if self.gui_scrub.value != 0.0:  # back to the live video: the scrubber says so (it kept "4")
                    self.gui_scrub.value = 0.0
                self.dirty = True
            return
        if wf.name != "track":
            return
        following = wf.current_step().name in ("tracking", "waiting")
        if following and self.frozen is not None:
            wf.use_frame(None)
            self._unfreeze()
            self.dirty = True
        elif not following and self.frozen is None:
            self._freeze(self.feed.grabber.latest(), "live")
            self.dirty = True

    def _on_scrub(self, event) -> None:
        if event.client_id is None:  # the panel set it back to 0 itself: nothing to freeze
            return
        self._freeze_back(float(self.gui_scrub.value))

    def _toggle_live(self) -> None:
        if self.frozen is None:
            raise WorkflowError("no frame is frozen: the live video is shown")
        self.show_live = not self.show_live

    def _send_frozen(self) -> None:
        """Show this client's frozen frame (sharp, upscaled) over the live video, or hide it."""
        # the frozen frame of the camera shown: its own, or the one frozen with it in another camera
        ref = None if self.frozen is None else self.frozen.others.get(self.camera_view, self.frozen)
        if ref is not None and ref.view and ref.view != self.camera_view:
            ref = None  # no frame of the shown camera was frozen with it: its live video shows
        key = None if (ref is None or self.show_live or self.view != "video") else id(ref)
        if key == self._frozen_sent:
            return
        self._frozen_sent = key
        if key is None:
            self.client.scene.remove_by_name("/frozen")
            return
        import cv2

        pw = self.app.views.get(ref.view, self.feed).pixel_world  # on its own camera's image
        image = ref.image
        if image.ndim == 2:
            image = np.repeat(image[:, :, None], 3, axis=2)
        up = max(1, min(4, FROZEN_MAX_SIDE // max(image.shape[:2])))
        if up > 1:  # nearest neighbour: zoomed in, the operator sees pixels, not blur
            image = cv2.resize(image, None, fx=up, fy=up, interpolation=cv2.INTER_NEAREST)
        rw, rh = pw.render_size
        cx, cy, _ = pw.image_center
        self.client.scene.add_image(
            "/frozen",
            image,
            rw,
            rh,
            format="png",
            position=(float(cx), float(cy), Z_FROZEN),
            cast_shadow=False,
            receive_shadow=False,
        )

    # ------------------------------------------------------------------ clicks
    def on_pixel_click(self, uv: np.ndarray, at: float | None = None, double: bool | None = None) -> None:
        """A click at pixel uv of the video, arrived at time ``at`` (monotonic; default now): the
        workflow's, or else select the nearest object. ``double``: it is the second click of a double
        click (told by the page), or not; None: a double click if it follows the last click closely in
        time and place at the server."""
        wf = self.session.workflow
        now, last = (time.monotonic() if at is None else float(at)), getattr(self, "_last_click", None)
        told = self._last_double
        if not double and told is not None and 0 <= now - told[0] <= LATE_FIRST_CLICK_S:
            if np.linalg.norm(uv - told[1]) <= LATE_FIRST_CLICK_PX:
                # the double click's own first click, arriving after the double that the page told (on a loaded
                # machine the two messages can swap): it was taken as part of the double, not as a new click
                # (as an edge's first point it hid the found poses' Accept)
                self._last_double = None
                return
        if double:  # its first click expected still when none came before it at that point
            first_seen = (
                last is not None
                and now - last[0] <= LATE_FIRST_CLICK_S
                and np.linalg.norm(uv - last[1]) <= LATE_FIRST_CLICK_PX
            )
            self._last_double = None if first_seen else (now, np.asarray(uv, float).copy())
        if double is None:
            double = (
                last is not None and now - last[0] <= DOUBLE_CLICK_S and np.linalg.norm(uv - last[1]) <= DOUBLE_CLICK_PX
            )
        # the frame shown at this click: a double click that starts Update pose freezes it (the newest, a
        # moment later, showed a moving box elsewhere: a new operator's run)
        self._last_click = (now, np.asarray(uv, float).copy(), self.session.selected, self.feed.grabber.latest())
        if (wf is None or wf.finished) and double:
            # no workflow, a double click: the object's pose is found from that point — Update pose started
            # and Find pressed at once. The object is the one selected before the double click, even when its
            # first click selected another whose wireframe runs there (the table's edge across the moved box:
            # a new operator's double click selected the table); with none selected before, the one its first
            # click selected (a new operator's double click with nothing selected only selected it)
            self._last_click = None
            if last is None:  # its first click not seen (told by the page alone): as if made here
                last = (now, uv, self.session.selected, self.feed.grabber.latest())
            name = last[2] if last[2] is not None else self.session.selected
            on = self._object_at(uv)
            if name is not None and on not in (None, name) and self._is_table(name):
                # the table selected, a double click on another object: that object's pose is meant (the
                # table's search was refused, and a new operator was left in Update pose: table)
                name = on
            if name is None:
                raise WorkflowError(
                    "a double click finds the pose of the selected object: select it by a click where the "
                    "database draws it, then double-click where it is in the video"
                )
            self.session.select(name)
            # the frame the double click was made on: the one the operator froze (F, Seconds back) when one is
            # shown, else the live frame shown at its first click (a new operator's frozen t = 24.75 s was
            # replaced by 27.58 s, where the box had moved)
            looked_at = self.frozen is not None and self.frozen_by is None and not self.show_live
            self._on_start("update_pose", frame=None if looked_at else last[3])
            self.session.workflow.click(uv)
            self._find_from_double_click(uv, name)
            return
        if wf is not None and not wf.finished and "click" in wf.actions:
            if double and wf.view != self.camera_view:
                raise WorkflowError(
                    f"a double click finds the pose in camera {wf.view}, where {wf.title} started: double-click there"
                )
            step = wf.current_step()
            if double and wf.double_click_is_one:  # its first click was the click: the second is dropped
                self._last_click = None
                return
            if double and getattr(wf, "found", None) is not None and hasattr(wf, "search_again"):
                # found poses there, a double click again (a better point): search again from it
                self._last_click = None
                wf.search_again(uv)
                self._find_from_double_click(uv, getattr(wf, "object_name", None))
                return
            if double and "find" in step.enabled:
                # a double click on the moved object: find its pose from that point (Find, at once)
                self._last_click = None
                self._find_from_double_click(uv, getattr(wf, "object_name", None))
                return
            if step.clicks:
                if self.show_live and self.frozen is not None:
                    raise WorkflowError(
                        "you are looking at the live video: clicks go to the frozen frame. Press Show "
                        "frozen (L) to see it, then click"
                    )
                self.error, self.confirm_pending, self.warning = "", None, ""
                wf.message = ""
                wf.click_in(self.camera_view, uv)  # the workflow says whether it takes clicks in this camera
                return
            if wf.name != "track":
                raise WorkflowError(f"clicks are not taken now. {wf.prompt_text(markdown=False)}")
        name = self._object_at(uv)
        self.session.select(name)
        self.error = ""

    def _find_from_double_click(self, uv: np.ndarray, name: str | None) -> None:
        """Find, pressed by a double click at uv; a refusal says where the click was and, when it lies on
        another object as the database draws it, that object (a new operator double-clicked box_1 with the
        parallelepiped selected, and read the same refusal three times, not knowing whether a click was taken)."""
        other = self._object_at(uv)
        # when it was (a repeated refusal reads as new: the pixel meant nothing to a new operator)
        self._double_at = (
            f"your double click is on {other} as the database draws it: to update {other}, Cancel (Esc), "
            "click it to select it, then double-click where it is in the video"
            if other not in (None, name) and not self._is_table(other)
            else f"double click at {time.strftime('%H:%M:%S')}"
        )
        self.press("find")

    def _on_click(self, event, arrival: float | None = None) -> None:
        arrival = time.monotonic() if arrival is None else arrival
        try:
            self._handle_click(event, arrival)
        finally:
            self.click_t = arrival  # answered by the first redraw after this callback (for the benchmark)

    def _handle_click(self, event, arrival: float | None = None) -> None:
        if self.view != "video":
            raise WorkflowError("clicks work on the video: switch the view to Video")
        uv = self._pixel_of_ray(np.array(event.ray_origin), np.array(event.ray_direction))
        # the page tells double clicks (_on_double), keeping their second click from the viewer; two clicks
        # that reach the server close in time and place are one too (a page whose script did not run)
        self.on_pixel_click(uv, arrival)

    def _pixel_of_ray(self, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """The pixel a click's ray meets: on the shown camera's image, or on another camera's (seen beside
        it when zoomed out), which is then the camera shown; a WorkflowError when it meets no image."""
        hit = self.app.view_at(origin, direction)
        if hit is not None and hit[0] != self.camera_view:
            self.camera_view = hit[0]  # the view stays where the operator put it
            if self.gui_camera is not None and self.gui_camera.value != hit[0]:
                self.gui_camera.value = hit[0]
        return self._on_image(None if hit is None else hit[1])

    def _on_image(self, uv: np.ndarray | None) -> np.ndarray:
        """uv, a clicked pixel, if it lies on the image; else a WorkflowError that says so."""
        if uv is None:
            raise WorkflowError("that click missed the image: click on the video")
        w, h = self.feed.pixel_world.width, self.feed.pixel_world.height
        if not (-0.5 <= uv[0] <= w - 0.5 and -0.5 <= uv[1] <= h - 0.5):
            raise WorkflowError(f"that click is outside the {w}×{h} image: click on the video")
        return uv

    def _on_double(self, value: str, arrival: float) -> None:
        """A double click on the video, told by static/wheel.js as "x y n" (x, y in 0..1 of the canvas):
        the second click of it, at that point. Its first click came as an ordinary click."""
        try:
            sx, sy = (float(v) for v in value.split()[:2])
        except ValueError:
            return  # cleared, or typed into the hidden field: not a double click
        if not (np.isfinite(sx) and np.isfinite(sy)) or self.view != "video":
            return
        try:
            ray = self._screen_ray(self.client.camera, (sx, sy))
        except (AssertionError, ZeroDivisionError):  # no camera reported yet
            return
        self.on_pixel_click(self._pixel_of_ray(*ray), arrival, double=True)
        self.click_t = arrival

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

    @staticmethod
    def _screen_ray(cam, screen_xy) -> tuple[np.ndarray, np.ndarray]:
        """The viewer ray (origin, direction) through screen point (x, y) in 0..1 of the canvas."""
        R = viser.transforms.SO3(np.asarray(cam.wxyz)).as_matrix()
        t = np.tan(cam.fov / 2.0)
        sx, sy = screen_xy
        d_cam = np.array([(2 * sx - 1) * t * cam.aspect, (2 * sy - 1) * t, 1.0])
        return np.asarray(cam.position), R @ d_cam

    def _screen_to_pixel(self, cam, screen_xy) -> np.ndarray | None:
        """The shown camera's pixel at screen point (x, y) in 0..1 of the canvas."""
        return self.feed.pixel_world.pixel_from_ray(*self._screen_ray(cam, screen_xy))

    def _on_wheel(self, _event) -> None:
        """Zoom about the point under the cursor: "x y deltaY n" from static/wheel.js (x, y in 0..1)."""
        try:
            sx, sy, dy = (float(v) for v in str(self.gui_wheel.value).split()[:3])
        except ValueError:
            return  # not a wheel message (cleared, or typed): ignore
        if not (np.isfinite(sx) and np.isfinite(sy) and np.isfinite(dy)):
            return
        cam = self.client.camera
        try:
            position, look_at = np.asarray(cam.position, float), np.asarray(cam.look_at, float)
            R = viser.transforms.SO3(np.asarray(cam.wxyz)).as_matrix()
            t, aspect = np.tan(cam.fov / 2.0), cam.aspect
        except (AssertionError, ZeroDivisionError):
            return
        ray = R @ np.array([(2 * sx - 1) * t * aspect, (2 * sy - 1) * t, 1.0])
        if self.view == "video":  # the point of the image plane (z = 0) under the cursor
            if abs(ray[2]) < 1e-9:
                return
            X = position + (-position[2] / ray[2]) * ray
        else:  # the 3D world: the point under the cursor at the distance of the orbit's centre
            X = position + np.linalg.norm(look_at - position) * ray / np.linalg.norm(ray)
        f = float(np.clip(np.exp(dy * WHEEL_ZOOM_PER_DELTA), 0.5, 2.0))
        if self.view == "video":  # between 200× in and a little beyond the whole image (every camera's)
            fit = max(
                abs(float(self.feed.pixel_world.fit_camera(aspect, cam.fov)[0][2])),
                abs(float(self.app.all_images.fit_camera(aspect, cam.fov)[0][2])) / 2.0,
            )
            dist = abs(float(position[2]))
            if not dist > 1e-9:  # a camera in the image's plane (a page can report one): nothing to zoom about
                return
            f = float(np.clip(f, 0.005 * fit / dist, 2.0 * fit / dist))
        with self.client.atomic():
            _place_camera(cam, X + f * (position - X), X + f * (look_at - X))
        self.dirty = True

    def _on_camera(self, cam) -> None:
        try:
            aspect = cam.aspect
        except (AssertionError, ZeroDivisionError):
            return
        if self.fitted_aspect is None or abs(aspect - self.fitted_aspect) > 1e-3:
            self.need_fit = True
            self.app.wake()
            return
        scale = self._zoom_scale(cam)
        if scale is not None and abs(np.log(scale / self.marks_scale)) > 0.1:  # zoomed: marks keep their screen size
            self.dirty = True
            self.app.wake()

    def _zoom_scale(self, cam) -> float | None:
        """Image pixels per screen pixel now, relative to the fitted view (1 at fit, 0.1 at 10× zoom)."""
        try:
            dist = abs(float(cam.position[2]))  # the image plane is z = 0 in the pixel world
            fov, aspect = cam.fov, cam.aspect
        except (AssertionError, ZeroDivisionError, TypeError):
            return None
        pw = self.feed.pixel_world
        fit_pos, _, _ = pw.fit_camera(aspect, fov)
        fit = abs(float(fit_pos[2]))
        return float(np.clip(dist / fit, 0.02, 4.0)) if fit > 0 else None

    def _image_px_per_screen_px(self) -> float:
        """Video pixels per screen pixel in this client's view now (1 when it is not known)."""
        try:
            cam = self.client.camera
            dist = abs(float(cam.position[2]))
            visible = (
                2.0 * dist * np.tan(float(cam.fov) / 2.0) / self.feed.pixel_world.k
            )  # video px across the canvas' height
            k = visible / float(cam.image_height)
        except (AssertionError, ZeroDivisionError, TypeError, AttributeError, ValueError):
            return 1.0
        return k if np.isfinite(k) and k > 0 else 1.0

    # ------------------------------------------------------------------ helpers
    def _object_at(self, uv: np.ndarray) -> str | None:
        """The object a click at uv picks (the overlay's own projections: nothing projected here)."""
        return self.app.object_at(uv, self.select_radius_px(), self.camera_view)

    def _is_table(self, name: str) -> bool:
        """The object ``name`` is the site's table (what the others stand on)."""
        try:
            return self.app.site.object(name).kind == "table"
        except ValueError:  # gone from the database meanwhile
            return False

    def select_radius_px(self) -> float:
        """How near a wireframe a click picks its object, in video pixels at this client's zoom."""
        return SELECT_RADIUS_SCREEN_PX * self._image_px_per_screen_px()

    # ------------------------------------------------------------------ drawing (loop only)
    def fit(self) -> None:
        cam = self.client.camera
        try:
            aspect, fov = cam.aspect, cam.fov
        except (AssertionError, ZeroDivisionError):
            return  # the browser has not reported its camera yet
        self.need_fit = False
        self.fitted_aspect = aspect
        pw = self.feed.pixel_world
        if self.view == "video":
            rect = self.zoom_rect
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
            _place_camera(cam, position, look_at)
        self.dirty = True

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
        self._announce()
        wf = self.session.workflow
        if wf is not self.built_for or (wf is not None and wf.finished and self.controls):
            ended = self.built_for
            if (
                ended is not None
                and ended.finished
                and getattr(ended, "progress", None) is None
                and ended.name in ("calibrate_turret", "model_object", "model_polyhedron", "designate")
            ):
                self.app.site.set_beam(None)  # the range finder's spot of a closed workflow would go stale
            self._rebuild_controls()
        idle = wf is None or wf.finished
        if self.gui_start.visible != idle:
            self.gui_start.visible = idle
        busy = self.worker is not None and self.worker.is_alive()
        progress = wf.progress if wf is not None else None
        self.gui_progress.visible = bool(busy or (progress is not None and 0 < progress < 1))
        if progress is not None:
            self.gui_progress.value = float(np.clip(progress * 100.0, 0, 100))
        self._follow_frame(wf)
        self._send_frozen()
        if not (self.dirty or site_changed or busy):
            return False
        self.dirty = False
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
        scale = self._zoom_scale(self.client.camera) if self.view == "video" else None
        self.marks_scale = 1.0 if scale is None else scale
        batch, labels = draw_marks(
            camera, marks, objects, pw.width, pw.height, selected=self.session.selected, scale=self.marks_scale
        )
        labels = spread_labels(labels, self._image_px_per_screen_px())
        self._labels_sent = self.app.send_client_overlay(self.client, batch, labels, self._labels_sent, pw)
        self._update_texts(wf)
        if self.click_t is not None:
            self.click_latencies_s.append(time.monotonic() - self.click_t)
            self.click_t = None
        return True

    def _weak_now(self, wf, step) -> list[str]:
        """The result's weaknesses while Accept applies (``Workflow.weaknesses``), read again only when the
        workflow's step, message or choice changed."""
        if wf.finished or "accept" not in step.enabled:
            return []
        key = (id(wf), step.name, wf.message, getattr(wf, "chosen", None))
        if getattr(self, "_weak_key", None) != key:
            self._weak_key = key
            try:
                self._weak = list(wf.weaknesses())
            except Exception:  # noqa: BLE001 - Accept asks again anyway
                log.exception("weaknesses of %s failed", wf.name)
                self._weak = []
        return self._weak

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

    def _update_texts(self, wf) -> None:
        selected = self.session.selected
        idle = _idle_text(selected)
        if (
            wf is not None
            and wf.finished
            and self._finished_at is not None
            and self._finished_at[0] is wf
            and self._finished_at[2] != selected
        ):
            # a finished workflow's text goes once the operator selects another object (it stayed on), and does
            # not come back with the selection it finished with (a new operator's Designate "closed" text did)
            self._finished_at = (wf, self._finished_at[1], object())
            wf = None
        if wf is None:
            title = Md("**No workflow.** ") + idle
            report = ""
            step = None
        else:
            step = wf.current_step()
            closes = wf.control("accept")  # History's Close, Designate's Done: nothing is accepted
            done = "accepted" if closes is None or closes.label == "Accept" else "closed"
            if wf.finished and (self._finished_at is None or self._finished_at[0] is not wf):
                self._finished_at = (wf, time.strftime("%H:%M:%S"))  # when this page saw it finish
                if wf.accepted and wf.name.startswith("model_") and wf.object_name:
                    try:  # the object just modelled is selected: Update pose, Track … apply to it next
                        self.session.select(wf.object_name)
                    except WorkflowError:
                        pass
                    selected = self.session.selected
                    idle = _idle_text(selected)
                self._finished_at = (wf, self._finished_at[1], selected)
            at = f" at {self._finished_at[1]}" if wf.finished else ""  # a finished workflow's text says when
            state = f" ({done}{at})" if wf.accepted else (f" (cancelled{at})" if wf.cancelled else "")
            subject = wf.object_name
            head = Md("**{}**{}").format(f"{wf.title}: {subject}" if subject else wf.title, state)
            if len(self.app.views) > 1:  # which camera it works in, and which is shown
                head += Md(" · in camera **{}**").format(wf.view)
                if wf.view != self.camera_view:
                    head += Md(" (camera {} shown)").format(self.camera_view)
            prompt = wf.prompt_text()
            title = head + Md("\n\n") + prompt
            if (
                wf.message
                and not wf.finished
                and not self.warning
                and wf.message[:40] not in wf.prompt_text(markdown=False)
            ):
                title += Md("\n\n_{}_").format(wf.message)  # not said twice, nor above a question being asked
            weak = [w for w in self._weak_now(wf, step) if w not in wf.message]  # not said twice
            if weak and not self.warning:  # said with the result, not first at Accept (a new operator's)
                title += Md("\n\n⚠ **Check before accepting:** {}.").format("; ".join(weak))
            if wf.finished:
                title += Md("\n\n") + idle
            # a cancelled result is gone; a closed one (History, Designate: nothing accepted) too
            report = "" if wf.cancelled or (wf.finished and done == "closed") else report_markdown(wf.summary())
            if self.error and self.error_step is not None and step.name != self.error_step:
                self.error = ""  # said in a step the workflow has left
        if self.error:
            title += Md("\n\n⚠ {}").format(self.error)
        _show(self.gui_title, title)
        _show(self.gui_report, report)
        self.gui_warning.visible = bool(self.warning)
        _show(self.gui_warning, self.warning)
        self._update_controls(wf, step)
        text = wf.copy_text() if wf is not None and not wf.finished else ""
        self.gui_copy.visible = bool(text)
        if text and self.gui_copy.value != text:
            self.gui_copy.value = text
        video = self.feed.grabber.status()
        live = Md(
            "Live video (no frame frozen)"
            if video.live
            else "**Not live**: the video is lost and the image is "
            "its last frame, greyed; no frame frozen (the status below says more)"
        )
        frame = (
            live + Md(". *Seconds back* freezes an earlier frame.")
            if self.frozen is None
            else (
                Md("Frozen frame: t = {:.2f} s").format(self.frozen.t_s)
                + Md(" · **live shown**" if self.show_live else "")
                + Md(". *Seconds back*: a frame that long before the live one.")
            )
        )
        _show(self.gui_frame, frame)
        live_label = "Show frozen (L)" if self.show_live and self.frozen is not None else "Show live (L)"
        if self.gui_live.label != live_label:  # says what it does now (it kept "Show live" while live was shown)
            self.gui_live.label = live_label

    def _update_controls(self, wf, step) -> None:
        """Show the controls that apply now (the others hidden), the choosers' options, shortcuts on/off."""
        if wf is None or step is None or wf is not self.built_for:
            return
        busy = self.worker is not None and self.worker.is_alive()
        applies = {c.action for c in wf.controls if c.action in step.enabled and not (busy and c.action != "cancel")}
        keyed = _live_shortcuts(wf.controls, applies)
        for c in wf.controls:
            handle = self.controls.get(c.action)
            if handle is None:
                continue
            on = c.action in applies
            if handle.visible != on:
                handle.visible = on
            # A shortcut stays live when its control is hidden: pressing it then says why it does not
            # apply (feedback); of controls sharing a key (Pause/Resume) only the one that applies.
            cmd = self._command_of.get(c.action)
            live = keyed.get(c.key) == c.action
            if cmd is not None and cmd.disabled == live:
                cmd.disabled = not live
            if c.kind == "choice" and on:
                opts = wf.choices(c.action)
                texts = {text: value for text, value in opts}
                self._choice_options[c.action] = texts
                options = tuple(texts) if texts else (NO_CHOICE,)
                if tuple(handle.options) != options:
                    handle.options = options
                current = wf.choice_value(c.action)
                if current is None:
                    current = self.choice_values.get(c.action)
                shown = next((t for t, v in texts.items() if v == current), None)
                if shown is None:
                    self.choice_values.pop(c.action, None)
                    shown = options[0]
                    if texts:
                        self.choice_values[c.action] = texts[shown]
                if handle.value != shown:
                    handle.value = shown
            if c.kind != "choice" and (self.confirm_pending or (None,))[0] != c.action:
                if handle.label != c.button_label:
                    handle.label = c.button_label

    def close(self) -> None:
        """The browser left: stop its click worker and tracking, and cancel its workflow."""
        self._click_worker.shutdown(wait=False, cancel_futures=True)
        if self.feeder is not None:
            self.feeder.stop()
        self.session.cancel()

    def set_status(self, text: str) -> None:
        _show(self.gui_status, text)


def _show(handle, content) -> None:
    """Set a Markdown element's content: ``Md`` as written, any other text escaped (app.markup)."""
    text = as_markdown(content)
    if handle.content != text:
        handle.content = text


def _place_camera(cam, position: np.ndarray, look_at: np.ndarray) -> None:
    """Move a client's camera. The position first: viser moves the look-at point with it, and refuses a
    look-at point equal to the position the camera has at that moment (whatever the page reported)."""
    cam.position = position
    cam.look_at = look_at


def _idle_text(selected: str | None) -> str:
    """What the panel says with no workflow under way."""
    if selected is None:
        return Md("Click an object to select it, or start a workflow below.")
    return Md(
        "**{}** is selected: double-click where it is in the video to find its pose, start a workflow below "
        "(Update pose, Track, …), or click another object."
    ).format(selected)


def _live_shortcuts(controls, applies) -> dict[str, str]:
    """key → the action its shortcut triggers now: of the controls sharing a key (Pause/Resume), the
    first that applies; a key whose controls all are hidden stays live on the first of them, so that
    pressing it says why it does not apply (feedback)."""
    live: dict[str, str] = {}
    for c in controls:
        if c.key is not None and c.action in applies:
            live.setdefault(c.key, c.action)
    for c in controls:
        if c.key is not None:
            live.setdefault(c.key, c.action)
    return live


def _sentence(text: str) -> str:
    """An operator message as a sentence: capitalised, ending with a full stop."""
    text = text.strip()
    if not text:
        return text
    first = text.split(" ", 1)[0]
    if not any(ch == "_" or ch.isdigit() for ch in first):  # an object's name ("cylinder_1 has …") keeps its case
        text = text[0].upper() + text[1:]
    return text if text.endswith((".", "!", "?")) else text + "."


def _prepare_frame(image) -> None:
    """The frozen frame's oriented edges, computed in the background (app.vision.evaluate)."""
    try:
        from app.vision.evaluate import prepare_frame

        prepare_frame(image)
    except Exception:  # noqa: BLE001 - only a head start: the workflow computes them when it needs them
        log.debug("could not prepare the frozen frame's edges", exc_info=True)
