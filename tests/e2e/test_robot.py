"""The robot in the browser, on the live emulated site as ``mcit serve`` runs it: targets clicked on the
video, the motion previewed and checked, Move robot (M), Stop (Space); a path into the parallelepiped
refused naming it, the robot not moved. Checked against the truth: the emulated robot's joints (the
feed's robot lines) through the scene's true base pose."""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import pytest

from .flows import Operator
from .harness import Interface, free_port, panel_state, wait_until

pytestmark = pytest.mark.e2e

STANDOFF_M = 0.02  # the workflow's default standoff


class LiveRobotSite(Interface):
    """``mcit serve``'s own interface (build_interface) on the bundled scene: the site rendered live with its
    robot, no range finder and turret, a fresh database and a feed file. ``base_calibrated``: the database
    starts with the robot's base calibrated at its true pose (as after Calibrate robot), else at the drawing's
    nominal pose (as a new database does)."""

    def __init__(self, tmp_path, base_calibrated: bool = True):
        from app.ui.serve import add_serve_parser, build_interface

        parser = argparse.ArgumentParser()
        add_serve_parser(parser.add_subparsers(dest="command"))
        self.feed_path = tmp_path / "feed.jsonl"
        db_path = tmp_path / "site.sqlite"
        if base_calibrated:
            _calibrated_database(db_path)
        args = parser.parse_args(
            ["serve", "--port", str(free_port()), "--db", str(db_path), "--no-devices"]
            + ["--feed-file", str(self.feed_path)]
        )
        self.server, self.closers = build_interface(args)
        self.server.start()
        self.site = self.server.site
        self.scene = self.site.scene
        self.db = self.site.db
        self._own_devices = None
        self.url = f"http://127.0.0.1:{self.server.port}/?fixedDpr=1"
        self.csp_refusals: list[str] = []

    def robot_lines(self) -> list[dict]:
        if not self.feed_path.exists():
            return []
        lines = [json.loads(x) for x in self.feed_path.read_text().splitlines() if x.strip()]
        return [x for x in lines if x.get("type") == "robot"]

    def close(self):
        self.server.stop()
        for close in self.closers:
            close()
        if self.csp_refusals:
            raise AssertionError(f"the page's Content-Security-Policy refused: {self.csp_refusals[:3]}")


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


def _said(page, text: str, what: str) -> None:
    wait_until(lambda: text in panel_state(page.panel), 60.0, what, panel=page.panel)


def _move_to(ui, page, op, X: np.ndarray, normal: np.ndarray) -> int:
    """Click the video where the point X lies, press M, wait for the arrival; the operator's actions taken."""
    before = op.actions
    op.click(ui.site.camera.project(X[None])[0])
    _said(page, "passes every check", "the motion checked")
    op.key("m")
    _said(page, "Arrived", "the robot's arrival")
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
    page.close()


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
    page.close()


def test_stop_halts_the_robot_where_it_is(browser, robot_site):
    ui = robot_site
    page = ui.open(browser)
    op = Operator(ui, page)
    op.press("Move robot")
    _said(page, "step=click", "Move robot's first step")
    op.click(ui.site.camera.project(np.array([[0.2, -0.4, 0.0]]))[0])
    _said(page, "passes every check", "the motion checked")
    op.key("m")
    wait_until(lambda: ui.site.robot.controller.state().moving, 30.0, "the robot moving")
    op.key(" ")
    _said(page, "Stopped", "the stop said")
    q = ui.site.robot.controller.state().q
    time.sleep(0.5)
    assert np.allclose(ui.site.robot.controller.state().q, q), "the robot went on after Stop"
    assert not ui.site.robot.controller.state().moving
    page.close()
