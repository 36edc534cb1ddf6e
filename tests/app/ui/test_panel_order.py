"""The panel's state against the order things happen in, on a real mcit interface reached by a page's websocket
(tests/app/ui/test_ws_fuzz.py's ``Served``): the panel's own setting of the Object chooser is not the operator's
choice; a click that reached the server before a question (handled after it) leaves the question; a question's
button label is drawn from the panel's state by every redraw (a redraw that read the state before the question had
set it back); the controls come back when a long action's worker ends after its last redraw; a press during a long
action is refused, and one as its worker ends waits for it."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from app.workflows import WorkflowError
from tests.app.ui.test_ws_fuzz import Page, Served, camera
from tests.e2e.harness import wait_until


@pytest.fixture
def served_page(site, caplog, monkeypatch):
    """A served interface, a page on it and its panel, the object list drawn; closed after the test."""
    served = Served(site, caplog, monkeypatch)
    page, panel = served.page()
    try:
        wait_until(lambda: "parallelepiped" in panel.gui_object.options, 15.0, "the object list drawn")
        yield served, page, panel
    finally:
        page.close()
        served.stop()


def _update_pose_controls(panel):
    """Update pose started on the parallelepiped, its controls built: the workflow and the controls."""
    panel.session.select("parallelepiped")
    wf = panel.session.start("update_pose")
    controls = panel.workflow_controls
    wait_until(lambda: controls.built_for is wf and "cancel" in controls.handles, 15.0, "the controls")
    return wf, controls


def test_the_panel_setting_the_object_chooser_selects_nothing_and_the_page_s_choice_selects(served_page):
    served, page, panel = served_page
    with panel.app.clients_lock:  # no redraw meanwhile: it would set the chooser to the selection
        panel.session.select("table")  # a click selected the table ...
        panel.gui_object.value = "parallelepiped"  # ... after a redraw had read the selection before it
    served.settle(page, panel)
    assert panel.session.selected == "table"
    page.send(dict(type="GuiUpdateMessage", uuid=panel.gui_object._impl.uuid, updates={"value": "parallelepiped"}))
    served.settle(page, panel)
    assert panel.session.selected == "parallelepiped"  # the operator's choice on the page


def test_a_click_that_arrived_before_a_question_leaves_it_and_one_after_it_drops_it(served_page):
    served, page, panel = served_page
    wf, _ = _update_pose_controls(panel)  # (the first redraw of a new workflow's controls drops any question)
    arrived = time.monotonic()  # a click reached the server; its handling (snapping, on a loaded machine) ...
    panel.on_pixel_click(np.array([200.0, 150.0]), arrived - 2.0)  # (the edge's first point, handled at once)
    # its snapping done (Cancel during a running action stops that action alone, and asks nothing)
    wait_until(lambda: wf.progress is None and not panel.busy, 15.0, "the first point taken")
    panel.press("cancel")  # ... waits behind an Esc pressed after it, asked about at once
    assert panel.asking == "cancel"
    panel.on_pixel_click(np.array([260.0, 170.0]), arrived)
    assert panel.asking == "cancel" and len(wf.clicks.segs) == 1  # the click taken, the question kept
    # a click made after the question: on a drawn edge of the parallelepiped (the edge's model edge)
    model_edges = wf.obj.model.edge_segments(wf.T_current)
    uv = panel.app.site.camera.project(model_edges[int(np.argmax(np.ptp(model_edges[:, :, 0], axis=1)))]).mean(axis=0)
    panel.on_pixel_click(uv, time.monotonic())
    assert panel.asking is None


def test_the_question_s_label_is_drawn_from_the_panel_s_state(served_page):
    served, page, panel = served_page
    wf, controls = _update_pose_controls(panel)
    wait_until(lambda: controls.handles["cancel"].visible, 15.0, "Cancel shown")
    cancel = controls.handles["cancel"]
    assert cancel.label == "Cancel (Esc)"
    with panel.app.clients_lock:  # Esc asked while a redraw that had read the state before it ...
        panel.confirm_pending = ("cancel", ())
        cancel.label = "Cancel (Esc)"  # ... set the button's label back
        panel.dirty = True
    panel.app.wake()
    wait_until(lambda: cancel.label == "Cancel: confirm (Esc)", 15.0, "the question's label")
    panel.confirm_pending, panel.dirty = None, True  # the question dropped: the label back
    panel.app.wake()
    wait_until(lambda: cancel.label == "Cancel (Esc)", 15.0, "the label back")


class _Worker:
    """A long action's worker thread, as the panel asks it whether it runs."""

    alive = True

    def is_alive(self) -> bool:
        return self.alive


def test_the_controls_come_back_when_a_long_action_s_worker_ends_after_its_last_redraw(served_page, monkeypatch):
    served, page, panel = served_page
    wf, controls = _update_pose_controls(panel)
    action = sorted(a for a in wf.current_step().enabled if a != "cancel" and a in controls.handles)[0]
    wait_until(lambda: controls.handles[action].visible, 15.0, f"{action} shown")
    worker = panel.worker = _Worker()  # a measurement under way
    drawn = panel.texts.update

    def update(shown_wf, busy) -> None:  # it ends just after a redraw drew it running, with no wake-up after it
        drawn(shown_wf, busy)
        if not controls.handles[action].visible:
            worker.alive = False

    monkeypatch.setattr(panel.texts, "update", update)
    panel.dirty = True
    panel.app.wake()
    wait_until(lambda: not worker.alive, 15.0, "the controls hidden while it ran")
    wait_until(lambda: controls.handles[action].visible, 5.0, "the controls back")


