"""The view in a real browser: the wheel zooms about the cursor, a workflow freezes its frame (shown,
with its time), Show live looks at the live video and refuses clicks meanwhile, marks keep their
screen size when zoomed."""

from __future__ import annotations

import time

import numpy as np
import pytest

from .harness import click_control, key_until, press, select_by_click, wait_for_steady_camera, wait_until

pytestmark = pytest.mark.e2e


def test_wheel_zooms_about_the_cursor(browser, interface):
    ui = interface
    page = ui.open(browser)
    cam = page.panel.client.camera
    box = page.locator("canvas").nth(1).bounding_box()
    for uv in (np.array([150.0, 100.0]), np.array([420.0, 60.0])):
        # the camera the page shows, at rest: after Fit view a camera on its way back put the cursor on another point
        wait_for_steady_camera(page.panel)
        x0, y0 = ui.screen_of(page, uv)
        d0 = abs(float(cam.position[2]))
        page.mouse.move(box["x"] + x0, box["y"] + y0)
        for _ in range(4):
            page.mouse.wheel(0, -100)
            time.sleep(0.15)
        wait_until(lambda: abs(float(cam.position[2])) < 0.7 * d0, what="the wheel zoom")
        wait_for_steady_camera(page.panel)  # every notch taken, the page showing the last
        x1, y1 = ui.screen_of(page, uv)
        assert np.hypot(x1 - x0, y1 - y0) < 3.0, f"the point under the cursor moved from {(x0, y0)} to {(x1, y1)}"
        click_control(page.get_by_role("button", name="Fit view"))
        wait_until(lambda: abs(abs(float(cam.position[2])) - d0) < 0.02 * d0, what="the fit")


def test_a_workflow_freezes_its_frame_and_live_view_refuses_clicks(browser, interface):
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    # with no workflow under way, Freeze (F) freezes a frame to look at; it stays (it was undone at once)
    key_until(
        page, "f", lambda: panel.frozen is not None and panel.frozen_frames.by is None, "a frame frozen to look at"
    )
    page.get_by_text("Frozen frame: t =").first.wait_for(timeout=60_000)
    time.sleep(0.5)
    assert panel.frozen is not None
    looked_at = panel.frozen
    click_control(page.get_by_role("button", name="Calibrate camera"))
    wait_until(
        lambda: panel.session.workflow is not None and panel.frozen_frames.by is panel.session.workflow,
        what="the workflow's own frozen frame",
    )
    wf = panel.session.workflow
    assert wf.frame is panel.frozen  # clicks, snapping and solving use it ...
    assert panel.frozen is looked_at  # ... the frame frozen before the start (a new operator lost it to the newest)
    page.get_by_text("Frozen frame: t =").first.wait_for(timeout=60_000)
    page.keyboard.press("l")  # Show live
    wait_until(lambda: panel.frozen_frames.show_live, what="the live view")
    page.get_by_text("live shown").first.wait_for(timeout=60_000)
    table = ui.site.object("table")
    corner = ui.site.camera.project(table.vertices_world()[np.argmax(table.vertices_world()[:, 2])])
    ui.click_pixel(page, corner)
    page.get_by_text("you are looking at the live video", exact=False).first.wait_for(timeout=60_000)
    assert wf.pending_X is None  # the click was refused
    press(page, "Show frozen")  # back to the frozen frame (the button says so while live is shown)
    wait_until(lambda: not panel.frozen_frames.show_live, what="the frozen view")
    ui.click_pixel(page, corner)
    wait_until(lambda: wf.pending_X is not None, what="the corner picked on the frozen frame")
    page.keyboard.press("f")  # another frame cannot be frozen once clicked
    page.get_by_text("every click of a workflow uses one frame", exact=False).first.wait_for(timeout=60_000)


def test_a_frame_frozen_to_look_at_goes_back_to_live_by_l(browser, interface):
    """With no workflow, a frame frozen to look at (F) is let go by L, "Back to live" (a new operator found no way
    back to the live video but starting and cancelling a workflow)."""
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    key_until(page, "f", lambda: panel.frozen is not None and panel.frozen_frames.by is None, "a frame frozen")
    page.get_by_role("button", name="Back to live (L)").wait_for(timeout=60_000)
    key_until(page, "l", lambda: panel.frozen is None, "back to the live video")
    page.get_by_text("Live video (no frame frozen)").first.wait_for(timeout=60_000)


