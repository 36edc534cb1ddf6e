"""The scene's robot calibration block: the nominal base (the drawing's) off the true one, the calibration
poses read in the URDF's joint order with the gripper closed, and the bundled poses doing what the scene
says: every motion between them (straight, or through home) clears every body at every time of the
recording at the true base and the database's objects at the nominal base, and the base's poses fix the
base to a millimetre from edges the front camera sees."""

import numpy as np
import pytest

from app.robot.collision import CollisionChecker
from app.robot.urdf import load_scene_robot
from app.scene import SceneError, default_scene_path, load_scene, scene_from_dict
from core.robot import joint_path
from core.robot.calibration import BaseClick, refine_base
from core.transforms import pose_error
from tests.app.test_scene_robot import with_robot

ROOT = default_scene_path()
CLEAR_M = 0.02  # every sample of every motion this far from every body at the true base


@pytest.fixture(scope="module")
def workcell():
    s = load_scene(ROOT)
    model, home = load_scene_robot(s.robot)
    return s, model, home


def test_the_nominal_base_is_off_the_true_one(workcell):
    s, _, _ = workcell
    deg, m = pose_error(s.robot.nominal_base, s.robot.T_world_base)
    assert 1.0 <= deg <= 5.0 and 0.01 <= m <= 0.05  # a robot bolted down roughly where the drawing says
    assert s.robot.nominal_base[2, 3] == s.robot.T_world_base[2, 3]  # on the table top, as the truth


def test_calibration_poses_are_read_in_joint_order_with_the_gripper_closed(workcell):
    s, model, _ = workcell
    for which, n in (("base", 3), ("camera", 8)):
        Q = s.robot.calibration_qs(model, which)
        assert Q.shape == (n, model.n)
        assert np.allclose(Q[:, model.joint_names.index("finger_joint")], model.lower[-1])
        assert all(model.within_limits(q) is None for q in Q)
    assert np.allclose(np.degrees(s.robot.calibration_qs(model, "base")[0, :6]), [-120, -70, 130, -160, -35, 35])


def test_a_scene_without_them_has_none_and_bad_ones_are_refused_naming_the_field(tmp_path):
    spec = scene_from_dict(with_robot(tmp_path), tmp_path).robot
    model, _ = load_scene_robot(spec)
    assert spec.calibration_qs(model, "base").shape == (0, model.n)
    assert np.array_equal(spec.nominal_base, spec.T_world_base)
    with pytest.raises(SceneError, match=r"calibration_base_deg\[0\]: 2 angles for the 6 turning joints"):
        scene_from_dict(with_robot(tmp_path, calibration_base_deg=[[1, 2]]), tmp_path).robot.calibration_qs(
            model, "base"
        )
    with pytest.raises(SceneError, match=r"calibration_camera_deg\[0\] puts joint elbow_joint at 200\.0 °"):
        scene_from_dict(
            with_robot(tmp_path, calibration_camera_deg=[[0, 0, 200, 0, 0, 0]]), tmp_path
        ).robot.calibration_qs(model, "camera")
    for bad, match in (
        ({"calibration_base_deg": [1, 2]}, r"calibration_base_deg\[0\]: a list of angles"),
        ({"calibration_base_deg": {"a": 1}}, r"calibration_base_deg: a list of configurations"),
        ({"calibration_base_deg": [["x"]]}, r"calibration_base_deg\[0\]: a number"),
        ({"T_world_base_nominal": [[1]]}, r"T_world_base_nominal"),
    ):
        with pytest.raises(SceneError, match=match):
            scene_from_dict(with_robot(tmp_path, **bad), tmp_path)


def _checkers(s, model):
    truth = CollisionChecker(model, s.robot.T_world_base)
    bodies = []
    for b in s.bodies:
        if b.kind in ("floor", "wall"):
            continue
        times = np.linspace(0.0, 28.5, 30) if b.motion else [0.0]
        bodies += [(f"{b.name} at {t:.1f} s", b.model, b.pose_at(t), CLEAR_M) for t in times]
    truth.set_obstacles(bodies)
    nominal = CollisionChecker(model, s.robot.nominal_base)
    nominal.set_obstacles([(b.name, b.model, b.pose_at(0.0), 0.01) for b in s.bodies if b.status == "known"])
    return truth, nominal


@pytest.mark.parametrize("which", ["base", "camera"])
def test_every_motion_of_the_tour_clears_every_body(workcell, which):
    """The workflows go from home through the poses in order: each leg straight or, refused, through home
    (``RobotCell.plan_joints`` with via=[home]); some route must clear both checks."""
    s, model, home = workcell
    truth, nominal = _checkers(s, model)
    q = home
    for k, goal in enumerate(s.robot.calibration_qs(model, which)):
        routes = ([q, goal], [q, home, goal])
        ok = []
        for legs in routes:
            path = np.vstack([joint_path(model, a, b, truth.path_step_m) for a, b in zip(legs, legs[1:])])
            ok.append(truth.check_path(path).ok and nominal.check_path(path).ok)
        assert any(ok), f"{which} pose {k + 1}: no route clears the bodies"
        q = goal


def test_the_base_poses_fix_the_base_to_a_millimetre(workcell):
    """Every edge and silhouette the front camera sees at the three poses (no body or link hiding it, in the
    image, 25 px or longer), clicked at 0.3 px: σ of the base from the pose pipeline's covariance."""
    from tests.app.robot.calibration_truth import clickable_edges

    s, model, _ = workcell
    cam = s.camera
    Q = s.robot.calibration_qs(model, "base")
    clicks = []
    for k, q in enumerate(Q):
        for f, a, b in clickable_edges(s, model, q, k, cam, None, s.robot.T_world_base):
            clicks.append(BaseClick(np.array([a + 0.25 * (b - a), a + 0.75 * (b - a)]), f, 0.3))
    assert len(clicks) >= 30
    fit = refine_base(model, Q, clicks, [cam], s.robot.nominal_base)
    assert pose_error(fit.T_world_base, s.robot.T_world_base)[1] < 1e-8
    assert 1000 * fit.std_position_m < 1.0 and np.degrees(fit.std_angle_rad) < 0.1
