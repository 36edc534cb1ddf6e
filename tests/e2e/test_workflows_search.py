"""Update pose from one click, in a real browser by visible controls and canvas clicks alone (issue 17):
select the moved box, Update pose, a double click on the box where the frame shows it, Accept; the
database pose checked against the scene's truth at FRAME_T_S. Then a click on the table: Find says no
pose fits, nothing is written. Prints the operator actions and seconds (run with -s).

Measured (2 cores, 1200×700; a canvas click, a double click or a button is one action): 4 actions —
select, Update pose, double click, Accept — in 1.1 s at load 1 (with a click and Find instead of the
double click: 5 actions, 2.9-6.2 s at load 8-16); written 0.05° / 0.5 mm from the truth. The whole
test (with the refused click on the table) runs in about 30 s.
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from core.transforms import pose_error

from .flows import Operator, projected_edges, visible_edges
from .harness import select_by_click, wait_for_steady_camera, wait_until
from .test_workflows_pose import _start_update_pose

pytestmark = pytest.mark.e2e

BOX = "parallelepiped"


def _with_cylinder(ui, browser, scene, off_m: float):
    """The scene's cylinder in the database as "cylinder_1", off_m along x from where the frame shows it,
    and a page open: (its true pose, the page, its Operator, its longest drawn segment (2, 2))."""
    from app.overlay import project_wireframe
    from core.transforms import make_T

    body = scene.body("unknown_cylinder")
    T_true = body.pose_at(ui.frame_t_s)
    ui.db.add_object(
        "cylinder_1",
        "cylinder",
        body.model,
        make_T(T_true[:3, :3], T_true[:3, 3] + [off_m, 0.0, 0.0]),
        status="modelled",
    )
    page = ui.open(browser)
    op = Operator(ui, page)
    wait_until(lambda: "cylinder_1" in {o.name for o in ui.site.objects()}, what="the cylinder in the database")
    obj = ui.site.object("cylinder_1")
    pw = project_wireframe(ui.site.camera, obj.model, obj.T_world_obj)
    return T_true, page, op, pw.seg_uv[int(np.argmax(np.linalg.norm(pw.seg_uv[:, 1] - pw.seg_uv[:, 0], axis=1)))]


def _missed(op) -> int:
    """Clicks of the selection that a loaded machine's fresh page did not take (clicked again): the
    clicks before the first button, less the one that selects."""
    first = next((i for i, a in enumerate(op.log) if a != "click"), len(op.log))
    return max(0, first - 1)


def test_update_pose_from_one_click(browser, interface, scene):
    ui = interface
    page = ui.open(browser)
    op = Operator(ui, page)
    site, cam = ui.site, ui.site.camera
    obj = site.object(BOX)
    T_true = scene.body(BOX).pose_at(ui.frame_t_s)
    assert pose_error(T_true, obj.T_world_obj)[0] > 50.0  # the 55° move: the database is stale
    n_changes = len(ui.db.history(BOX))

    wf = _start_update_pose(op, page, obj, cam)
    on_box = cam.project_obj(T_true, obj.model.vertices).mean(axis=0)  # where the frame shows the box
    assert "Double-click" in wf.prompt_text()
    op.double_click(on_box)  # on the box where the frame shows it: Find from that point, at once
    wait_until(lambda: wf.found is not None, timeout_s=60, what="the found poses")
    assert "Accept" in op.check()
    assert len(ui.db.history(BOX)) == n_changes  # nothing written yet
    deg, m = pose_error(wf.candidates[wf.chosen or 0], T_true)
    print(f"found {len(wf.found)} pose(s); the shown one {deg:.3f}° / {1000 * m:.2f} mm from the truth")
    op.accept(wf)
    page.get_by_text(re.compile(r"\(accepted at \d\d:\d\d:\d\d\)")).first.wait_for(timeout=60_000)  # says when
    rec = ui.db.get(BOX)
    assert rec.version == obj.version + 1
    entry = ui.db.history(BOX)[-1]
    assert entry.method == "search" and entry.client.startswith("browser-")
    assert np.allclose(entry.clicks["click_uv"], on_box, atol=1.0)
    deg, m = pose_error(rec.T_world_obj, T_true)
    print(f"written: {deg:.3f}° / {1000 * m:.2f} mm from the truth")
    assert deg < 1.0 and m < 0.005
    text = op.report("update pose from one click")
    assert op.actions - _missed(op) <= 4, text  # select, Update pose, double click, Accept

    # A click on the table: no pose fits, said in the panel; nothing written.
    n_changes = len(ui.db.history(BOX))
    op.press("Update pose")
    wait_until(
        lambda: page.panel.session.workflow is not wf and page.panel.session.workflow is not None, what="a new workflow"
    )
    wf2 = page.panel.session.workflow
    op.click(cam.project(np.array([[0.3, -0.3, 0.0]]))[0])
    wait_until(lambda: wf2.current_step().name == "click_edge_end", what="the click on the table")
    op.press("Find")
    wait_until(
        lambda: "no pose of the parallelepiped fits the image near your click" in page.panel.error.lower(),
        timeout_s=60,
        what="the refusal",
    )
    assert len(ui.db.history(BOX)) == n_changes and wf2.found is None
    op.press("Cancel")


def test_update_pose_from_one_click_and_one_edge(browser, interface, scene):
    """The ambiguity path: after the double click, one edge of the box clicked (two points and the
    model edge on the white ghost), Refine — the edge fits together with the found pose (one edge is
    enough) — and Accept: method search+refine, the pose within 1° / 5 mm of the truth. 8 actions."""
    ui = interface
    page = ui.open(browser, viewport={"width": 1280, "height": 720})
    op = Operator(ui, page)
    site, cam = ui.site, ui.site.camera
    obj = site.object(BOX)
    T_true = scene.body(BOX).pose_at(ui.frame_t_s)

    wf = _start_update_pose(op, page, obj, cam)
    op.double_click(cam.project_obj(T_true, obj.model.vertices).mean(axis=0))
    wait_until(lambda: wf.found is not None, timeout_s=60, what="the found poses")
    T_found = wf.candidates[wf.chosen or 0]
    true = projected_edges(cam, obj.model, T_true)
    k = max(visible_edges(cam, obj.model, T_true), key=lambda i: np.linalg.norm(true[i, 1] - true[i, 0]))
    a, b = true[k]
    op.click(a + 0.3 * (b - a))
    op.click(a + 0.7 * (b - a))
    wait_until(lambda: wf.current_step().name == "assign_edge", what="the edge's two points")
    op.click(projected_edges(cam, obj.model, T_found)[k].mean(axis=0))  # which model edge: on the white ghost
    wait_until(lambda: wf.edge_ids == [k], what="the assignment")
    assert "Refine" in op.check()
    op.press("Refine")
    wait_until(lambda: wf.refined is not None, timeout_s=60, what="the refined pose")
    op.accept(wf)
    entry = ui.db.history(BOX)[-1]
    assert entry.method == "search+refine" and entry.clicks["edge_ids"] == [k]
    deg, m = pose_error(ui.db.get(BOX).T_world_obj, T_true)
    print(f"written: {deg:.3f}° / {1000 * m:.2f} mm from the truth")
    assert deg < 1.0 and m < 0.005
    text = op.report("update pose from one click and one edge")
    assert op.actions - _missed(op) <= 8, (
        text
    )  # select, Update pose, double click, 2 clicks, the model edge, Refine, Accept


def test_update_a_cylinder_from_one_double_click(browser, interface, scene):
    """An object with no straight edges (a cylinder modelled earlier, its database pose 8 cm off): select
    it on its outline, Update pose, a double click where the video shows it, Accept — 4 actions; the
    written axis within 1° and 5 mm of the truth. (Before, Update pose refused it.)"""
    ui = interface
    T_true, page, op, longest = _with_cylinder(ui, browser, scene, 0.08)
    cam = ui.site.camera
    select_by_click(page, "cylinder_1", lambda: op.click(longest.mean(axis=0)))
    op.press("Update pose")
    wait_until(lambda: page.panel.session.workflow is not None, what="the workflow")
    wf = page.panel.session.workflow
    assert "no straight edges to click" in wf.prompt_text()
    op.double_click(cam.project_obj(T_true, np.array([[0.0, 0.0, 0.09]]))[0])
    wait_until(lambda: wf.found is not None, timeout_s=60, what="the found poses")
    op.accept(wf)
    rec = ui.db.get("cylinder_1")
    axis_deg = np.degrees(np.arccos(np.clip(rec.T_world_obj[:3, 2] @ T_true[:3, 2], -1, 1)))
    moved_mm = 1000 * np.linalg.norm(rec.T_world_obj[:3, 3] - T_true[:3, 3])
    print(f"written: axis {axis_deg:.3f}°, origin {moved_mm:.2f} mm from the truth")
    assert axis_deg < 1.0 and moved_mm < 5.0
    assert ui.db.history("cylinder_1")[-1].method == "search"
    text = op.report("update a cylinder from one double click")
    assert op.actions - _missed(op) <= 4, text  # select, Update pose, double click, Accept


def test_update_pose_by_a_double_click_on_the_selected_object(browser, interface, scene):
    """The shortest path: select the box (click its wireframe), double-click it where the frame shows it
    (Update pose starts and Find runs from that point), Accept — 3 actions; the pose within 1° and 5 mm
    of the truth. (A new operator double-clicked straight after selecting, as the Help's order suggests,
    and lost the selection.)"""
    from .test_workflows_pose import _select

    ui = interface
    page = ui.open(browser, viewport={"width": 1280, "height": 720})
    op = Operator(ui, page)
    cam = ui.site.camera
    obj = ui.site.object(BOX)
    T_true = scene.body(BOX).pose_at(ui.frame_t_s)
    missed = _select(op, page, obj, cam) - 1  # a first click the loaded page did not take, clicked again
    # on the box where the frame shows it, at a pixel where the table's wireframe runs: the double click's
    # first click alone would select the table (a new operator lost the box so), the double click is the box's
    from scipy.spatial import Delaunay

    hull = Delaunay(cam.project_obj(T_true, obj.model.vertices))
    grid = np.stack(np.meshgrid(np.arange(0, cam.width, 2.0), np.arange(0, cam.height, 2.0)), axis=-1).reshape(-1, 2)
    inside = grid[hull.find_simplex(grid) >= 0]
    on_table = [uv for uv in inside if page.panel._object_at(uv) == "table"]
    assert on_table, "no pixel of the moved box lies by the table's wireframe in this frame"
    page.keyboard.press("f")  # a frame frozen to look at first: the double click is made on it, and uses it
    wait_until(lambda: page.panel.frozen is not None, what="the frame frozen")
    looked_at = page.panel.frozen
    op.double_click(on_table[len(on_table) // 2])
    wait_until(
        lambda: page.panel.session.workflow is not None and page.panel.session.workflow.found is not None,
        timeout_s=60,
        what="Update pose started and the found poses",
        panel=page.panel,
    )
    wf = page.panel.session.workflow
    assert wf.name == "update_pose" and wf.object_name == BOX
    assert wf.frame is looked_at  # not the newest frame (a new operator's frozen frame was replaced)
    op.accept(wf)
    entry = ui.db.history(BOX)[-1]
    assert entry.method == "search"
    deg, m = pose_error(ui.db.get(BOX).T_world_obj, T_true)
    print(f"written: {deg:.3f}° / {1000 * m:.2f} mm from the truth")
    assert deg < 1.0 and m < 0.005
    text = op.report("update pose by a double click on the selected object")
    assert op.actions - missed <= 3, text  # select, double click, Accept


def _box_selected(ui, browser, scene):
    """A page at 1280×720 with the box selected by a click on its wireframe: (page, its Operator, its
    panel, the box's SiteObject, its true pose in the frame)."""
    from .test_workflows_pose import _select

    page = ui.open(browser, viewport={"width": 1280, "height": 720})
    op = Operator(ui, page)
    obj = ui.site.object(BOX)
    _select(op, page, obj, ui.site.camera)
    return page, op, page.panel, obj, scene.body(BOX).pose_at(ui.frame_t_s)


def test_a_double_click_is_told_by_the_page_when_the_server_is_late(browser, interface, scene):
    """A double click's two clicks reached a loaded server 0.3–2.7 s apart, were read as two clicks, and
    Update pose did not start (a CI run failed so). The page tells a double click, timed by the browser:
    here the server's event loop is held 1.5 s once the double click's first click arrives, so that its
    second reaches the server 1.5 s late, and the double click still finds the box's pose."""
    ui = interface
    page, op, panel, obj, T_true = _box_selected(ui, browser, scene)
    cam = ui.site.camera
    submit, held = panel.click_worker.submit, []

    def take_then_hold(fn, *args):  # called in the server's event loop as each click arrives
        held.append(args[-1])  # its arrival
        if len(held) == 1:  # the double click's first click: the server is busy a while after it
            time.sleep(1.5)
        return submit(fn, *args)

    panel.click_worker.submit = take_then_hold
    # on the box's middle where the frame shows it (its frame's origin, at the bottom face's centre, lies by the
    # bottom edge: from there the search found no pose in 3 runs of the whole suite, two of them loaded; what this
    # test checks is the double click's timing, the search's reach is bench/search.py's)
    target = cam.project_obj(T_true, obj.model.vertices).mean(axis=0)
    op.double_click(target)
    try:
        wait_until(
            lambda: panel.session.workflow is not None and panel.session.workflow.found is not None,
            timeout_s=60,
            what="Update pose started and the found poses",
            panel=page.panel,
        )
    except AssertionError as exc:  # where the server took the double click (two loaded CI runs found no pose there)
        wf = panel.session.workflow
        at = None if wf is None else getattr(wf, "search_click", None)
        raise AssertionError(f"{exc}; double-clicked at {np.round(target, 1)}, searched from {at}") from None
    assert len(held) == 2 and held[1] - held[0] >= 1.4  # the second click did reach the server late
    wf = panel.session.workflow
    assert wf.name == "update_pose" and wf.object_name == BOX
    # found, a double click again at another point of the box: the search runs again from it (a new
    # operator's was split into two edge points, and Accept went)
    first, other = wf.found, cam.project_obj(T_true, obj.model.vertices).mean(axis=0) + [3.0, -2.0]
    op.double_click(other)
    wait_until(
        lambda: wf.found is not None and wf.found is not first, timeout_s=60, what="the poses found again", panel=panel
    )
    assert np.linalg.norm(wf.search_click - other) < 2.0 and not wf.segs and wf.pending is None
    op.accept(wf)
    deg, m = pose_error(ui.db.get(BOX).T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005


def test_a_click_while_find_searches_is_refused_and_the_found_poses_stay_acceptable(
    browser, interface, scene, monkeypatch
):
    """A click while Find searches (here slowed to 3 s) is refused and said; it had become an edge's point,
    and the found poses could then not be accepted (a new operator double-clicked again during a search)."""
    import app.vision.search as search

    slow = search.search_pose

    def slowed(*args, **kwargs):
        time.sleep(3.0)
        return slow(*args, **kwargs)

    monkeypatch.setattr(search, "search_pose", slowed)
    ui = interface
    page, op, panel, obj, T_true = _box_selected(ui, browser, scene)
    cam = ui.site.camera
    on_box = cam.project_obj(T_true, obj.model.vertices).mean(axis=0)
    op.double_click(on_box)
    wait_until(
        lambda: panel.session.workflow is not None and panel.worker is not None and panel.worker.is_alive(),
        what="Find searching",
    )
    wf = panel.session.workflow
    op.click(on_box + [20.0, 0.0])
    page.get_by_text(
        "Clicks are not taken now. Searching for the pose of parallelepiped from your click… Cancel stops the search",
        exact=False,
    ).first.wait_for(timeout=60_000)
    wait_until(lambda: wf.found is not None, timeout_s=60, what="the found poses")
    assert wf.pending is None and not wf.segs and "accept" in wf.current_step().enabled
    op.accept(wf)
    deg, m = pose_error(ui.db.get(BOX).T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005


def test_a_double_click_says_which_object_and_where(browser, interface, scene):
    """A double click with nothing selected: on an object's wireframe it selects that object and finds its
    pose (a new operator's only selected it, silently); on no wireframe it says to select first. With the
    box selected, a double click on another object's wireframe is refused for the box and names that other
    object (the same refusal three times had left a new operator unsure a click was taken)."""
    ui = interface
    _, page, op, longest = _with_cylinder(ui, browser, scene, 0.003)
    cam = ui.site.camera
    panel = page.panel
    # nothing selected, on the table away from every wireframe: said, nothing started. Away by 4 times the pick
    # radius: the radius follows the page's zoom, which a loaded page may still be settling (a click picked the
    # table's edge in a full run)
    empty = next(
        uv
        for uv in (
            cam.project(np.array([[x, y, 0.0]]))[0]
            for x in np.linspace(-0.3, 0.3, 13)
            for y in np.linspace(-0.5, 0.2, 15)
        )
        if ui.server.object_at(uv, 4 * panel.select_radius_px(), panel.camera_view) is None
    )
    for _ in range(4):  # a loaded machine's page may miss its very first click: one single click taken first
        wait_for_steady_camera(panel)  # (a view still settling put a click on the table's edge: it selected it)
        ui.click_pixel(page, empty)
        try:
            wait_until(lambda: panel.clicks.last is not None, timeout_s=3, what="a first click taken")
        except AssertionError:
            continue
        if panel.session.selected is None:
            break
    time.sleep(1.0)  # not part of the double click below
    op.double_click(empty)
    wait_until(
        lambda: "a double click finds the pose of the selected object" in panel.error.lower(),
        what="the hint",
        panel=panel,
    )
    assert panel.session.workflow is None
    # the box selected, a double click on the cylinder's wireframe: the box's search refused, the cylinder named
    from .test_workflows_pose import _select

    _select(op, page, ui.site.object(BOX), cam)
    outline = longest.mean(axis=0)
    op.double_click(outline)
    wait_until(
        lambda: "is on cylinder_1 as the database draws it: to update cylinder_1" in panel.error,
        timeout_s=60,
        what="the refusal naming the cylinder",
        panel=panel,
    )
    assert panel.session.workflow.object_name == BOX and panel.session.workflow.found is None
    page.get_by_text("Your double click is on cylinder_1 as the database draws it", exact=False).first.wait_for(
        timeout=60_000
    )
    op.key("Escape")  # Cancel (the refused click was dropped: nothing to lose, no question)
    wait_until(lambda: panel.session.workflow.finished, what="the cancel")
    # nothing selected (a click away from every wireframe), then a double click on the cylinder's outline:
    # selected and found in one gesture
    op.click(empty)
    wait_until(lambda: panel.session.selected is None, what="the selection cleared")
    op.double_click(outline)
    wait_until(
        lambda: (
            panel.session.workflow is not None
            and not panel.session.workflow.finished
            and panel.session.workflow.found is not None
        ),
        timeout_s=60,
        what="the cylinder's pose found",
        panel=panel,
    )
    assert panel.session.workflow.object_name == "cylinder_1"
    # Cancel: the found poses would be thrown away, so it asks once more ...
    # pressed once: a second Escape after a slow first would confirm the cancel
    wf = panel.session.workflow
    for attempt in (1, 2):  # a loaded page may drop a key before its shortcuts take it: then pressed once more
        op.key("Escape")
        try:
            wait_until(lambda: panel.asking == "cancel" or wf.finished, 20.0, "the question", panel=panel)
            break
        except AssertionError:
            if attempt == 2:
                raise
    if not wf.finished:  # (a first press taken late with the second: already cancelled)
        assert panel.asking == "cancel"
        op.key("Escape")  # ... and the second press cancels
    wait_until(lambda: wf.finished, what="the cancel")
    # a click inside the box's drawn outline, far from every wireframe, selects it (a new operator clicked
    # a face, and nothing was selected)
    from scipy.spatial import Delaunay

    from app.overlay import nearest_segment

    box = ui.site.object(BOX)
    drawn = ui.server.db_overlay._pick[0]
    grid = np.stack(np.meshgrid(np.arange(0, cam.width, 2.0), np.arange(0, cam.height, 2.0)), axis=-1).reshape(-1, 2)
    inside = grid[Delaunay(cam.project(box.vertices_world())).find_simplex(grid) >= 0]
    face = max(inside, key=lambda uv: nearest_segment(drawn, uv)[1])
    assert nearest_segment(drawn, face)[1] > panel.select_radius_px()  # by no wireframe
    op.click(face)
    wait_until(lambda: panel.session.selected == BOX, what="the box selected by a click inside it")
    # a click on the table's top 10 video pixels (about 20 on the screen) from its drawn edges clears the
    # selection: 15 video pixels had let the table's edges take such clicks (a new operator's run)
    ring = [uv for uv in grid if 9.0 < nearest_segment(drawn, uv)[1] < 11.0 and panel._object_at(uv) is None]
    assert ring and panel.select_radius_px() < 9.0
    op.click(ring[len(ring) // 2])
    wait_until(lambda: panel.session.selected is None, what="the selection cleared")
    # the table selected, a double click on the box as the database draws it: the box's pose is searched,
    # not the table's (a new operator was left in "Update pose: table", its search refused)
    table_edge = next(uv for uv in grid if panel._object_at(uv) == "table" and nearest_segment(drawn, uv)[1] < 1.0)
    op.click(table_edge)
    wait_until(lambda: panel.session.selected == "table", what="the table selected")
    op.double_click(face)
    wait_until(
        lambda: panel.session.workflow is not None and not panel.session.workflow.finished, what="Update pose started"
    )
    assert panel.session.workflow.object_name == BOX
