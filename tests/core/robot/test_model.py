"""The kinematic tree: forward kinematics against hand-computed poses, the Jacobian against finite
differences, limits, shapes placed in the world, and malformed trees refused."""

import numpy as np
import pytest

from core.robot import Joint, Mimic, RobotModel
from core.transforms import log_so3, make_T, rot_z
from tests.core.robot.arms import PI, at, planar_2r, random_q, ur_like


def test_planar_forward_matches_the_hand_computed_tip():
    m = planar_2r(0.5, 0.3)
    for q1, q2 in [(0.0, 0.0), (PI / 2, 0.0), (0.3, -1.1), (-2.0, 2.5)]:
        T = m.tool_pose([q1, q2])
        p = [0.5 * np.cos(q1) + 0.3 * np.cos(q1 + q2), 0.5 * np.sin(q1) + 0.3 * np.sin(q1 + q2), 0.0]
        np.testing.assert_allclose(T[:3, 3], p, atol=1e-12)
        np.testing.assert_allclose(T[:3, :3], rot_z(q1 + q2), atol=1e-12)
        np.testing.assert_allclose(m.forward([q1, q2])["link2"][:3, 3], p - 0.3 * T[:3, 0], atol=1e-12)


def test_ur_like_arm_at_zero_is_stretched_along_x_with_its_offsets():
    """UR5 at q = 0: x = a2 + a3, y = the shoulder, elbow, wrist and tool offsets, z = d1 − d5."""
    m = ur_like()
    q = np.zeros(m.n)
    q[-1] = 0.02
    T = m.tool_pose(q)
    y = 0.13585 - 0.1197 + 0.093 + 0.0823 + 0.11
    np.testing.assert_allclose(T[:3, 3], [0.425 + 0.39225, y, 0.089159 - 0.09465])
    np.testing.assert_allclose(T[:3, 2], [0, 1, 0], atol=1e-12)  # the gripper points along the wrist's y


def test_ur_like_arm_upright_puts_the_wrist_above_the_shoulder():
    m = ur_like()
    q = np.array([0, -PI / 2, 0, 0, 0, 0, 0.01])
    p = m.forward(q)["wrist_1_link"][:3, 3]
    np.testing.assert_allclose(p, [0, 0.13585 - 0.1197, 0.089159 + 0.425 + 0.39225], atol=1e-12)


def test_prismatic_and_mimic_fingers_open_symmetrically():
    m = ur_like()
    q = np.array([0.3, -1.0, 1.2, -0.4, 0.7, 0.2, 0.03])
    F = m.forward(q)
    G = F["gripper_link"]
    left = np.linalg.solve(G, F["finger_left"])[:3, 3]
    right = np.linalg.solve(G, F["finger_right"])[:3, 3]
    np.testing.assert_allclose(left, [0, 0.03, 0.05], atol=1e-12)
    np.testing.assert_allclose(right, [0, -0.03, 0.05], atol=1e-12)


def test_mimic_multiplier_and_offset():
    joints = [
        Joint("a", "revolute", "base", "l1", at(), (0, 0, 1), -PI, PI),
        Joint("b", "revolute", "l1", "l2", at((1, 0, 0)), (0, 0, 1), mimic=Mimic("a", -2.0, 0.1)),
        Joint("t", "fixed", "l2", "tip", at((1, 0, 0))),
    ]
    m = RobotModel("mimic", joints)
    assert m.joint_names == ("a",)
    T = m.tool_pose([0.4])
    assert np.isclose(np.arctan2(T[1, 0], T[0, 0]), 0.4 + (-2.0 * 0.4 + 0.1))
    J = m.jacobian([0.4])
    eps = 1e-7
    np.testing.assert_allclose(J[:3, 0], (m.tool_pose([0.4 + eps])[:3, 3] - T[:3, 3]) / eps, atol=1e-6)


@pytest.mark.parametrize("make", [ur_like, planar_2r], ids=["ur_like", "planar"])
def test_jacobian_matches_finite_differences(make):
    m = make()
    rng = np.random.default_rng(0)
    eps = 1e-6
    for _ in range(10):
        q = random_q(m, rng)
        J = m.jacobian(q)
        assert J.shape == (6, m.n)
        for i in range(m.n):
            dq = np.zeros(m.n)
            dq[i] = eps
            Tp, Tm = m.tool_pose(q + dq), m.tool_pose(q - dq)
            v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * eps)
            w = log_so3(Tp[:3, :3] @ Tm[:3, :3].T) / (2 * eps)
            np.testing.assert_allclose(J[:3, i], v, atol=1e-7)
            np.testing.assert_allclose(J[3:, i], w, atol=1e-7)


def test_batched_forward_agrees_with_one_at_a_time():
    m = ur_like()
    Q = np.array([random_q(m, np.random.default_rng(k)) for k in range(5)])
    F = m.forward_many(Q)
    assert F.shape == (5, len(m.links), 4, 4)
    for k in range(5):
        one = m.forward(Q[k])
        for i, link in enumerate(m.links):
            np.testing.assert_allclose(F[k, i], one[link], atol=1e-14)
    np.testing.assert_allclose(m.tool_poses(Q)[3], m.tool_pose(Q[3]), atol=1e-14)
    T, J = m.poses_and_jacobians(Q)
    assert T.shape == (5, 4, 4) and J.shape == (5, 6, m.n)
    np.testing.assert_allclose(J[2], m.jacobian(Q[2]), atol=1e-14)


