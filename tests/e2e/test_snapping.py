"""Snapping in a real browser: an edge clicked on the canvas is snapped to the video's edge, the
raw click is drawn beside it, and Refuse snap brings the raw click back."""

from __future__ import annotations

import re

import numpy as np
import pytest

from .harness import click_control, select_by_click
from .harness import wait_until as _wait

pytestmark = pytest.mark.e2e


def test_a_clicked_edge_is_snapped_shown_and_can_be_refused(browser, interface, scene):
    ui = interface
    page = ui.open(browser)
    site = ui.site
    obj = site.object("parallelepiped")
    cam = site.camera
    T_true = scene.body("parallelepiped").pose_at(ui.frame_t_s)
    drawn = cam.project(obj.model.edge_segments(obj.T_world_obj).reshape(-1, 3)).reshape(-1, 2, 2)
    wfv = obj.model.wireframe(cam.center, obj.T_world_obj)
    k_sel = next(int(k) for k, v, kind in zip(wfv.edge_index, wfv.visible, wfv.kind) if v and kind == "edge")
    select_by_click(page, "parallelepiped", lambda: ui.click_pixel(page, drawn[k_sel].mean(axis=0)))
    click_control(page.get_by_role("button", name="Update pose"))
    _wait(lambda: page.panel.session.workflow is not None, what="the workflow")
    wf = page.panel.session.workflow
    # the longest visible edge of the box where the video shows it, clicked 1.5 px off on average
    true = cam.project(obj.model.edge_segments(T_true).reshape(-1, 3)).reshape(-1, 2, 2)
    wft = obj.model.wireframe(cam.center, T_true)
    vis = [int(k) for k, v, kind in zip(wft.edge_index, wft.visible, wft.kind) if v and kind == "edge"]
    k = max(vis, key=lambda i: np.linalg.norm(true[i, 1] - true[i, 0]))
    a, b = true[k]
    n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
    raw = [a + 0.3 * (b - a) + 1.5 * n, a + 0.7 * (b - a) - 1.2 * n]
    for p in raw:
        ui.click_pixel(page, p)
    _wait(lambda: len(wf.segs) == 1, what="the clicked segment")
    snap = wf.seg_snaps[0]
    assert snap.applied and np.max(np.abs((wf.segs[0] - a) @ n)) <= 0.3  # on the video's edge
    assert np.max(np.abs((snap.raw - a) @ n)) > 1.0  # the clicks were not
    page.get_by_text(re.compile(r"Edge 1 snapped \d\.\d px")).first.wait_for(
        timeout=60_000
    )  # how far it moved, in the panel
    assert len(wf.marks().raw_segments) == 1  # and the raw click drawn beside the snapped one
    click_control(page.get_by_role("button", name="Refuse snap"))
    _wait(lambda: not wf.seg_snaps[0].applied, what="the refusal")
    assert np.array_equal(wf.segs[0], snap.raw) and len(wf.marks().raw_segments) == 0
    page.get_by_text("Snap refused", exact=False).first.wait_for(timeout=60_000)
