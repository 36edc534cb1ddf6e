"""URDF files: the bundled arm's (written by app.robot.arm, loaded by yourdfpy), a real arm's with mesh
links (pybullet's data files, a test dependency), and bad files refused in one line."""

import numpy as np
import pytest

from app import cli
from app.robot.arm import ARM_JOINTS, FINGER_JOINT, arm_urdf
from app.robot.urdf import UrdfError, load_robot
from app.scene import default_scene_path
from core.primitives import Revolution

ARM_FILE = default_scene_path() / "arm.urdf"


def test_the_bundled_file_is_the_arm_text():
    assert ARM_FILE.read_text(encoding="utf-8") == arm_urdf()


def test_the_cli_writes_the_arm(tmp_path, capsys):
    out = tmp_path / "arm.urdf"
    assert cli.main(["robot", "urdf", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == arm_urdf()
    assert cli.main(["robot", "urdf"]) == 0
    assert capsys.readouterr().out == arm_urdf()


def test_the_arm_loads_with_six_joints_a_gripper_and_its_tool():
    m = load_robot(ARM_FILE)
    assert m.joint_names == (*ARM_JOINTS, FINGER_JOINT)
    assert m.tool == "tool0"
    assert m.joint("finger_right_joint").mimic.joint == FINGER_JOINT
    # every link but the tool frame has visual and collision shapes, boxes and cylinders alone
    assert set(m.link_shapes) == set(m.collision_shapes) == set(m.links) - {"tool0"}
    for shapes in m.link_shapes.values():
        for s in shapes:
            assert len(s.brep.vertices) == 8 or (len(s.brep.solids) == 1 and isinstance(s.brep.solids[0], Revolution))


def test_the_arm_reaches_like_a_ur5():
    m = load_robot(ARM_FILE)
    q = np.zeros(m.n)
    q[-1] = 0.02
    F = m.forward(q)
    shoulder = F["upper_arm_link"][:3, 3]
    wrist = F["wrist_3_link"][:3, 3]
    # stretched along x at q = 0: upper arm and forearm 0.817 m, with the wrist's offsets a UR5's 0.85 m reach
    assert wrist[0] - shoulder[0] == pytest.approx(0.425 + 0.39225, abs=1e-9)
    assert abs(wrist[2] - shoulder[2]) < 0.1
    # the fingertips' centre: tool0 between the fingers at their tips, z out of the gripper
    T_g = np.linalg.inv(F["gripper_link"])
    tips = [T_g @ F[f] @ [0, 0, 0.06, 1] for f in ("finger_left_link", "finger_right_link")]
    np.testing.assert_allclose((T_g @ F["tool0"])[:3, 3], np.mean(tips, axis=0)[:3], atol=1e-12)


@pytest.mark.parametrize(
    "text, match",
    [
        ("hello, not XML", "not XML"),
        ("<robot name='r'><link name='a'/>", "not XML"),
        ("<model name='r'/>", "root element is <model>"),
        (
            "<robot name='r'><link name='a'/><link name='b'/><joint name='j' type='fixed'><child link='b'/></joint>"
            "</robot>",
            "joint 'j' has no <parent link=...>",
        ),
        (
            "<robot name='r'><link name='a'/><joint name='j' type='fixed'><parent link='a'/><child link='c'/></joint>"
            "</robot>",
            "child link 'c' is not defined",
        ),
        (
            "<robot name='r'><link name='a'><visual><geometry><mesh filename='package://nowhere/x.stl'/></geometry>"
            "</visual></link><link name='b'/><joint name='j' type='fixed'><parent link='a'/><child link='b'/></joint>"
            "</robot>",
            "mesh file 'package://nowhere/x.stl' not found",
        ),
        (
            "<robot name='r'><link name='a'/><link name='b'/><joint name='j' type='revolute'><parent link='a'/>"
            "<child link='b'/></joint></robot>",
            "needs <limit lower=... upper=...>",
        ),
        (
            "<robot name='r'><link name='a'/><link name='b'/><joint name='j' type='floating'><parent link='a'/>"
            "<child link='b'/></joint></robot>",
            "type 'floating' is not supported",
        ),
        ("<robot name='r'><link name='a'/></robot>", "has no joints"),
    ],
    ids=["not-xml", "truncated", "not-robot", "no-parent", "unknown-link", "no-mesh", "no-limit", "floating", "empty"],
)
def test_bad_urdf_is_refused_in_one_line_naming_the_file(tmp_path, text, match):
    f = tmp_path / "bad.urdf"
    f.write_text(text, encoding="utf-8")
    with pytest.raises(UrdfError, match=match) as caught:
        load_robot(f)
    assert str(caught.value).startswith(str(f)) and "\n" not in str(caught.value)


def test_a_missing_file_is_refused(tmp_path):
    with pytest.raises(UrdfError, match="no such URDF file"):
        load_robot(tmp_path / "none.urdf")


def test_an_unreadable_mesh_is_refused_naming_the_link(tmp_path):
    (tmp_path / "m.stl").write_text("solid nothing\nendsolid nothing\n")
    f = tmp_path / "r.urdf"
    f.write_text(
        "<robot name='r'><link name='a'><collision><geometry><mesh filename='m.stl'/></geometry></collision></link>"
        "<link name='b'/><joint name='j' type='fixed'><parent link='a'/><child link='b'/></joint></robot>"
    )
    with pytest.raises(UrdfError, match="link 'a' collision: .*m.stl"):
        load_robot(f)


def _pybullet_file(name: str):
    data = pytest.importorskip("pybullet_data", reason="pybullet's data files (pip install pybullet) hold real arms")
    from pathlib import Path

    path = Path(data.getDataPath()) / name
    if not path.is_file():
        pytest.skip(f"{name} is not in this pybullet's data files")
    return path


@pytest.mark.parametrize(
    "name, joints, tool",
    [("kuka_iiwa/model.urdf", 7, "lbr_iiwa_link_7"), ("franka_panda/panda.urdf", 8, "panda_grasptarget")],
)
def test_a_real_arm_with_mesh_links_loads_and_gives_link_breps(name, joints, tool):
    m = load_robot(_pybullet_file(name))
    assert m.n == joints and m.tool == tool
    q = np.clip(np.zeros(m.n), m.lower, m.upper)
    placed = m.link_breps(q)
    assert len(placed) >= 8
    for _, brep, T in placed:
        assert len(brep.vertices) > 20 and len(brep.faces) > 10  # a mesh B-Rep, not a primitive
        assert T.shape == (4, 4)
    # the meshes sit where the links are: each link's mesh within 0.3 m of its link's origin
    F = m.forward(q)
    for link, brep, T in placed:
        centre = T[:3, :3] @ brep.vertices.mean(axis=0) + T[:3, 3]
        assert np.linalg.norm(centre - F[link][:3, 3]) < 0.3
    assert len(m.link_breps(q, collision=True)) >= 8
    J = m.jacobian(np.clip(np.full(m.n, 0.3), m.lower, m.upper))
    assert J.shape == (6, m.n) and np.linalg.matrix_rank(J[:, :7]) == 6
