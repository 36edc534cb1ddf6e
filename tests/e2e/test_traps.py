"""The operator's traps (issue 27, item 5), each met again in a real browser by visible controls, keys and
canvas clicks alone: what the page says now where it misled a new operator before.

* Designate on a frame frozen long before: the target says the frame's age and that the scene may have
  changed since, not "range finder agrees" alone.
* Seconds back counts from the frame on screen, and says when it reaches past the frames kept.
* Calibrate turret: a click on the table 24 video px from a box corner is a point on the table, not the corner.
"""

from __future__ import annotations

import numpy as np
import pytest

from .harness import press, wait_until

pytestmark = pytest.mark.e2e

OLD_FRAME_S = 11.0  # older than the age past which a frozen frame is said to be old (10 s)


def _workflow(page, name: str):
    wait_until(
        lambda: (
            page.panel.session.workflow is not None
            and page.panel.session.workflow.name == name
            and page.panel.workflow_controls.built_for is page.panel.session.workflow
        ),
        what=f"the {name} workflow's controls",
        panel=page.panel,
    )
    return page.panel.session.workflow


def _table_point(site, fx: float = 0.25, fy: float = -0.3) -> np.ndarray:
    """A point of the table's top where nothing stands (in the database and in the truth)."""
    table = site.object("table")
    T = table.T_world_obj
    return T[:3, :3] @ np.array([fx, fy, float(table.model.vertices[:, 2].max())]) + T[:3, 3]


def _newest_after(panel, stamp: float) -> float:
    """How long after ``stamp`` (unix s) the newest frame of the page's video was taken."""
    newest = panel.feed.grabber.latest()
    return -1.0 if newest is None or newest.stamp is None else float(newest.stamp) - float(stamp)


def test_designate_on_an_old_frozen_frame_says_its_age(browser, device_interface):
    ui = device_interface
    site = ui.site
    page = ui.open(browser)
    panel = page.panel
    press(page, "Designate target")
    wf = _workflow(page, "designate")
    wait_until(lambda: wf.frame is not None and wf.frame.stamp is not None, what="the frozen frame")
    # the live video runs on while the operator looks at the frozen frame
    wait_until(
        lambda: _newest_after(panel, wf.frame.stamp) > OLD_FRAME_S,
        timeout_s=OLD_FRAME_S + 60,
        what=f"the live video {OLD_FRAME_S:.0f} s past the frozen frame",
    )
    ui.click_pixel(page, site.camera.project(_table_point(site)[None])[0])
    wait_until(lambda: len(wf.targets) == 1 and wf.progress is None, timeout_s=60, what="the target", panel=panel)
    t = wf.targets[0]
    assert t.object == "table" and t.rangefinder_X is not None
    page.get_by_text("the scene may have changed since", exact=False).first.wait_for(timeout=60_000)
    said = page.get_by_text("the scene may have changed since", exact=False).first.inner_text()
    age = float(said.split("this frame is ")[1].split(" s old")[0])
    assert OLD_FRAME_S <= age < OLD_FRAME_S + 120
    assert not wf.message.startswith("The range finder agrees")  # no agreement with what the frame shows
    page.close()


def _seconds_back(page, value: str) -> None:
    """Type ``value`` in the Seconds back box and press Enter."""
    box = page.get_by_text("Seconds back", exact=True).first.locator("xpath=ancestor::div[2]").locator("input").last
    box.click()
    box.fill(value)
    page.keyboard.press("Enter")


def test_seconds_back_counts_from_the_frame_on_screen_and_says_when_clamped(browser, interface):
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    page.keyboard.press("f")  # Freeze the newest frame
    wait_until(lambda: panel.frozen is not None, what="the frozen frame", panel=panel)
    on_screen = panel.frozen
    # the live video runs on, 3 s past the frame on screen
    wait_until(lambda: _newest_after(panel, on_screen.stamp) > 3.0, timeout_s=60, what="the live video 3 s on")
    _seconds_back(page, "1")
    wait_until(lambda: panel.frozen is not on_screen, what="the frame 1 s back frozen", panel=panel)
    back = on_screen.stamp - panel.frozen.stamp
    assert 0.7 <= back <= 1.3, f"the frame frozen is {back:.1f} s before the one on screen, not 1 s"
    page.get_by_text("a frame that long before the frame on screen", exact=False).first.wait_for(timeout=60_000)
    # 12 s before it: the kept frames (12 s before the newest) do not reach so far, and the page says so
    one_back = panel.frozen
    _seconds_back(page, "12")
    wait_until(lambda: panel.frozen is not one_back, what="the oldest kept frame frozen", panel=panel)
    page.get_by_text("reaches past the frames kept", exact=False).first.wait_for(timeout=60_000)
    assert on_screen.stamp - panel.frozen.stamp < 12.0 - 0.5
    page.close()


def test_calibrate_turret_a_click_on_the_table_near_a_box_corner_is_the_table(browser, device_interface):
    ui = device_interface
    site = ui.site
    cam = site.camera
    page = ui.open(browser)
    panel = page.panel
    scale = panel.viewport.image_px_per_screen_px()
    off_px = 24.0  # video pixels from the box's corner, as the operator's click
    assert off_px / scale > 20.0  # more than 20 screen pixels: not on the corner as the operator sees it
    known = []  # every corner and face centre the workflow may pick, projected
    for obj in site.objects():
        known += list(obj.vertices_world())
        if obj.model.faces:
            T = obj.T_world_obj
            known += list(obj.model.face_centroids() @ T[:3, :3].T + T[:3, 3])
    known_uv = cam.project(np.array(known))
    target = None
    for X in site.object("parallelepiped").vertices_world():
        c = cam.project(X[None])[0]
        for ang in np.linspace(0, 2 * np.pi, 24, endpoint=False):
            p = c + off_px * np.array([np.cos(ang), np.sin(ang)])
            origin, ray = cam.rays(p.reshape(1, 2))
            hit = site.raycast(origin, ray[0])
            nearest = np.linalg.norm(known_uv - p, axis=1).min()
            if hit is not None and hit.name == "table" and nearest > off_px - 0.5:  # the box's corner is the nearest
                target = p
                break
        if target is not None:
            break
    assert target is not None
    press(page, "Calibrate turret")
    wf = _workflow(page, "calibrate_turret")
    ui.click_pixel(page, target)
    wait_until(lambda: wf.pending_label, what="the picked point", panel=panel)
    assert wf.pending_label == "a point on table", wf.pending_label
    page.get_by_text("Target: a point on table", exact=False).first.wait_for(timeout=60_000)
    page.close()
