"""Two cameras in the browser: the operator shows the side camera (its chooser, or N), selects in it,
and calibrates it by clicks as the first one; the first camera's calibration stays as it was."""

from __future__ import annotations

import numpy as np
import pytest

from core.camera import Camera

from .flows import Operator
from .harness import (
    FRAME_T_S,
    Interface,
    assert_prompt_controls,
    canvas_size,
    select_by_click,
    site_frame,
    wait_for_steady_camera,
    wait_until,
    workflow_shown,
)
from .test_workflows_site import _pair_corner, _true_box_in_database, _visible_corners, _wrong_camera

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def side_frame(scene):
    """The side camera's image at FRAME_T_S (RGB uint8)."""
    return site_frame(scene, "side", FRAME_T_S)


@pytest.fixture
def two_cameras(scene, frame, side_frame, tmp_path):
    ui = Interface(scene, {"front": frame, "side": side_frame}, tmp_path / "site.sqlite")
    yield ui
    ui.close()


def _show_side(page):
    panel = page.panel
    # pressed once: N cycles the cameras, a second press after a slow first would show the front one again
    page.keyboard.press("n")
    wait_until(
        lambda: panel.camera_view == "side" and not panel.viewport.need_fit, 60.0, "the side camera shown", panel=panel
    )
    wait_until(lambda: page.get_by_text("Camera (N)").first.is_visible(), what="the Camera chooser")
    # the page's own camera on the side camera's image (its report comes after the fit is sent): a click placed
    # through the camera it reported before lands on the front camera's image
    side = panel.app.views["side"].pixel_world
    wait_until(
        lambda: abs(float(panel.client.camera.look_at[0]) - side.image_center[0]) < 0.05 * side.render_size[0],
        what="the page's view on the side camera's image",
        panel=panel,
    )
    wait_for_steady_camera(panel)


def test_the_side_camera_is_shown_by_its_key_and_clicked_in(browser, two_cameras, scene):
    ui = two_cameras
    page = ui.open(browser)
    op = Operator(ui, page)
    _true_box_in_database(ui, scene)
    wait_until(lambda: ui.server.database_drawn, what="the moved box drawn")
    _show_side(page)
    cam = page.panel.client.camera  # fitted on the side camera's image: right of the first one's
    side_pw = ui.server.views["side"].pixel_world
    assert abs(float(cam.look_at[0]) - side_pw.image_center[0]) < 0.05 * side_pw.render_size[0]
    # a click on the box's wireframe as the side camera sees it selects it
    side = ui.site.camera_of("side")
    box = ui.site.object("parallelepiped")
    V = box.vertices_world()
    top = np.argsort(V[:, 2])[-4:]  # a top edge, well inside the image
    uv = side.project(V[top[:2]]).mean(axis=0)
    select_by_click(page, "parallelepiped", lambda: op.click(uv))
    assert page.panel.camera_view == "side"


def test_both_cameras_frozen_fitted_side_by_side_and_clicked_in(browser, two_cameras, scene):
    """F freezes every camera's frame of that moment, each shown over its own video (the camera not shown
    played live beside a frozen one); Fit view on a fitted view shows both images; a click on the side
    camera's image there selects in the side camera."""
    import viser

    ui = two_cameras
    page = ui.open(browser)
    panel = page.panel
    _true_box_in_database(ui, scene)
    wait_until(lambda: ui.server.database_drawn, what="the moved box drawn")
    page.keyboard.press("f")
    frozen = panel.frozen_frames
    wait_until(lambda: frozen.frame is not None and set(frozen.frame.others) == {"side"}, what="both frames frozen")
    wait_until(
        lambda: all(frozen._sent.get(v) is not None for v in ("front", "side")), what="each camera's frozen image"
    )
    # the page opened fitted on the front camera's image: Fit view, the view unmoved, shows every camera's
    wait_for_steady_camera(panel)  # (an operator presses it on the view the page shows, not one on its way)
    page.keyboard.press("h")
    every = ui.server.all_images
    wait_until(
        lambda: (
            panel.viewport.all_cameras
            and not panel.viewport.need_fit
            and abs(float(panel.client.camera.look_at[0]) - every.image_center[0]) < 0.02 * every.render_size[0]
        ),
        what="both images fitted side by side",
        panel=panel,
    )
    # the click is placed through the camera the page reports: wait for the fit's move to end (its look-at can
    # reach the middle while the view still zooms out)
    wait_for_steady_camera(panel)
    assert panel.camera_view == "front"
    side = ui.site.camera_of("side")
    V = ui.site.object("parallelepiped").vertices_world()
    uv = side.project(V[np.argsort(V[:, 2])[-4:][:2]]).mean(axis=0)  # a top edge as the side camera sees it
    cam = panel.client.camera
    X = ui.server.views["side"].pixel_world.to_world(uv)
    p = viser.transforms.SO3(np.asarray(cam.wxyz)).as_matrix().T @ (X - np.asarray(cam.position))
    t = np.tan(cam.fov / 2.0)
    width, height = canvas_size(panel)
    x = (0.5 + p[0] / p[2] / (2 * t * cam.aspect)) * width
    y = (0.5 + p[1] / p[2] / (2 * t)) * height
    page.locator("canvas").nth(1).click(position={"x": float(x), "y": float(y)})
    wait_until(
        lambda: panel.camera_view == "side" and panel.session.selected == "parallelepiped",
        what="the box selected in the side camera",
        panel=panel,
    )
    assert frozen.frame is not None and panel.viewport.all_cameras  # the view and the frozen frames stay
    page.keyboard.press("h")  # again: the camera shown, alone
    shown = ui.server.views["side"].pixel_world
    wait_until(
        lambda: (
            not panel.viewport.all_cameras
            and not panel.viewport.need_fit
            and abs(float(panel.client.camera.look_at[0]) - shown.image_center[0]) < 0.02 * shown.render_size[0]
        ),
        what="the side image fitted alone",
        panel=panel,
    )


