"""The robot in the browser, on the live emulated site as ``mcit serve`` runs it: targets clicked on the
video, the motion previewed and checked, Move robot (M), Stop (Space); a path into the parallelepiped
refused naming it, the robot not moved. Checked against the truth: the emulated robot's joints (the
feed's robot lines) through the scene's true base pose."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from .flows import Operator
from .harness import ServedInterface, panel_state, wait_until

pytestmark = pytest.mark.e2e

STANDOFF_M = 0.02  # the workflow's default standoff


class LiveRobotSite(ServedInterface):
    """``mcit serve``'s own interface (build_interface) on the bundled scene: the site rendered live with its
    robot, no range finder and turret, a fresh database and a feed file. ``base_calibrated``: the database
    starts with the robot's base calibrated at its true pose (as after Calibrate robot), else at the drawing's
    nominal pose (as a new database does). The site is rendered at 2 frames/s, not its video's 12: these checks read
    the robot's joints, not the video, and rendering it (the server's llvmpipe, the page's software WebGL) was most
    of their CPU."""

    def __init__(self, tmp_path, base_calibrated: bool = True):
        self.feed_path = tmp_path / "feed.jsonl"
        db_path = tmp_path / "site.sqlite"
        if base_calibrated:
            _calibrated_database(db_path)
        super().__init__(["--db", str(db_path), "--no-devices", "--feed-file", str(self.feed_path), "--fps", "2"])

    def robot_lines(self) -> list[dict]:
        if not self.feed_path.exists():
            return []
        lines = [json.loads(x) for x in self.feed_path.read_text().splitlines() if x.strip()]
        return [x for x in lines if x.get("type") == "robot"]


def _calibrated_database(path) -> None:
    """A new database of the bundled scene whose robot base is calibrated at its true pose."""
    from app.db import Database, seed_from_scene
    from app.scene import default_scene_path, load_scene

    scene = load_scene(default_scene_path())
    with Database.open(path) as db:
        seed_from_scene(db, scene)
        base = {"T_world_base": scene.robot.T_world_base, "nominal": False}
        db.add_calibration("robot_base", base, None, method="test set-up", client="test")


@pytest.fixture
def robot_site(tmp_path):
    ui = LiveRobotSite(tmp_path)
    yield ui
    ui.close()


def _true_tool(ui) -> np.ndarray:
    """The tool's true pose: the emulated robot's joints through the scene's true base."""
    cell = ui.site.robot
    return ui.scene.robot.T_world_base @ cell.model.tool_pose(cell.controller.state().q)


def _no_true_contact(ui, path) -> None:
    """The motion the robot made touched none of the site's true bodies (the emulated truth, not the database)."""
    from app.robot.collision import CollisionChecker

    world = ui.server.emulated_world
    checker = CollisionChecker(world.model, world.T_world_base)
    t = ui.site.time_s()
    checker.set_obstacles(
        [(b.name, b.model, world.pose_of(i, t), 0.0) for i, b in enumerate(ui.scene.bodies) if b.status != "scenery"]
    )
    check = checker.check_path(path)
    assert check.ok, f"the robot touched {check.other} with its {check.link} ({1000 * check.distance_m:.1f} mm)"


def _moved(ui, page) -> bool:
    """Move (M) was taken: the robot moves, or the preview has gone (arrived, faulted or stopped already)."""
    return ui.site.robot.controller.state().moving or "step=preview" not in panel_state(page.panel)


def _said(page, text: str, what: str) -> None:
    wait_until(lambda: text in panel_state(page.panel), 60.0, what, panel=page.panel)


