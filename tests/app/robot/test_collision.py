"""The collision check: paths through an object refused naming it, thin obstacles between samples not
missed, margins, self-collision, and the conservative advancement against a sample-by-sample check."""

import numpy as np
import pytest

from app.robot.collision import CollisionChecker, Contact
from app.robot.fcl_shapes import fcl_parts
from app.robot.urdf import load_robot
from app.scene import default_scene_path
from core.brep import BRep
from core.robot import joint_path
from core.transforms import make_T, rot_z

ARM = load_robot(default_scene_path() / "arm.urdf")
SWEEP_FROM = np.array([-1.0, -0.3, 0.3, -1.57, -1.57, 0.0, 0.03])  # the arm stretched forward, low
SWEEP_TO = np.array([1.0, -0.3, 0.3, -1.57, -1.57, 0.0, 0.03])


def forearm_middle(pan: float) -> np.ndarray:
    q = SWEEP_FROM.copy()
    q[0] = pan
    F = ARM.forward(q)
    return (F["forearm_link"] @ [0, 0, 0.2, 1])[:3]


@pytest.fixture(scope="module")
def checker():
    return CollisionChecker(ARM, np.eye(4))


def test_a_path_through_a_box_is_refused_naming_the_box(checker):
    c = forearm_middle(0.0)
    checker.set_obstacles([("crate", BRep.box(0.1, 0.1, 0.6), make_T(np.eye(3), [c[0], c[1], c[2] - 0.3]), 0.01)])
    Q = joint_path(ARM, SWEEP_FROM, SWEEP_TO, checker.path_step_m)
    assert checker.check(Q[0]) == [] and checker.check(Q[-1]) == []
    result = checker.check_path(Q)
    assert not result.ok and result.other == "crate" and result.link in ARM.links
    assert 0 < result.index < len(Q) // 2  # met on the way in, before the pan reaches 0
    assert result.distance_m <= 0.01 and result.samples == result.index + 1
    assert any(contact.other == "crate" for contact in checker.check(Q[result.index]))


def test_the_same_path_with_the_box_moved_away_passes(checker):
    c = forearm_middle(0.0)
    checker.set_obstacles([("crate", BRep.box(0.1, 0.1, 0.6), make_T(np.eye(3), [c[0] + 1.5, c[1], c[2] - 0.3]), 0.01)])
    result = checker.check_path(joint_path(ARM, SWEEP_FROM, SWEEP_TO, checker.path_step_m))
    assert result.ok and result.index == -1 and result.samples > 100


def test_the_step_is_half_the_thinnest_link(checker):
    thinnest = min(s.thickness_m for shapes in ARM.collision_shapes.values() for s in shapes)
    assert thinnest == pytest.approx(0.015)  # the fingers
    assert checker.path_step_m == pytest.approx(thinnest / 2)


@pytest.mark.parametrize("gap", [1, 2, 3, 4])
def test_a_thin_obstacle_between_coarse_samples_is_not_missed(checker, gap):
    """A 2 × 2 cm bar across the forearm's sweep, halfway between two samples of a coarse path (which misses
    it): the path sampled at the checker's step (half the thinnest link) catches it."""
    coarse = joint_path(ARM, SWEEP_FROM, SWEEP_TO, 0.5)
    pan = 0.5 * (coarse[gap, 0] + coarse[gap + 1, 0])
    heading = rot_z(pan)
    c = forearm_middle(pan)
    bar = BRep.box(0.1, 0.02, 0.02)  # along the forearm, 2 cm thick across its way
    checker.set_obstacles([("bar", bar, make_T(heading, c - [0, 0, 0.01]), 0.0)])
    assert checker.check_path(coarse).ok  # the coarse samples fall on either side of the bar
    fine = joint_path(ARM, SWEEP_FROM, SWEEP_TO, checker.path_step_m)
    result = checker.check_path(fine)
    assert not result.ok and result.other == "bar"


def test_advancement_finds_the_first_contact_a_sample_by_sample_check_finds(checker):
    rng = np.random.default_rng(0)
    scene = [
        ("table", BRep.box(1.6, 1.6, 0.04), make_T(np.eye(3), [0, 0, -0.04]), 0.01),
        ("post", BRep.cylinder(0.04, 0.6), make_T(np.eye(3), [0.45, 0.3, 0.0]), 0.02),
        ("crate", BRep.box(0.2, 0.15, 0.25), make_T(rot_z(0.4), [0.3, -0.45, 0.0]), 0.01),
    ]
    checker.set_obstacles(scene)
    agreed = 0
    for _ in range(12):
        q0 = np.append(rng.uniform(-np.pi, np.pi, 6), 0.03)
        q1 = np.append(rng.uniform(-np.pi, np.pi, 6), 0.03)
        Q = joint_path(ARM, q0, q1, checker.path_step_m)
        first = next((k for k, q in enumerate(Q) if checker.check(q)), -1)
        assert checker.check_path(Q).index == first
        agreed += first >= 0
    assert agreed >= 3  # the paths do meet things


