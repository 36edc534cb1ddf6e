"""The panel's state against the order things happen in, on a real mcit interface reached by a page's websocket
(tests/app/ui/test_ws_fuzz.py's ``Served``): the panel's own setting of the Object chooser is not the operator's
choice; a press waits for the clicks that reached the server before it; a question's button label is drawn from
the panel's state by every redraw (a redraw that read the state before the question had set it back)."""

from __future__ import annotations

import threading
import time

from tests.app.ui.test_ws_fuzz import Served
from tests.e2e.harness import wait_until


def _served_page(site, caplog, monkeypatch):
    served = Served(site, caplog, monkeypatch)
    page, panel = served.page()
    wait_until(lambda: "parallelepiped" in panel.gui_object.options, 15.0, "the object list drawn")
    return served, page, panel


def test_the_panel_setting_the_object_chooser_selects_nothing_and_the_page_s_choice_selects(site, caplog, monkeypatch):
    served, page, panel = _served_page(site, caplog, monkeypatch)
    try:
        with panel.app.clients_lock:  # no redraw meanwhile: it would set the chooser to the selection
            panel.session.select("table")  # a click selected the table ...
            panel.gui_object.value = "parallelepiped"  # ... after a redraw had read the selection before it
        served.settle(page, panel)
        assert panel.session.selected == "table"
        page.send(dict(type="GuiUpdateMessage", uuid=panel.gui_object._impl.uuid, updates={"value": "parallelepiped"}))
        served.settle(page, panel)
        assert panel.session.selected == "parallelepiped"  # the operator's choice on the page
    finally:
        page.close()
        served.stop()


def test_a_press_is_handled_after_the_clicks_that_reached_the_server_before_it(site, caplog, monkeypatch):
    served, page, panel = _served_page(site, caplog, monkeypatch)
    try:
        order: list[str] = []
        monkeypatch.setattr(panel, "press", lambda action: order.append(action))
        started = threading.Event()

        def click_handled() -> None:  # a click whose handling (snapping, on a loaded machine) takes a while
            started.set()
            time.sleep(0.5)
            order.append("click")

        panel.click_worker.submit(click_handled)
        started.wait(5)
        panel.press_event("cancel")  # Esc, on viser's threads
        assert order == ["click", "cancel"]
    finally:
        page.close()
        served.stop()


def test_the_question_s_label_is_drawn_from_the_panel_s_state(site, caplog, monkeypatch):
    served, page, panel = _served_page(site, caplog, monkeypatch)
    try:
        panel.session.select("parallelepiped")
        wf = panel.session.start("update_pose")
        controls = panel.workflow_controls
        wait_until(lambda: controls.built_for is wf and controls.handles["cancel"].visible, 15.0, "the controls")
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
    finally:
        page.close()
        served.stop()


class _Worker:
    """A long action's worker thread, as the panel asks it whether it runs."""

    alive = True

    def is_alive(self) -> bool:
        return self.alive


def test_the_controls_come_back_when_a_long_action_s_worker_ends_after_its_last_redraw(site, caplog, monkeypatch):
    served, page, panel = _served_page(site, caplog, monkeypatch)
    try:
        panel.session.select("parallelepiped")
        wf = panel.session.start("update_pose")
        controls = panel.workflow_controls
        wait_until(lambda: controls.built_for is wf, 15.0, "the controls")
        action = sorted(a for a in wf.current_step().enabled if a != "cancel" and a in controls.handles)[0]
        wait_until(lambda: controls.handles[action].visible, 15.0, f"{action} shown")
        worker = panel.worker = _Worker()  # a measurement under way
        drawn = panel.texts.update

        def update(shown_wf) -> None:  # it ends just after a redraw drew it running, with no wake-up after it
            drawn(shown_wf)
            if not controls.handles[action].visible:
                worker.alive = False

        monkeypatch.setattr(panel.texts, "update", update)
        panel.dirty = True
        panel.app.wake()
        wait_until(lambda: not worker.alive, 15.0, "the controls hidden while it ran")
        wait_until(lambda: controls.handles[action].visible, 5.0, "the controls back")
    finally:
        page.close()
        served.stop()