def test_calibrate_the_side_camera_by_clicks(browser, two_cameras, scene):
    ui = two_cameras
    _true_box_in_database(ui, scene)
    true_side = scene.view("side").camera
    wrong = _wrong_camera(true_side)
    ui.site.set_camera(wrong, rms_px=0.0, residuals_px=np.zeros((0, 2)), points={}, client="test setup", view="side")
    front_before = ui.site.camera_of("front").C.copy()
    n_front = len(ui.db.calibrations("camera"))
    n_side = len(ui.db.calibrations("camera:side"))
    page = ui.open(browser)
    op = Operator(ui, page)
    _show_side(page)
    op.press("Calibrate camera")
    wf = workflow_shown(page, "calibrate_camera")
    assert wf.view == "side"
    assert_prompt_controls(page)
    corners = _visible_corners(ui.site, wrong)
    box = [c for c in corners if c[0] == "parallelepiped"]
    corners = [c for c in corners if c[0] == "table"] + box[::2]
    assert len(corners) >= 8, corners
    for corner in corners:
        _pair_corner(op, page, wf, corner, wrong, true_side)  # where the side overlay draws it, then in its video
    op.key("r")  # Solve (R)
    wait_until(lambda: wf.result is not None, what="the solution", panel=page.panel)
    op.accept(wf)
    cals = ui.db.calibrations("camera:side")
    assert len(cals) == n_side + 1 and len(ui.db.calibrations("camera")) == n_front
    stored = Camera(np.asarray(cals[-1].data["C"], float), true_side.width, true_side.height)
    t = ui.frame_t_s
    bodies = np.vstack(
        [b.model.vertices @ b.pose_at(t)[:3, :3].T + b.pose_at(t)[:3, 3] for b in scene.bodies if b.status != "scenery"]
    )
    seen = true_side.in_image(true_side.project(bodies)) & (true_side.depth(bodies) > 0)  # where the operator looks
    err = np.linalg.norm(stored.project(bodies[seen]) - true_side.project(bodies[seen]), axis=1)
    print(f"  stored side C vs the true one at the {seen.sum()} body corners it sees: max {err.max():.2f} px")
    assert err.max() < 1.0
    assert np.array_equal(ui.site.camera_of("front").C, front_before)  # the first camera untouched
    assert cals[-1].data["view"] == "side" and cals[-1].data["frame"]["view"] == "side"
    said = [c for c in ui.site.changes_since(0) if c.who.startswith("browser-")]
    assert said and said[-1].what == "calibrated the camera side", said
    op.report("calibrate the side camera")


def _edges_seen(camera, model, T) -> list[int]:
    wf = model.wireframe(camera.center, T)
    uv = camera.project(model.edge_segments(T).reshape(-1, 3)).reshape(-1, 2, 2)
    return [
        int(k)
        for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind)
        if v and kind == "edge" and camera.in_image(uv[k]).all() and np.linalg.norm(uv[k][1] - uv[k][0]) > 30
    ]


