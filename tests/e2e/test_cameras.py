"""Two cameras in the browser: the operator shows the side camera (its chooser, or N), selects in it,
and calibrates it by clicks as the first one; the first camera's calibration stays as it was."""

from __future__ import annotations

import numpy as np
import pytest

from core.camera import Camera

from .flows import Operator
from .harness import FRAME_T_S, Interface, assert_prompt_controls, key_until, select_by_click, wait_until
from .test_workflows_site import _pair_corner, _true_box_in_database, _visible_corners, _workflow, _wrong_camera

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def side_frame(scene):
    """The side camera's image at FRAME_T_S (RGB uint8)."""
    from app.render.renderer import Renderer

    view = scene.view("side")
    img = Renderer(scene, camera=view.camera, lens=view.lens).render(FRAME_T_S, 0)
    return np.repeat(img[:, :, None], 3, axis=2) if img.ndim == 2 else img


@pytest.fixture
def two_cameras(scene, frame, side_frame, tmp_path):
    ui = Interface(scene, {"front": frame, "side": side_frame}, tmp_path / "site.sqlite")
    yield ui
    ui.close()


def _show_side(page):
    panel = page.panel
    key_until(page, "n", lambda: panel.camera_view == "side" and not panel.need_fit, "the side camera shown")
    wait_until(lambda: page.get_by_text("Camera (N)").first.is_visible(), what="the Camera chooser")


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
    page.close()


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
    wf = _workflow(page, "calibrate_camera")
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
    page.close()