def test_margins_count_contacts_before_touching(checker):
    q = SWEEP_FROM.copy()
    q[0] = 0.0
    # a block 5 mm beyond the fingertips (tool0 lies between them; the gripper points along its z)
    T = ARM.tool_pose(q) @ make_T(np.eye(3), [0, 0, 0.005])
    checker.set_obstacles([("block", BRep.box(0.1, 0.1, 0.1), T, 0.0)])
    assert checker.check(q) == []
    checker.set_obstacles([("block", BRep.box(0.1, 0.1, 0.1), T, 0.01)])
    contacts = checker.check(q)
    assert sorted(c.link for c in contacts) == ["finger_left_link", "finger_right_link"]
    assert all(c.other == "block" and c.distance_m == pytest.approx(0.005, abs=1e-6) for c in contacts)


def test_a_folded_arm_collides_with_itself(checker):
    checker.set_obstacles([])
    q = np.array([0.0, -1.57, 3.1, -1.57, -1.57, 0.0, 0.03])  # the forearm folded back onto the upper arm
    contacts = checker.check(q)
    assert all(isinstance(c, Contact) and c.distance_m <= 0 for c in contacts)
    pairs = {frozenset((c.link, c.other)) for c in contacts}
    assert frozenset(("upper_arm_link", "wrist_1_link")) in pairs  # the wrist folded into the upper arm
    assert all(p not in checker.ignored_pairs for p in pairs)
    assert [c.distance_m for c in contacts] == sorted(c.distance_m for c in contacts)  # deepest first
    assert checker.check(SWEEP_FROM) == []  # stretched: no contact
    # joined links are ignored; this arm has no pair that always touches
    assert frozenset(("forearm_link", "upper_arm_link")) in checker.ignored_pairs
    assert checker.always_touching == frozenset()


def test_pairs_always_in_contact_are_found_and_ignored():
    """A link welded into its grandparent (a collar around the shoulder) touches it in every configuration."""
    from core.robot import Joint, LinkShape, RobotModel, cylinder_shape

    at = lambda xyz=(0, 0, 0): make_T(np.eye(3), xyz)  # noqa: E731
    joints = [
        Joint("j1", "revolute", "base", "arm", at((0, 0, 0.1)), (0, 0, 1), -np.pi, np.pi),
        Joint("j2", "revolute", "arm", "hand", at((0, 0, 0.3)), (0, 0, 1), -1, 1),  # about the same axis
    ]
    shapes = {
        "base": (cylinder_shape(0.1, 0.1, at((0, 0, 0.05))),),
        "arm": (cylinder_shape(0.03, 0.3, at((0, 0, 0.15))),),
        "hand": (LinkShape(BRep.box(0.05, 0.05, 0.1), at()), cylinder_shape(0.12, 0.02, at((0, 0, -0.3)))),
    }
    robot = RobotModel("collar", joints, shapes, shapes)
    checker = CollisionChecker(robot, np.eye(4), n_samples=50)
    assert frozenset(("base", "hand")) in checker.always_touching
    assert checker.check([0.3, 0.2]) == []


def test_static_links_are_left_out_and_said(checker):
    checker.set_obstacles([("table", BRep.box(1.0, 1.0, 0.04), make_T(np.eye(3), [0, 0, -0.04]), 0.01)])
    assert [(c.link, c.other) for c in checker.static_contacts] == [("base_link", "table")]
    assert checker.check(SWEEP_FROM) == []


@pytest.mark.parametrize(
    "obstacle, match",
    [
        (("a", "not a model", np.eye(4), 0.0), "a BRep model expected"),
        (("a", BRep.box(1, 1, 1), np.eye(3), 0.0), "T_world_obj"),
        (("a", BRep.box(1, 1, 1), np.eye(4), -0.1), "margin_m"),
        (("a", BRep.box(1, 1, 1)), r"\(name, BRep, T_world_obj, margin_m\) expected"),
    ],
)
def test_bad_obstacles_are_refused(checker, obstacle, match):
    with pytest.raises(ValueError, match=match):
        checker.set_obstacles([obstacle])


def test_each_part_becomes_the_fitting_fcl_geometry():
    L_shape = BRep.prism(np.array([[0, 0], [1, 0], [1, 1], [0, 1]]), 0.1).transformed(make_T(rot_z(0.3), [0, 0, 0]))
    concave = BRep.from_faces(
        np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]] + [[x, y, 1] for x, y, _ in
                  [[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]]], dtype=float),
        [(5, 4, 3, 2, 1, 0), (6, 7, 8, 9, 10, 11)] + [(i, (i + 1) % 6, 6 + (i + 1) % 6, 6 + i) for i in range(6)],
    )  # fmt: skip
    kinds = {
        "box": BRep.box(0.2, 0.3, 0.1),
        "cylinder": BRep.cylinder(0.05, 0.2),
        "cone": BRep.cone(0.05, 0.0, 0.2),
        "convex": L_shape,
        "mesh": concave,
    }
    for kind, brep in kinds.items():
        assert [p.kind for p in fcl_parts(brep)] == [kind]
    assert [p.kind for p in fcl_parts(BRep.cone(0.05, 0.02, 0.2))] == ["convex"]
