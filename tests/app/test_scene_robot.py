"""The scene's robot block: read and checked naming the field; the bundled arm's placement does what the
scene says (reaches the objects' tops from home without collision, hides no object edge from either camera)."""

import json

import numpy as np
import pytest

from app.robot.collision import CollisionChecker
from app.robot.urdf import load_scene_robot
from app.scene import RobotSpec, SceneError, default_scene_path, load_scene, scene_from_dict
from core.robot import joint_path, solve_ik
from core.transforms import invert_T, make_T
from tests.app.test_scene import minimal

ROOT = default_scene_path()


def with_robot(tmp_path, **robot) -> dict:
    (tmp_path / "arm.urdf").write_text((ROOT / "arm.urdf").read_text())
    d = minimal()
    d["robot"] = {"urdf": "arm.urdf", "T_world_base": {"xyz": [-0.3, 0, 0]}, **robot}
    return d


def test_the_workcell_has_its_robot_beside_the_bodies():
    s = load_scene(ROOT)
    assert isinstance(s.robot, RobotSpec) and s.robot.urdf_path == (ROOT / "arm.urdf").resolve()
    assert "robot" not in [b.name for b in s.bodies] and len(s.bodies) == 6  # the videos' truth unchanged
    model, home = load_scene_robot(s.robot)
    assert model.tool == "tool0" and model.within_limits(home) is None
    np.testing.assert_allclose(np.degrees(home[:6]), [0, -90, 90, -90, -90, 0])
    assert home[-1] == pytest.approx(0.03)
    np.testing.assert_allclose(s.robot.T_world_base[:3, 3], [-0.37, 0.03, 0.0])


def test_a_scene_without_robot_has_none(tmp_path):
    assert scene_from_dict(minimal(), tmp_path).robot is None


def test_home_values_are_read_in_their_units(tmp_path):
    d = with_robot(tmp_path, home_deg={"elbow_joint": 45}, home_m={"finger_joint": 0.02}, tool="gripper_link")
    spec = scene_from_dict(d, tmp_path).robot
    model, home = load_scene_robot(spec)
    assert model.tool == "gripper_link"
    assert home[model.joint_names.index("elbow_joint")] == pytest.approx(np.pi / 4)
    assert home[model.joint_names.index("finger_joint")] == pytest.approx(0.02)
    assert home[0] == 0.0


@pytest.mark.parametrize(
    "robot, match",
    [
        ({"urdf": None}, r"robot\.urdf: a URDF file name"),
        ({"urdf": "none.urdf"}, r"robot\.urdf: file not found"),
        ({"T_world_base": [[1, 0], [0, 1]]}, r"robot\.T_world_base"),
        ({"home_deg": {"elbow_joint": "x"}}, r"robot\.home_deg\.elbow_joint: a number"),
        ({"home_deg": [1, 2]}, r"robot\.home_deg: an object"),
        ({"home_deg": {"a": 1}, "home_m": {"a": 0.1}}, "given twice"),
        ({"tool": ""}, r"robot\.tool"),
        ({"colour": 1}, r"unknown field\(s\) \['colour'\]"),
        ({"appearance": {"albedo": 2}}, r"robot\.appearance\.albedo"),
    ],
)
def test_bad_robot_blocks_are_refused_naming_the_field(tmp_path, robot, match):
    d = with_robot(tmp_path)
    d["robot"].update(robot)
    with pytest.raises(SceneError, match=match):
        scene_from_dict(d, tmp_path)


@pytest.mark.parametrize(
    "robot, match",
    [
        ({"home_deg": {"knee": 10}}, r"robot\.home_deg: arm\.urdf has no actuated joint 'knee'"),
        ({"home_deg": {"finger_joint": 10}}, r"robot\.home_deg\.finger_joint: a prismatic joint; give it in home_m"),
        ({"home_m": {"elbow_joint": 0.1}}, r"robot\.home_m\.elbow_joint: a revolute joint; give it in home_deg"),
        ({"home_deg": {"elbow_joint": 200}}, r"robot: the home position puts joint elbow_joint at 200\.0 °"),
        ({"tool": "hand"}, r"robot\.tool: arm\.urdf has no link 'hand'"),
    ],
)
def test_home_and_tool_are_checked_against_the_urdf(tmp_path, robot, match):
    spec = scene_from_dict(with_robot(tmp_path, **robot), tmp_path).robot
    with pytest.raises(SceneError, match=match):
        load_scene_robot(spec)


def test_the_bundled_scene_file_names_its_choice():
    comment = json.loads((ROOT / "scene.json").read_text())["robot"]["_comment"]
    assert "reach" in comment and "hides no visible edge" in comment


# ---------------------------------------------------------------------- the placement's claims
@pytest.fixture(scope="module")
def workcell():
    s = load_scene(ROOT)
    model, home = load_scene_robot(s.robot)
    return s, model, home