def _move_to(ui, page, op, X: np.ndarray, normal: np.ndarray, told: str = "") -> int:
    """Click the video where the point X lies, press M, wait for the arrival; the operator's actions taken. ``told``:
    what the panel must say of the checked motion."""
    before = op.actions
    op.click(ui.site.camera.project(X[None])[0])
    _said(page, "passes every check", "the motion checked")
    assert told in panel_state(page.panel), panel_state(page.panel)
    op.key_until("m", lambda: _moved(ui, page), "the motion sent")
    _said(page, "Arrived", "the robot's arrival")
    _no_true_contact(ui, page.panel.session.workflow.sent.path)
    T = _true_tool(ui)
    goal = X + STANDOFF_M * normal
    err = float(np.linalg.norm(T[:3, 3] - goal))
    assert err < 0.005, f"the tool stopped {1000 * err:.1f} mm from the commanded point"
    assert T[:3, 2] @ -normal > np.cos(np.radians(1.0)), "the tool does not point into the surface"
    return op.actions - before


def test_the_robot_goes_to_targets_clicked_on_the_table_and_the_box_top(browser, robot_site):
    ui = robot_site
    page = ui.open(browser)
    op = Operator(ui, page)
    op.press("Move robot")
    _said(page, "step=click", "Move robot's first step")
    up = np.array([0.0, 0.0, 1.0])
    n_table = _move_to(ui, page, op, np.array([0.15, -0.25, 0.0]), up)
    box = ui.site.object("parallelepiped")
    V = box.vertices_world()
    top = V[np.argsort(V[:, 2])[-4:]].mean(axis=0)
    n_box = _move_to(ui, page, op, top, up)
    assert n_table <= 6 and n_box <= 6, op.report("moves")
    lines = ui.robot_lines()
    assert any(x["moving"] for x in lines) and not lines[-1]["moving"], "the feed did not follow the motion"
    assert np.allclose(np.array(lines[-1]["T"])[:3, 3], _true_tool(ui)[:3, 3], atol=1e-3)


def test_a_robot_left_inside_the_table_s_margin_is_moved_clear_by_a_click_and_told(browser, robot_site):
    """The robot 4 mm over the table, inside the 10 mm kept from it (as a base calibrated since can leave it): every
    motion was refused at its first sample. A target clicked across the table is planned, the panel says the motion
    may take it away but not nearer, and M moves it there without touching anything."""
    from tests.app.robot.test_move_workflows import _stand_over_the_table

    ui = robot_site
    _stand_over_the_table(ui.site, 0.004)
    page = ui.open(browser)
    op = Operator(ui, page)
    op.press("Move robot")
    _said(page, "step=click", "Move robot's first step")
    told = "from table, inside the 10 mm kept from it: this motion may take it away but not nearer"
    _move_to(ui, page, op, np.array([0.2, -0.4, 0.0]), np.array([0.0, 0.0, 1.0]), told=told)


def test_a_path_into_the_parallelepiped_is_refused_naming_it_and_the_robot_stays(browser, robot_site):
    ui = robot_site
    page = ui.open(browser)
    op = Operator(ui, page)
    q0 = ui.site.robot.controller.state().q
    op.press("Move robot")
    _said(page, "step=click", "Move robot's first step")
    # on the table, right against the parallelepiped's front face: the gripper would come within its margin
    op.click(ui.site.camera.project(np.array([[-0.02, 0.06, 0.0]]))[0])
    _said(page, "refused", "the refusal")
    text = panel_state(page.panel)
    assert "parallelepiped" in text, text
    assert (
        page.get_by_role("button", name="Move robot (M)").count() == 0
        or not page.get_by_role("button", name="Move robot (M)").first.is_enabled()
    )
    op.key("m")  # pressed anyway: nothing moves
    time.sleep(1.0)
    assert np.allclose(ui.site.robot.controller.state().q, q0)
    assert not any(x["moving"] for x in ui.robot_lines())


def test_stop_halts_the_robot_where_it_is(browser, robot_site):
    ui = robot_site
    page = ui.open(browser)
    op = Operator(ui, page)
    op.press("Move robot")
    _said(page, "step=click", "Move robot's first step")
    op.click(ui.site.camera.project(np.array([[0.2, -0.4, 0.0]]))[0])
    _said(page, "passes every check", "the motion checked")
    ui.site.robot.controller.speed_scale = 0.03  # a slow robot: still moving when Space arrives on a loaded machine
    op.key_until("m", lambda: _moved(ui, page), "the robot moving")
    op.key(" ")
    _said(page, "Stopped", "the stop said")
    q = ui.site.robot.controller.state().q
    time.sleep(0.5)
    assert np.allclose(ui.site.robot.controller.state().q, q), "the robot went on after Stop"
    assert not ui.site.robot.controller.state().moving


