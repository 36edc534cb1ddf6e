"""The panel's fixed layout: the workflow under way first (its instruction and actions always above the
fold), then starting one, the frame and the view, the object, the result, the status and the help; and
the page's hidden fields that static/wheel.js writes the wheel and double clicks into."""

from __future__ import annotations

import functools
import logging
import time
from typing import TYPE_CHECKING

import viser

from app.markup import Md
from app.workflows.session import WORKFLOWS

from .controls import START_BUTTONS, operator_help
from .workflow_controls import on_key

if TYPE_CHECKING:  # pragma: no cover
    from .client import ClientPanel

__all__ = ["build_panel", "WHEEL_FIELD", "DOUBLE_FIELD", "SIZE_FIELD", "SHAPES"]

log = logging.getLogger("mcit.ui")

WHEEL_FIELD = "mcit-wheel"  # the hidden text field static/wheel.js writes the wheel into
DOUBLE_FIELD = "mcit-dblclick"  # the hidden text field static/wheel.js writes a double click into
SIZE_FIELD = "mcit-canvas"  # the hidden text field static/wheel.js writes the 3D view's size on screen into
SHAPES = ("box", "cylinder", "cone", "wedge", "pyramid")  # Model object's shapes
NO_SELECTION = "(none)"


def build_panel(panel: ClientPanel) -> None:
    """Add the panel's elements to ``panel.client``'s GUI, each as ``panel.gui_*``, with their callbacks."""
    gui, guard = panel.client.gui, panel.guard
    try:  # a docked panel leaves the whole canvas to the video
        gui.main_panel.dock_right()
        gui.main_panel.set_width(340)
    except Exception:  # noqa: BLE001 - layout only
        log.debug("could not dock the panel", exc_info=True)
    panel.gui_title = gui.add_markdown(Md("**No workflow.** Click an object to select it, or start a workflow below."))
    panel.gui_notice = gui.add_markdown("", visible=False)  # the server's notice to every operator (solvers ready?)
    panel.gui_progress = gui.add_progress_bar(0.0, visible=False)
    panel.gui_actions = gui.add_folder(None)
    # A question asked once more (a weak result, Redo) goes under the buttons: shown above them it pushed the
    # button just pressed down, away from the cursor about to press it again.
    panel.gui_warning = gui.add_markdown("", visible=False)
    # the result's σ and residuals under the buttons: the Result section was below the fold at 1280×720
    panel.gui_headline = gui.add_markdown("", visible=False)
    panel.gui_copy = gui.add_text("Target (m)", "", visible=False, hint="World x y z of the last target: copy it")
    # Hidden while a workflow is under way (Cancel it to start another): at 1280×720 its buttons pushed the
    # frame's controls (Freeze, Seconds back) below the fold (a new operator's run).
    panel.gui_start = gui.add_folder("Start a workflow")
    with panel.gui_start:
        missing: dict[str, list[str]] = {}  # why → the workflows this site cannot run for that reason
        for label, name in START_BUTTONS:
            why = WORKFLOWS[name].available(panel.app.site)
            if why:  # e.g. Move robot on a site with no robot: not offered, and said why below
                missing.setdefault(why, []).append(label)
                continue
            gui.add_button(label).on_click(guard(functools.partial(panel.start, name)))
        if missing:
            gui.add_markdown(
                Md("*Not on this site:* ")
                + Md("; ").join(Md("{} ({})").format(", ".join(labels), why) for why, labels in missing.items())
            )
        # Model object's form, shown where it is offered; "Lies on the table" where the database has a table
        shown = not WORKFLOWS["model_object"].available(panel.app.site)
        has_table = any(o.kind == "table" for o in panel.app.site.objects())  # a site of one's own may have none
        panel.gui_shape = gui.add_dropdown(
            "Shape", SHAPES, initial_value="box", hint="Model object: the shape you see", visible=shown
        )
        panel.gui_vertical = gui.add_checkbox(
            "Vertical", True, hint="Model object: its axis/sides are vertical", visible=shown
        )
        panel.gui_on_table = gui.add_checkbox(
            "Lies on the table", has_table, hint="Model object: it stands on the table", visible=shown
        )
        panel.gui_snap = gui.add_checkbox(
            "Snap clicks",
            True,
            hint="Snap clicked edges and corners to the image (Refuse snap keeps a click as clicked)",
        )
        panel.gui_snap.on_update(guard(lambda _e: panel.session.set_snap(bool(panel.gui_snap.value))))
    frozen, viewport = panel.frozen_frames, panel.viewport
    with gui.add_folder("Frame and view"):
        panel.gui_frame = gui.add_markdown("")
        freeze = gui.add_button("Freeze (F)", hint="Freeze the newest frame: clicks, snapping and solving use it")
        freeze.on_click(guard(lambda _e: frozen.freeze_back(0)))
        panel.gui_live = gui.add_button(
            "Show live (L)", hint="Look at the live video (clicks still go to the frozen frame: switch back to click)"
        )
        panel.gui_live.on_click(guard(lambda _e: frozen.toggle_live()))
        panel.gui_scrub = gui.add_slider("Seconds back", 0.0, float(panel.feed.recent.seconds), 0.5, 0.0)
        panel.gui_scrub.on_update(guard(panel.on_scrub))
        panel.gui_camera = None
        if len(panel.app.views) > 1:  # which camera's image is shown and clicked in (N: the next one)
            panel.gui_camera = gui.add_dropdown(
                "Camera (N)", tuple(panel.app.views), initial_value=panel.camera_view, hint="The camera shown"
            )
            panel.gui_camera.on_update(guard(lambda _e: panel.show_camera(str(panel.gui_camera.value))))
        view = gui.add_button_group("View", ("Video", "3D world"))
        view.on_click(guard(lambda e: viewport.set_view("3d" if e.target.value == "3D world" else "video")))
        fit = gui.add_button(
            "Fit view (H)",
            icon=viser.Icon.ZOOM_RESET,
            hint="Show the whole image; again: every camera's (a left drag zooms onto a rectangle)",
        )
        fit.on_click(guard(lambda _e: viewport.request_fit()))
    with gui.add_folder("Object"):
        panel.gui_object = gui.add_dropdown("Object", (NO_SELECTION,), initial_value=NO_SELECTION)

        async def chosen(event) -> None:
            """The operator's choice, as it arrives (the value read now: a redraw may set the chooser back before a
            worker runs), selects it after the clicks before it. The panel's own setting of the chooser (``_draw``:
            to a selection read before a click changed it) selected back what the click had changed: not a choice."""
            if event.client_id is not None:
                try:
                    panel.click_worker.submit(guard(panel.select), str(event.target.value))
                except RuntimeError:  # the page gone
                    pass

        panel.gui_object.on_update(chosen)
        stale = gui.add_button("Mark stale", hint="The selected object has moved: flag it until its pose is updated")
        stale.on_click(guard(panel.mark_stale))
    with gui.add_folder("Result"):
        panel.gui_report = gui.add_markdown("")
    panel.gui_status = gui.add_markdown("…")
    with gui.add_folder("Help", expand_by_default=False):
        gui.add_markdown(Md(operator_help()))  # static/help.md: the project's own file
    for label, key, fn in (
        ("Freeze", "F", lambda: frozen.freeze_back(0)),
        ("Show live / frozen", "L", frozen.toggle_live),
        ("Fit view", "H", viewport.request_fit),
        *((("Next camera", "N", panel.show_camera),) if len(panel.app.views) > 1 else ()),
    ):  # workflow_controls.GLOBAL_KEYS
        gui.add_command(label, hotkey=key).on_trigger(on_key(panel, lambda _e, fn=fn: fn()))
    # The hidden fields come last: the page shows them only once it has taken everything before them, the
    # shortcuts included (a page-ready sign for the browser tests, tests/e2e/harness.py).
    # Wheel zoom about the cursor (static/wheel.js, run by the page: app/ui/page.py): viser zooms to the centre;
    # the page script sends the cursor and the wheel through this hidden field instead.
    wheel = gui.add_text(WHEEL_FIELD, "")
    wheel.on_update(guard(lambda _e: viewport.on_wheel(str(wheel.value))))
    size = gui.add_text(SIZE_FIELD, "")  # the view's size in the screen's pixels (viser's are the canvas's own)
    size.on_update(guard(lambda _e: viewport.on_canvas_size(str(size.value))))
    # Double clicks are told by the page (static/wheel.js), timed by the browser: at the server a double
    # click's two messages arrived 0.3–2.7 s apart on a loaded machine.
    double = gui.add_text(DOUBLE_FIELD, "")
    on_double = guard(panel.on_double)

    async def told(_event) -> None:  # after the click before it, in the order they arrive
        panel.clicks_received += 1
        panel.click_worker.submit(on_double, str(double.value), time.monotonic())

    double.on_update(told)