def test_a_fit_is_pending_until_the_page_reports_its_camera_there(served_page):
    """The server holds the camera it sends as if the page had it: a click placed through it while the page still
    showed the view before landed on another camera's image. ``fit_pending`` says the page has not shown it yet."""
    served, page, panel = served_page
    vp = panel.viewport
    wait_until(lambda: vp.fitted_aspect is not None and vp._fitted_at is not None, 15.0, "the first fit")
    # the page's camera far from any fit (the test page's own place could lie within 2 % of one, at some fov)
    away = {"position": [2.56, 1.28, -40.0]}
    served.settle(page, panel, **away)
    with panel.app.clients_lock:  # no redraw meanwhile
        vp.fit()  # sent again, the page last reported its camera elsewhere
        fitted = vp._fitted_at.copy()
        assert vp.fit_pending
    page.send(camera(fov=0.95, **away))  # a report from the view before: still pending
    served.settle(page, panel, **away)
    assert vp.fit_pending
    page.send(camera(position=[float(x) for x in fitted], fov=0.95))  # the page shows the fit
    wait_until(lambda: not vp.fit_pending, 15.0, "the fit no longer pending")


def test_a_page_that_connects_already_at_its_fit_is_not_left_pending(served_page):
    """A page that connects again (the server restarted) already shows the view the fit puts it at: it reports no
    camera after its first, and its fit stayed pending for good (the harness waited 20 s for it, and Fit view
    pressed again never saw the view unmoved)."""
    served, page, panel = served_page
    wait_until(lambda: panel.viewport._fitted_at is not None, 15.0, "the first page's fit")
    at = [float(x) for x in panel.viewport._fitted_at]
    before = set(served.server.clients)
    again = Page(served.port)
    try:
        again.send(camera(position=at))  # its first report: where the fit puts it
        wait_until(lambda: set(served.server.clients) - before, 15.0, "the second page's panel")
        (cid,) = set(served.server.clients) - before
        vp = served.server.clients[cid].viewport
        wait_until(lambda: vp._fitted_at is not None, 15.0, "the second page's fit")
        assert np.allclose(vp._fitted_at, at) and not vp.fit_pending
    finally:
        again.close()


def test_a_press_during_a_long_action_is_refused_and_one_as_its_worker_ends_waits_for_it(served_page):
    served, page, panel = served_page
    wf, controls = _update_pose_controls(panel)
    action = sorted(a for a in wf.current_step().enabled if a != "cancel" and a in controls.handles)[0]
    running = threading.Thread(target=time.sleep, args=(1.0,))  # the action under way
    running.start()
    panel.worker, panel._performing = running, True
    try:
        with pytest.raises(WorkflowError, match="a measurement is running"):
            panel.press(action)
    finally:
        panel._performing = False
        running.join()
    ending = threading.Thread(target=time.sleep, args=(0.1,))  # its action returned: the worker is saying so
    ending.start()
    panel.worker = ending
    try:
        panel.press(action)
    except WorkflowError as exc:  # what the action itself may say (nothing clicked yet), never that one runs
        assert "measurement is running" not in str(exc), exc
    assert not ending.is_alive()


def test_a_workflow_s_buttons_are_made_as_they_are_shown_not_hidden_then_shown(served_page):
    """A button made hidden and shown in the same redraw queued an update that outlived its making when the workflow
    ended before the page took them (viser drops a pending making once its removal follows): the page logged "Tried
    to update non-existent component". Each is made as the step shows it, so the first update has nothing to send."""
    served, page, panel = served_page
    with panel.app.clients_lock:  # no redraw meanwhile
        panel.session.select("parallelepiped")
        wf = panel.session.start("update_pose")
        controls = panel.workflow_controls
        controls.rebuild(wf)
        made = {a: (h.visible, getattr(h, "label", None)) for a, h in controls.handles.items()}
        controls.update(wf, wf.current_step(), panel.busy)
        shown = {a: (h.visible, getattr(h, "label", None)) for a, h in controls.handles.items()}
    assert made == shown and any(visible for visible, _ in made.values())


def test_a_workflow_s_shortcuts_are_made_before_its_buttons(served_page, monkeypatch):
    """The page takes the server's messages in order: with every shortcut of a workflow made before its first button,
    a button the page shows has its key live (a key pressed as the buttons appeared went nowhere when the page had
    taken a button but not yet the shortcut made after it)."""
    served, page, panel = served_page
    gui, made = panel.client.gui, []

    def recorded(name):
        make = getattr(gui, name)
        return lambda *args, **kwargs: made.append(name) or make(*args, **kwargs)

    for name in ("add_command", "add_button", "add_dropdown"):
        monkeypatch.setattr(gui, name, recorded(name))
    with panel.app.clients_lock:  # no redraw meanwhile
        panel.session.select("parallelepiped")
        wf = panel.session.start("update_pose")
        panel.workflow_controls.rebuild(wf)
    keyed = [c for c in wf.controls if c.key is not None and c.kind != "choice"]
    first_button = made.index("add_button")
    assert len(keyed) > 3 and made[:first_button].count("add_command") >= len(keyed), made