def _modelled_box_in_database(ui) -> None:
    """Setup: the unknown box in the database as Model object leaves it: modelled, 2 mm and 0.5° off its truth."""
    from core.transforms import exp_so3, make_T

    b = ui.scene.body("unknown_box")
    T = b.T_world_obj @ make_T(exp_so3(np.radians([0.0, 0.0, 0.5])), np.array([0.002, 0.0, 0.0]))
    cov = np.diag([0.002**2] * 3 + [np.radians(0.5) ** 2] * 3)
    ui.db.add_object("unknown_box", "box", b.model, T, cov=cov, status="modelled", client="test setup")


def test_pick_and_place_moves_the_modelled_box_and_the_database_follows(browser, robot_site):
    from core.transforms import log_so3

    from .harness import select_by_click

    ui = robot_site
    _modelled_box_in_database(ui)
    wait_until(lambda: ui.server.database_drawn, what="the box drawn")
    page = ui.open(browser)
    op = Operator(ui, page)
    box = ui.site.object("unknown_box")
    select_by_click(page, "unknown_box", lambda: op.click(ui.site.camera.project(box.vertices_world()).mean(axis=0)))
    op.press("Pick and place")
    _said(page, "step=click", "Pick and place's first step")
    place = np.array([-0.05, -0.38, 0.0])
    op.click(ui.site.camera.project(place[None])[0])
    _said(page, "passes every check", "the motion checked")
    op.key_until("m", lambda: _moved(ui, page), "the pick and place started")
    _said(page, "step=done", "the box put down and looked at")
    text = panel_state(page.panel)
    assert "confirmed by the video" in text, text
    # the page says it by itself, with no key pressed (it stayed on "Looking for …" until a key, for minutes)
    page.get_by_text("is put down, confirmed by the video", exact=False).first.wait_for(timeout=60_000)
    i = [b.name for b in ui.scene.bodies].index("unknown_box")
    T_true = ui.server.emulated_world.pose_of(i, 0.0)
    rec = ui.site.object("unknown_box")
    dp = 1000 * np.linalg.norm(rec.T_world_obj[:3, 3] - T_true[:3, 3])
    dr = np.degrees(np.linalg.norm(log_so3(T_true[:3, :3].T @ rec.T_world_obj[:3, :3])))
    assert dp < 5.0 and dr < 1.0, f"the database's box is {dp:.1f} mm and {dr:.2f}° off the truth"
    assert np.linalg.norm(T_true[:3, 3] - place) < 0.006, "the box is not where the operator clicked"
    assert ui.db.history("unknown_box", limit=1)[-1].method == "robot"
    assert op.actions <= 6, op.report("pick and place")


def test_a_joint_that_does_not_reach_its_command_is_said_in_the_panel(browser, robot_site):
    from app.robot.controller import ControllerFaults

    ui = robot_site
    ui.site.robot.controller.faults = ControllerFaults(stall_joint="elbow_joint", stall_at=0.4)
    page = ui.open(browser)
    op = Operator(ui, page)
    op.press("Move robot")
    _said(page, "step=click", "Move robot's first step")
    op.click(ui.site.camera.project(np.array([[0.15, -0.25, 0.0]]))[0])
    _said(page, "passes every check", "the motion checked")
    op.key_until("m", lambda: _moved(ui, page), "the motion sent")
    _said(page, "Fault: joint elbow_joint did not reach its command", "the fault said")
    # the feed is written by its own thread: its line with the fault may come a moment after the panel said it
    wait_until(
        lambda: (lines := ui.robot_lines()) and "elbow_joint" in (lines[-1]["fault"] or ""),
        30.0,
        "the feed to carry the fault",
    )
