"""The robot's base calibrated from the video, and the camera calibrated from the robot, in the browser on the
live emulated site as ``mcit serve`` runs it, by visible controls, keys and canvas clicks only; checked against
the scene's truth.

* Calibrate robot: a new database believes the drawing's base (2.5 cm and 2° off); Move robot asks once more
  before moving through it. The robot goes to the scene's three poses (G); at each, the operator clicks two
  points along the edges a human would click (seen, long enough, one clear step in the frozen frame), each
  off the edge by 0.7 px; when the panel asks which edge it is, they click it on the white robot. Solve (R); the
  farthest-off edge chosen in Edge and forgotten by Remove edge; Solve again, Accept: the base within 1° and
  3 mm of the truth, and the robot drawn through it within 0.5 px of the rendered one at every pose.
* Calibrate camera from robot: the base known (its true pose stored, as surveyed), the camera's calibration
  bumped by 1° and 3 cm: the robot shows its tool's tip at the scene's eight poses, the operator clicks the
  circled corner where the video shows it (0.7 px off), Solve, Accept: the table's and boxes' corners
  through the new C within 3 px of the true C's (the fingertips are 8 to 12 px wide: their snapped corners are
  off by 0.1 to 0.8 px, and the DLT's 11 unknowns rest on 8 points spread over the robot's reach, not the
  table's far corners).
"""

from __future__ import annotations

import numpy as np
import pytest

from core.robot.calibration import features_at
from core.transforms import exp_so3, make_T, pose_error

from .flows import Operator
from .harness import key_until, panel_state, wait_until
from .test_robot import LiveRobotSite

pytestmark = pytest.mark.e2e

CLICK_SIGMA_PX = 0.7  # how far off the edge (or the corner) the test's operator clicks


def _said(page, text: str, what: str, timeout_s: float = 60.0) -> None:
    wait_until(lambda: text in panel_state(page.panel), timeout_s, what, panel=page.panel)


def _at_pose(op, page, wf, k: int, step: str) -> None:
    """Next pose (G), then wait for the robot to be at pose k with its frame frozen and the workflow asking for
    clicks. A key pressed before the page's shortcuts listen does nothing: pressed again, as an operator would."""
    op.actions += key_until(page, "g", lambda: wf.tour.index == k, f"the robot sent to pose {k + 1}", page.panel)
    op.log.append("key g")
    wait_until(
        lambda: wf.tour.at == k and wf.frame is not None and wf.current_step().name == step,
        90.0,
        f"the robot at pose {k + 1} and its frame frozen",
        panel=page.panel,
    )


