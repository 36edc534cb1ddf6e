"""Robots built by hand for the kinematics tests (no URDF): a planar 2R arm, a UR5-like 6R arm with a
mimic-driven two-finger gripper, both with box and cylinder shapes."""

from __future__ import annotations

import numpy as np

from core.robot import Joint, Mimic, RobotModel, box_shape, cylinder_shape
from core.transforms import make_T, rot_x, rot_y

PI = np.pi


def at(xyz=(0, 0, 0), R=None) -> np.ndarray:
    return make_T(np.eye(3) if R is None else R, xyz)


def planar_2r(l1: float = 0.5, l2: float = 0.3) -> RobotModel:
    """Two revolute joints about z, links along x of lengths l1 and l2; the tool at the second link's end."""
    joints = [
        Joint("j1", "revolute", "base", "link1", at(), (0, 0, 1), -PI, PI),
        Joint("j2", "revolute", "link1", "link2", at((l1, 0, 0)), (0, 0, 1), -PI, PI),
        Joint("tip", "fixed", "link2", "tool0", at((l2, 0, 0))),
    ]
    shapes = {
        "link1": (box_shape((l1, 0.04, 0.04), at((l1 / 2, 0, 0))),),
        "link2": (box_shape((l2, 0.03, 0.03), at((l2 / 2, 0, 0))),),
    }
    return RobotModel("planar", joints, shapes, shapes)


Y = rot_x(PI / 2)  # a cylinder's z axis onto the link's y


def ur_like(**limits) -> RobotModel:
    """A UR5's kinematics (at q = 0 stretched along +x) with a parallel gripper: ``finger_joint`` and its
    mimic; ``limits`` replaces a joint's (lower, upper)."""

    def lim(name, lo, hi):
        return limits.get(name, (lo, hi))

    specs = [
        ("shoulder_pan_joint", "base_link", "shoulder_link", at((0, 0, 0.089159)), (0, 0, 1), (-2 * PI, 2 * PI)),
        ("shoulder_lift_joint", "shoulder_link", "upper_arm_link", at((0, 0.13585, 0), rot_y(PI / 2)), (0, 1, 0),
         (-2 * PI, 2 * PI)),
        ("elbow_joint", "upper_arm_link", "forearm_link", at((0, -0.1197, 0.425)), (0, 1, 0), (-PI, PI)),
        ("wrist_1_joint", "forearm_link", "wrist_1_link", at((0, 0, 0.39225), rot_y(PI / 2)), (0, 1, 0),
         (-2 * PI, 2 * PI)),
        ("wrist_2_joint", "wrist_1_link", "wrist_2_link", at((0, 0.093, 0)), (0, 0, 1), (-2 * PI, 2 * PI)),
        ("wrist_3_joint", "wrist_2_link", "wrist_3_link", at((0, 0, 0.09465)), (0, 1, 0), (-2 * PI, 2 * PI)),
    ]  # fmt: skip
    joints = [Joint(n, "revolute", p, c, T, a, *lim(n, *lu)) for n, p, c, T, a, lu in specs]
    joints += [
        Joint("mount", "fixed", "wrist_3_link", "gripper_link", at((0, 0.0823, 0), rot_x(-PI / 2))),
        Joint("finger_joint", "prismatic", "gripper_link", "finger_left", at((0, 0, 0.05)), (0, 1, 0), 0.001, 0.04),
        Joint("finger_right_joint", "prismatic", "gripper_link", "finger_right", at((0, 0, 0.05)), (0, -1, 0),
              0.001, 0.04, mimic=Mimic("finger_joint")),
        Joint("tool0_joint", "fixed", "gripper_link", "tool0", at((0, 0, 0.11))),
    ]  # fmt: skip
    shapes = {
        "base_link": (cylinder_shape(0.075, 0.086, at((0, 0, 0.043))),),
        "shoulder_link": (cylinder_shape(0.06, 0.12, at()),),
        "upper_arm_link": (cylinder_shape(0.045, 0.425, at((0, 0, 0.2125))),),
        "forearm_link": (cylinder_shape(0.038, 0.39225, at((0, 0, 0.196))),),
        "wrist_1_link": (cylinder_shape(0.04, 0.12, at((0, 0.093, 0))),),
        "wrist_2_link": (cylinder_shape(0.04, 0.1, at((0, 0, 0.09465), Y)),),
        "wrist_3_link": (cylinder_shape(0.04, 0.03, at((0, 0.0673, 0), Y)),),
        "gripper_link": (box_shape((0.05, 0.13, 0.05), at((0, 0, 0.025))),),
        "finger_left": (box_shape((0.02, 0.015, 0.06), at((0, 0.0075, 0.03))),),
        "finger_right": (box_shape((0.02, 0.015, 0.06), at((0, -0.0075, 0.03))),),
    }
    return RobotModel("ur_like", joints, shapes, shapes)


def random_q(model: RobotModel, rng: np.random.Generator, span: float = PI) -> np.ndarray:
    """Joint positions within the limits, revolute ones within ±span."""
    lo = np.maximum(model.lower, -span)
    hi = np.minimum(model.upper, span)
    return rng.uniform(lo, hi)


def link_points(model: RobotModel, Q: np.ndarray) -> np.ndarray:
    """Points (k, P, 3), base frame, on every link shape (their support points) at k configurations Q (k, n)."""
    F = model.forward_many(Q)
    out = []
    for i, link in enumerate(model.links):
        for shape in model.link_shapes.get(link, ()):
            X = shape.brep.support_points(24) @ shape.T_link_shape[:3, :3].T + shape.T_link_shape[:3, 3]
            out.append(np.einsum("kij,pj->kpi", F[:, i, :3, :3], X) + F[:, i, None, :3, 3])
    return np.concatenate(out, axis=1)