def _click_edges(op, page, wf, camera, model, T_true, edges) -> None:
    """Each edge: two clicks along it where the video shows it, then one on the wireframe where the
    workflow's estimate draws it in this camera ("this is model edge k")."""
    true = camera.project(model.edge_segments(T_true).reshape(-1, 3)).reshape(-1, 2, 2)
    for k in edges:
        a, b = true[k]
        op.click(a + 0.3 * (b - a))
        op.click(a + 0.7 * (b - a))
        wait_until(lambda: wf.current_step().name == "assign_edge", what="the clicked edge", panel=page.panel)
        drawn = camera.project(model.edge_segments(wf.T_current).reshape(-1, 3)).reshape(-1, 2, 2)
        op.click(drawn[k].mean(axis=0))
        wait_until(lambda: wf.edge_ids and wf.edge_ids[-1] == k, what=f"edge {k} assigned", panel=page.panel)


def test_update_pose_from_edges_clicked_in_both_cameras(browser, two_cameras, scene):
    """The moved box: three edges clicked and assigned in the front camera, Solve, then (N) three in the
    side camera, one of them a model edge clicked in the front camera too; Refine fits all six in both
    cameras at once: the pose within 1° and 3 mm of the truth."""
    from core.transforms import pose_error

    from .test_workflows_pose import _select

    ui = two_cameras
    page = ui.open(browser, viewport={"width": 1280, "height": 720})
    op = Operator(ui, page)
    site = ui.site
    obj = site.object("parallelepiped")
    T_true = scene.body("parallelepiped").pose_at(ui.frame_t_s)
    assert pose_error(T_true, obj.T_world_obj)[1] > 0.1  # the database is stale: the box moved
    front, side = site.camera_of("front"), site.camera_of("side")
    model = obj.model
    _select(op, page, obj, front)
    op.press("Update pose")
    wait_until(lambda: page.panel.session.workflow is not None, what="the workflow")
    wf = page.panel.session.workflow
    assert wf.view == "front"
    # front: three edges of three directions, not through one corner
    import itertools

    V, E = model.vertices, model.edges
    vis = [k for k in _edges_seen(front, model, T_true) if k in _edges_seen(front, model, obj.T_world_obj)]
    axis = {k: int(np.abs(V[E[k][1]] - V[E[k][0]]).argmax()) for k in vis}
    triple = next(
        t
        for t in itertools.combinations(vis, 3)
        if len({axis[k] for k in t}) == 3 and not set(E[t[0]]) & set(E[t[1]]) & set(E[t[2]])
    )
    _click_edges(op, page, wf, front, model, T_true, triple)
    op.press("Solve")
    wait_until(lambda: len(wf.candidates) > 0, what="P3L candidates", panel=page.panel)
    best = min(range(len(wf.candidates)), key=lambda i: pose_error(wf.candidates[i], T_true)[0])
    if best != wf.chosen:  # the white ghost on the box, picked in the Candidate chooser
        op.choose("Candidate", wf.candidate_labels()[best])
        wait_until(lambda: wf.chosen == best, what="the candidate on the box")
    one_view = pose_error(wf.candidates[best], T_true)
    # side: the camera shown by its key, three more edges clicked there
    _show_side(page)
    op.actions += 1
    seen = _edges_seen(side, model, T_true)
    assert len(seen) >= 3, seen
    # one of them an edge already clicked in the front camera: it is that model edge again, in this camera
    again = [k for k in seen if k in triple][:1]
    _click_edges(op, page, wf, side, model, T_true, (again + [k for k in seen if k not in triple])[:3])
    page.get_by_text("in camera front (camera side shown)").first.wait_for(timeout=60_000)
    assert wf.seg_views == ["front"] * 3 + ["side"] * 3
    op.press("Refine")
    wait_until(lambda: wf.refined is not None, what="the refinement over both cameras", panel=page.panel)
    assert wf.refined.views == (0, 0, 0, 1, 1, 1)
    assert "in cameras front, side" in wf.message
    op.accept(wf)
    rec = ui.db.get("parallelepiped")
    deg, m = pose_error(rec.T_world_obj, T_true)
    print(
        f"  P3L from the front camera alone: {one_view[0]:.3f}° / {1000 * one_view[1]:.2f} mm; written from both "
        f"cameras: {deg:.3f}° / {1000 * m:.2f} mm"
    )
    assert deg < 1.0 and m < 0.003
    assert ui.db.history("parallelepiped")[-1].clicks["views"] == ["front"] * 3 + ["side"] * 3
    op.report("update pose from edges clicked in both cameras")