def test_the_base_is_calibrated_from_edges_clicked_on_the_live_video(browser, tmp_path):
    from tests.app.robot.calibration_truth import clickable_edges, drawn_error_px, operator_segment

    ui = LiveRobotSite(tmp_path, base_calibrated=False)
    try:
        page = ui.open(browser)
        op = Operator(ui, page)
        site, scene = ui.site, ui.scene
        cam, model, T_true = site.camera, site.robot.model, scene.robot.T_world_base
        assert site.robot_base_nominal
        wait_until(lambda: "not calibrated" in page.panel.gui_title.content, 30.0, "the panel: base nominal")

        # Move robot with the drawing's base: asked once more, in one line, before anything moves
        q0 = site.robot.controller.state().q
        op.press("Move robot")
        _said(page, "step=click", "Move robot's first step")
        op.click(cam.project(np.array([[0.15, -0.25, 0.0]]))[0])
        _said(page, "passes every check", "the motion checked")
        op.key_until("m", lambda: page.panel.asking == "move", "Move's question")
        assert "not calibrated" in page.panel.warning and "\n" not in page.panel.warning
        assert np.allclose(site.robot.controller.state().q, q0)
        op.key("Escape")
        wait_until(lambda: page.panel.session.workflow.finished, 30.0, "Move robot cancelled", panel=page.panel)

        op.press("Calibrate robot")
        _said(page, "workflow=calibrate_robot", "Calibrate robot started")
        wf = page.panel.session.workflow
        _said(page, "step=go", "Calibrate robot's first step")
        op.check()
        rng = np.random.default_rng(0)
        auto = hand = 0
        for k in range(wf.tour.n):
            _at_pose(op, page, wf, k, "click_edge")
            q = wf.tour.arrived[k]
            edges = clickable_edges(scene, model, q, k, cam, wf.frame.image, T_true, t_s=wf.frame.t_s)
            assert len(edges) >= 3, f"pose {k + 1}: {len(edges)} edges to click on the frame of t = {wf.frame.t_s} s"
            for f, a, b in edges:
                n = len(wf.edges)
                for p in operator_segment(a, b, rng, CLICK_SIGMA_PX):
                    op.click(p)
                # (the step read under the workflow's lock: once the edge's click has been handled whole)
                steps = ("click_edge", "assign_edge")
                taken = lambda: len(wf.edges) == n + 1 and wf.current_step().name in steps  # noqa: E731
                wait_until(taken, 30.0, "the edge taken", page.panel)
                edge = wf.edges[-1]
                if wf.current_step().name == "assign_edge":  # the panel asks which edge it is: click it on the robot
                    drawn = {g: s for g, s, _ in features_at(model, q, wf.T_est, cam.center, k)}
                    op.click(cam.project(drawn[f]).mean(axis=0))
                    wait_until(lambda: edge.feature is not None, 30.0, "the edge assigned", panel=page.panel)
                    hand += 1
                    how = "assigned by the click on the robot"
                else:
                    auto += 1
                    how = "matched automatically"
                assert edge.feature == f, (
                    f"edge {len(wf.edges)} at pose {k + 1} was {how} to {edge.feature}; it is {f} "
                    f"(the frame of t = {wf.frame.t_s} s)"
                )
        op.key("r")
        _said(page, "step=review", "the solved base")
        op.check()
        # the farthest-off edge, chosen in the Edge chooser, forgotten by Remove edge; then solved again
        n = len(wf.edges)
        text, i = wf.choices("edge")[0]
        removed = wf.edges[i]
        chooser = page.panel.workflow_controls.handles["edge"]
        wait_until(lambda: chooser.value == text, 30.0, "the farthest-off edge shown chosen", page.panel)
        op.choose("Edge", text)
        op.press("Remove edge")
        gone = lambda: len(wf.edges) == n - 1 and all(e is not removed for e in wf.edges)  # noqa: E731
        wait_until(gone, 30.0, "the edge removed", page.panel)
        _said(page, f"Edge {i + 1} (", "the edge's removal said")
        op.key("r")
        _said(page, "step=review", "the base solved again")
        op.accept(wf)
        T = site.robot.T_world_base
        deg, m = pose_error(T, T_true)
        qs = np.array(list(wf.tour.arrived.values()))
        drawn = drawn_error_px(model, qs, cam, T_true, T)
        # what the fit says of it: the same measure between the base and bases drawn from its covariance ((δt, δr) in
        # the world frame about the base's origin). The edges clickable on the frames vary with the live site's clock
        # (its boxes move and hide some): 14-17 of them, 0.17-0.58 px, in runs of this test
        rng_cov = np.random.default_rng(1)
        spread = [
            drawn_error_px(model, qs, cam, T, make_T(exp_so3(d[3:]) @ T[:3, :3], T[:3, 3] + d[:3]))
            for d in rng_cov.multivariate_normal(np.zeros(6), wf.fit.cov, 40)
        ]
        stated = float(np.sqrt(np.mean(np.square(spread))))
        print(
            f"base calibrated from {len(wf.edges)} edges ({auto} matched automatically, {hand} assigned): "
            f"{deg:.3f}° and {1000 * m:.2f} mm from the truth; drawn robot within {drawn:.3f} px (its σ "
            f"{stated:.3f} px); " + op.report("calibrate robot")
        )
        assert deg < 1.0 and m < 0.003, (deg, m)
        assert drawn < 3.0 * stated and stated < 0.35, (drawn, stated)  # within what it states, which is small
        assert not site.robot_base_nominal and site.db.latest_calibration("robot_base").method == "robot edges"
        wait_until(lambda: "not calibrated" not in page.panel.gui_title.content, 30.0, "the panel's warning gone")
    finally:
        ui.close()