def test_marks_keep_their_screen_size_when_zoomed(browser, interface):
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    cam = panel.client.camera
    # the marks' scale follows the fitted view at the next redraw (late on a loaded machine)
    wait_until(lambda: abs(panel.viewport.marks_scale - 1.0) < 0.05, what="the marks at their size in the fitted view")
    box = page.locator("canvas").nth(1).bounding_box()
    x, y = ui.screen_of(page, [256.0, 128.0])
    page.mouse.move(box["x"] + x, box["y"] + y)
    d0 = abs(float(cam.position[2]))
    for _ in range(8):
        page.mouse.wheel(0, -200)
        time.sleep(0.1)
    wait_until(lambda: abs(float(cam.position[2])) < 0.3 * d0, what="the zoom")
    wait_until(lambda: panel.viewport.marks_scale < 0.35, what="the marks redrawn smaller in image pixels")


def test_double_and_rapid_clicks_are_taken_in_order_or_refused_with_the_state_intact(browser, interface):
    """Bad input from the mouse: once an edge is under way a double click on one point is refused (two
    ends of an edge cannot coincide) and said (before it, a double click is Find's); a quick burst of
    clicks is taken in order, one segment per two clicks."""
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    obj = ui.site.object("parallelepiped")
    cam = ui.site.camera
    drawn = cam.project(obj.model.edge_segments(obj.T_world_obj).reshape(-1, 3)).reshape(-1, 2, 2)
    select_by_click(page, "parallelepiped", lambda: ui.click_pixel(page, drawn[1].mean(axis=0)))
    click_control(page.get_by_role("button", name="Update pose"))
    wait_until(
        lambda: panel.session.workflow is not None and panel.workflow_controls.handles, what="the workflow", panel=panel
    )
    wf = panel.session.workflow
    press(page, "Auto match")  # Auto match first: clicked edges wait for the match
    wait_until(lambda: wf.auto, what="automatic assignment")
    # one edge first (before it, a double click is Find's: it finds the pose from that point)
    for p in ([60.0, 200.0], [140.0, 220.0]):
        ui.click_pixel(page, p)
        time.sleep(0.8)  # not a double click
    wait_until(lambda: len(wf.segs) == 1, what="the first edge")
    ui.double_click_pixel(page, [200.0, 120.0])
    page.get_by_text("px apart", exact=False).first.wait_for(timeout=60_000)
    assert wf.pending is not None and len(wf.segs) == 1  # the first click waits; the second was refused
    press(page, "Remove last")
    wait_until(lambda: wf.pending is None, what="the pending click removed")
    pts = [[100.0 + 20 * i, 60.0 + 7 * i] for i in range(8)]
    for p in pts:  # a burst: each click made as soon as the last reached the server, none waiting for an answer
        ui.click_pixel(page, p)
    wait_until(lambda: len(wf.segs) == 5, what="four segments from eight quick clicks", panel=panel)
    # in the order clicked: each segment's raw clicks (before any snap) are the burst's pairs
    raw = [sn.raw if sn is not None else seg for sn, seg in zip(wf.seg_snaps[1:], wf.segs[1:])]
    assert np.allclose(np.array(raw), np.array(pts).reshape(4, 2, 2), atol=0.6)
    assert all(c.client != panel.session.client for c in ui.db.history())  # nothing written


def test_a_number_typed_in_a_box_gives_the_keys_back_on_enter_or_a_click_on_the_video(browser, interface):
    """Seconds back typed and entered, then F: Freeze acts (the F went into the box before, and a
    Backspace meant for Remove last too: a new operator's run). A click on the video gives the keys back too."""
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    box = page.get_by_text("Seconds back", exact=True).first.locator("xpath=ancestor::div[2]").locator("input").last
    click_control(box)
    box.fill("1")
    page.keyboard.press("Enter")
    wait_until(lambda: panel.frozen is not None and panel.gui_scrub.value == 1.0, what="the frame 1 s back frozen")
    first = panel.frozen
    page.keyboard.press("f")  # Freeze: the newest frame, not an "f" in the box
    wait_until(lambda: panel.frozen is not first, what="Freeze by its key after Enter in the box")
    assert box.input_value() in ("0", "1")
    click_control(box)
    box.fill("2")
    time.sleep(1.0)  # the value taken (or not) before the click
    second = panel.frozen
    ui.click_pixel(page, [20.0, 20.0])  # a click on the video (nothing selected there): the box lets go
    page.keyboard.press("f")
    wait_until(lambda: panel.frozen is not second, what="Freeze by its key after a click on the video")