def test_within_limits_names_the_joint_and_how_far():
    m = ur_like()
    q = np.zeros(m.n)
    q[-1] = 0.02
    assert m.within_limits(q) is None
    q[2] = PI + np.radians(10)
    assert m.within_limits(q) == "joint elbow_joint at 190.0 ° is 10.0 ° beyond its upper limit 180.0 °"
    q[2] = 0.0
    q[-1] = 0.05
    assert "finger_joint at 50.0 mm is 10.0 mm beyond its upper limit 40.0 mm" in m.within_limits(q)


def test_bad_joint_values_are_refused():
    m = ur_like()
    with pytest.raises(ValueError, match="7 joint values"):
        m.tool_pose(np.zeros(6))
    q = np.zeros(m.n)
    q[1] = np.nan
    with pytest.raises(ValueError, match="shoulder_lift_joint"):
        m.forward(q)


def test_link_breps_place_the_shapes_in_the_world():
    m = ur_like()
    T_world_base = make_T(rot_z(0.5), [-0.4, 0.1, 0.0])
    q = np.array([0.2, -1.2, 1.0, -0.5, 0.3, 0.1, 0.02])
    placed = m.link_breps(q, T_world_base)
    assert [name for name, _, _ in placed] == [k for k in m.links if k in m.link_shapes]
    name, brep, T = placed[0]
    assert name == "base_link"
    # URDF centres a cylinder; BRep.cylinder stands on its frame: the base cylinder's bottom is at the base
    np.testing.assert_allclose(T, T_world_base, atol=1e-12)
    F = m.forward(q)
    for name, _, T in placed:
        shape = m.link_shapes[name][0]
        np.testing.assert_allclose(T, T_world_base @ F[name] @ shape.T_link_shape, atol=1e-12)


def test_structure_queries():
    m = ur_like()
    assert m.tool == "tool0"
    assert m.static_links() == ("base_link",)
    assert frozenset(("forearm_link", "wrist_1_link")) in m.adjacent_links()
    assert list(m.moves_tool()) == [True] * 6 + [False]
    assert planar_2r().tool == "tool0"


def test_the_default_tool_is_the_deepest_link_no_finger_moves():
    joints = [
        Joint("a", "revolute", "base", "arm", at(), (0, 0, 1), -1, 1),
        Joint("f", "prismatic", "arm", "finger", at((0, 0, 1)), (1, 0, 0), 0, 0.1),
        Joint("g", "fixed", "arm", "grasp", at((0, 0, 1))),
    ]
    assert RobotModel("r", joints).tool == "grasp"
    gantry = [
        Joint("x", "prismatic", "base", "carriage", at(), (1, 0, 0), 0, 1),
        Joint("z", "prismatic", "carriage", "head", at(), (0, 0, 1), 0, 1),
    ]
    assert RobotModel("gantry", gantry).tool == "head"


@pytest.mark.parametrize(
    "joints, match",
    [
        ([Joint("a", "revolute", "b", "c", at(), (0, 0, 1)), Joint("b", "revolute", "x", "c", at(), (0, 0, 1))],
         "child of two joints"),
        ([Joint("a", "fixed", "b", "c"), Joint("d", "fixed", "e", "f")], "one root"),
        ([Joint("a", "fixed", "b", "c"), Joint("d", "fixed", "c", "b")], "root"),
        ([Joint("a", "revolute", "b", "c", at(), (0, 0, 1), mimic=Mimic("zz"))], "mimics 'zz'"),
        ([Joint("a", "fixed", "b", "c"), Joint("a", "fixed", "c", "d")], "share a name"),
        ([], "no joints"),
    ],
)  # fmt: skip
def test_malformed_trees_are_refused(joints, match):
    with pytest.raises(ValueError, match=match):
        RobotModel("bad", joints)


def test_malformed_joints_are_refused():
    with pytest.raises(ValueError, match="kind"):
        Joint("a", "floating", "b", "c")
    with pytest.raises(ValueError, match="axis"):
        Joint("a", "revolute", "b", "c", at(), (0, 0, 0))
    with pytest.raises(ValueError, match="lower ≤ upper"):
        Joint("a", "revolute", "b", "c", at(), (0, 0, 1), 1.0, -1.0)


def test_with_tool_moves_the_tcp_and_keeps_the_rest():
    m = ur_like()
    g = m.with_tool("gripper_link", at((0, 0, 0.2)))
    q = np.array([0.1, -1.0, 1.0, -0.5, 0.3, 0.2, 0.02])
    np.testing.assert_allclose(g.tool_pose(q), m.forward(q)["gripper_link"] @ at((0, 0, 0.2)))
    assert g.joint_names == m.joint_names and g.link_shapes is not None
    with pytest.raises(ValueError, match="no tool link 'hand'"):
        m.with_tool("hand")