def test_the_camera_is_calibrated_from_the_robot_s_tool_tip(browser, tmp_path):
    from app.db import Database, seed_from_scene
    from app.scene import default_scene_path, load_scene
    from app.workflows.calibrate_camera_robot import visible_tip
    from core.camera import Camera
    from core.transforms import exp_so3, make_T
    from tests.app.robot.calibration_truth import scene_points

    scene = load_scene(default_scene_path())
    truth = scene.camera
    K, T_cw = truth.decompose()
    bumped = Camera.from_intrinsics(
        K, make_T(exp_so3(np.radians([0.8, -0.6, 0.5])), [0.01, -0.015, 0.02]) @ T_cw, truth.width, truth.height
    )
    with Database.open(tmp_path / "site.sqlite") as db:  # the base surveyed, the camera bumped since
        seed_from_scene(db, scene)
        base = {"T_world_base": scene.robot.T_world_base, "nominal": False}
        db.add_calibration("robot_base", base, None, method="test set-up", client="test")
        cam = {"C": bumped.C, "width": truth.width, "height": truth.height}
        db.add_calibration("camera", cam, None, method="test set-up", client="test")
    ui = LiveRobotSite(tmp_path, base_calibrated=False)
    try:
        page = ui.open(browser)
        op = Operator(ui, page)
        site, X = ui.site, scene_points(scene)
        before = np.linalg.norm(site.camera.project(X) - truth.project(X), axis=1).max()
        assert before > 10
        op.press("Calibrate camera from robot")
        _said(page, "workflow=calibrate_camera_robot", "the workflow started")
        wf = page.panel.session.workflow
        _said(page, "step=go", "the first step")
        rng = np.random.default_rng(1)
        for k in range(wf.tour.n):
            _at_pose(op, page, wf, k, "click_tip")
            op.check()
            corner = visible_tip(truth, site.robot.model, wf.tour.arrived[k], scene.robot.T_world_base)[0]
            assert np.allclose(wf._tip(k)[0], corner), "the workflow circles another corner than the one seen"
            op.click(truth.project(corner[None])[0] + rng.normal(0.0, CLICK_SIGMA_PX, 2))
            wait_until(lambda: k in wf.points, 30.0, "the tip taken", panel=page.panel)
        op.key("r")
        _said(page, "step=review", "the solved camera")
        op.accept(wf)
        err = np.linalg.norm(site.camera.project(X) - truth.project(X), axis=1)
        print(
            f"camera from the tool's tip at {wf.tour.n} poses: the scene's corners {before:.1f} px off before, "
            f"{err.max():.2f} px (RMS {np.sqrt(np.mean(err**2)):.2f} px) after; " + op.report("calibrate camera")
        )
        assert err.max() < 3.0, err.max()
        assert site.db.latest_calibration("camera").method == "robot dlt"
    finally:
        ui.close()


def test_a_calibration_pose_an_object_blocks_is_refused_and_left_out_by_skip_pose(browser, tmp_path):
    """A crate modelled where the camera's first calibration pose puts the tool: Next pose is refused, naming it and
    Skip pose (K); the Skip pose button leaves the pose out, and Next pose then sends the robot to the second."""
    from app.db import Database
    from app.robot.urdf import load_scene_robot
    from core.brep import BRep
    from core.transforms import make_T

    ui = LiveRobotSite(tmp_path)
    try:
        scene = ui.scene
        model, _ = load_scene_robot(scene.robot)
        tip = scene.robot.T_world_base @ model.tool_pose(scene.robot.calibration_qs(model, "camera")[0])
        with Database.open(tmp_path / "site.sqlite") as db:
            db.add_object("crate", "box", BRep.box(0.04, 0.04, 0.04), make_T(np.eye(3), tip[:3, 3]), client="test")
        page = ui.open(browser)
        op = Operator(ui, page)
        wait_until(lambda: "crate" in [o.name for o in ui.site.objects()], 30.0, "the crate in the site")
        q0 = ui.site.robot.controller.state().q
        op.press("Calibrate camera from robot")
        _said(page, "step=go", "the first step")
        wf = page.panel.session.workflow
        op.key_until("g", lambda: "Skip pose (K)" in page.panel.error, "pose 1's motion refused")
        assert "pose 1 was refused" in page.panel.error and "crate" in page.panel.error, page.panel.error
        assert np.allclose(ui.site.robot.controller.state().q, q0)
        op.press("Skip pose")
        wait_until(lambda: wf.tour.skipped == [0], 30.0, "pose 1 left out", panel=page.panel)
        _said(page, f"Pose 1 of {wf.tour.n} left out: Next pose (G) sends the robot to pose 2", "the pose left out")
        _at_pose(op, page, wf, 1, "click_tip")
        op.key("Escape")
    finally:
        ui.close()