def _hidden(cam, placed, X: np.ndarray) -> int:
    """How many of the world points X (N, 3) a placed robot part hides from the camera."""
    c = cam.center
    d = X - c
    dist = np.linalg.norm(d, axis=1)
    d = d / dist[:, None]
    hidden = np.zeros(len(X), dtype=bool)
    for _, brep, T in placed:
        T_obj_world = invert_T(T)
        o, dd = T_obj_world[:3, :3] @ c + T_obj_world[:3, 3], d @ T_obj_world[:3, :3].T
        for part in brep.parts:
            if part.surface:
                hidden |= part.ray_cast(o, dd)[0] < dist - 2e-3
    return int(hidden.sum())


@pytest.mark.parametrize("t_s", [0.0, 13.5, 15.0, 19.0, 22.5, 26.0])
def test_at_home_the_arm_hides_no_object_edge_from_either_camera(workcell, t_s):
    s, model, home = workcell
    placed = model.link_breps(home, s.robot.T_world_base)
    for view in s.views:
        cam = view.camera
        X = []
        for b in s.known + s.unknown:
            if b.name == "table":
                continue
            wf = b.model.wireframe(cam.center, b.pose_at(t_s))
            S = wf.segments[wf.visible]
            a = np.linspace(0.05, 0.95, 15)[None, :, None]
            X.append((S[:, :1] * (1 - a) + S[:, 1:] * a).reshape(-1, 3))
        X = np.vstack(X)
        assert len(X) > 100
        assert _hidden(cam, placed, X) == 0, view.name


def test_both_cameras_see_the_arm_at_home(workcell):
    """The base and shoulder wholly in both images; the side camera sees more than half of the arm."""
    s, model, home = workcell
    seen = {}
    for view in ("front", "side"):
        cam = s.view(view).camera
        for name, b, T in model.link_breps(home, s.robot.T_world_base):
            uv = cam.project(b.support_points(24) @ T[:3, :3].T + T[:3, 3])
            inside = np.all((uv >= 0) & (uv <= [cam.width - 1, cam.height - 1]), axis=1)
            seen.setdefault(view, []).append(inside)
            if name in ("base_link", "shoulder_link"):
                assert inside.all(), (view, name)
    assert np.concatenate(seen["side"]).mean() > 0.5


def test_from_home_the_arm_reaches_every_object_top_without_collision(workcell):
    """A 10 cm standoff above each object's top, tool pointing down, at the parallelepiped's first and last
    poses: solved from home, and the straight joint path to it is free of collision (margin 1 cm)."""
    s, model, home = workcell
    checker = CollisionChecker(model, s.robot.T_world_base)
    down = np.diag([1.0, -1.0, -1.0])
    for t_s in (0.0, 26.0):
        checker.set_obstacles([(b.name, b.model, b.pose_at(t_s), 0.01) for b in s.bodies if b.status != "scenery"])
        assert checker.check(home) == []
        for name in ("unknown_box", "parallelepiped", "unknown_cylinder"):
            b = s.body(name)
            top = b.pose_at(t_s)[:3, 3] + [0, 0, b.model.bounds()[1, 2] + 0.10]
            r = solve_ik(model, invert_T(s.robot.T_world_base) @ make_T(down, top), home)
            assert r.ok, (name, r.reason)
            path = checker.check_path(joint_path(model, home, r.q, checker.path_step_m))
            assert path.ok, (name, t_s, path)


def test_a_real_arms_urdf_with_mesh_links_and_no_tool0_serves_as_the_sites_robot(tmp_path):
    """A user's own arm (pybullet's KUKA iiwa: mesh links, no tool0, no gripper) named in a scene: its tool is
    its last link, it is drawn and rendered from its joints, and a Move robot plan is made for it."""
    import shutil
    from pathlib import Path

    pybullet_data = pytest.importorskip("pybullet_data")
    from app.db import Database, seed_from_scene
    from app.robot.cell import obstacles_of
    from app.robot.setup import open_robot
    from app.scene import default_scene_path, load_scene
    from app.workflows import Site

    shutil.copytree(Path(pybullet_data.getDataPath()) / "kuka_iiwa", tmp_path / "kuka_iiwa")
    d = json.loads((default_scene_path() / "scene.json").read_text())
    for v in d["cameras"]:
        v.pop("video", None)
    d["robot"] = {
        "urdf": "kuka_iiwa/model.urdf",
        "T_world_base": {"xyz": [-0.55, 0.0, 0.0], "rpy_deg": [0, 0, 0]},
        "home_deg": {"lbr_iiwa_joint_2": 30, "lbr_iiwa_joint_4": -60, "lbr_iiwa_joint_6": 60},
    }
    (tmp_path / "scene.json").write_text(json.dumps(d))
    scene = load_scene(tmp_path)
    robot = open_robot(scene)
    try:
        assert robot.cell.model.tool == "lbr_iiwa_link_7" and robot.cell.finger is None
        assert len(robot.world.bodies_at(0.0)) > len(scene.bodies)  # its links are rendered
        db = Database.open(tmp_path / "site.sqlite")
        seed_from_scene(db, scene)
        site = Site(scene, db, robot=robot.cell, frames=None)
        plan = robot.cell.plan_approach(
            np.array([-0.1, -0.2, 0.0]), np.array([0.0, 0.0, 1.0]), 0.1, obstacles_of(site.objects())
        )
        assert plan.ok, plan.reason
        db.close()
    finally:
        robot.close()
