"""The bundled workcell's arm: a 6-axis arm with a two-finger gripper, as URDF text.

Its kinematics are a UR5's (Universal Robots' published offsets: shoulder 89.2 mm above the base,
upper arm 425 mm, forearm 392.2 mm, wrist offsets 109.2 / 94.7 / 82.3 mm; at q = 0 the arm lies
stretched along the base's +x), so the reach is the UR5's 0.85 m from the shoulder to the wrist.
Its links are boxes and cylinders (visual and collision alike), which the database's B-Rep drawing,
ray casting and collision handle as they are. The gripper is a parallel gripper: one prismatic joint
``finger_joint`` (each finger's travel from the centre, 1–60 mm: a 2–120 mm opening, enough for the
workcell's 9 × 9.4 cm box) and a second finger mimicking it. ``tool0`` sits between the fingertips,
z out of the gripper (the approach direction). The gripper's body is 17 cm wide, its fingers 1.5 cm
thick: the thinnest links, which set the collision check's sampling step (7.5 mm).

``arm_urdf()`` is the text; ``scenes/workcell/arm.urdf`` holds it (``mcit robot urdf --out FILE``
writes it again).
"""

from __future__ import annotations

import math

__all__ = ["arm_urdf", "ARM_NAME", "ARM_JOINTS", "FINGER_JOINT"]

ARM_NAME = "mcit_arm"
ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
FINGER_JOINT = "finger_joint"

_PI = math.pi
_Y = (_PI / 2, 0.0, 0.0)  # rpy turning a URDF cylinder's z axis onto the link's y axis

# link: [(kind, size, xyz, rpy)], kind "box" (size x, y, z) or "cylinder" (radius, length); metres
_LINKS = {
    "base_link": [("cylinder", (0.075, 0.086), (0, 0, 0.043), (0, 0, 0))],
    "shoulder_link": [
        ("cylinder", (0.06, 0.12), (0, 0, 0), (0, 0, 0)),
        ("cylinder", (0.06, 0.09), (0, 0.045, 0), _Y),
    ],
    "upper_arm_link": [
        ("cylinder", (0.06, 0.1), (0, 0, 0), _Y),
        ("cylinder", (0.045, 0.425), (0, 0, 0.2125), (0, 0, 0)),
        ("cylinder", (0.055, 0.15), (0, -0.045, 0.425), _Y),
    ],
    "forearm_link": [
        ("cylinder", (0.038, 0.39225), (0, 0, 0.196125), (0, 0, 0)),
        ("cylinder", (0.04, 0.11), (0, 0.025, 0.39225), _Y),
    ],
    "wrist_1_link": [("cylinder", (0.04, 0.12), (0, 0.093, 0), (0, 0, 0))],
    "wrist_2_link": [("cylinder", (0.04, 0.1), (0, 0, 0.09465), _Y)],
    "wrist_3_link": [("cylinder", (0.04, 0.03), (0, 0.0673, 0), _Y)],
    "gripper_link": [("box", (0.05, 0.17, 0.05), (0, 0, 0.025), (0, 0, 0))],
    "finger_left_link": [("box", (0.02, 0.015, 0.06), (0, 0.0075, 0.03), (0, 0, 0))],
    "finger_right_link": [("box", (0.02, 0.015, 0.06), (0, -0.0075, 0.03), (0, 0, 0))],
    "tool0": [],
}

# joint: (type, parent, child, xyz, rpy, axis, (lower, upper, velocity) or None, mimic or None)
_JOINTS = [
    ("shoulder_pan_joint", "revolute", "base_link", "shoulder_link", (0, 0, 0.089159), (0, 0, 0), (0, 0, 1),
     (-2 * _PI, 2 * _PI, _PI), None),
    ("shoulder_lift_joint", "revolute", "shoulder_link", "upper_arm_link", (0, 0.13585, 0), (0, _PI / 2, 0),
     (0, 1, 0), (-2 * _PI, 2 * _PI, _PI), None),
    ("elbow_joint", "revolute", "upper_arm_link", "forearm_link", (0, -0.1197, 0.425), (0, 0, 0), (0, 1, 0),
     (-_PI, _PI, _PI), None),
    ("wrist_1_joint", "revolute", "forearm_link", "wrist_1_link", (0, 0, 0.39225), (0, _PI / 2, 0), (0, 1, 0),
     (-2 * _PI, 2 * _PI, 2 * _PI), None),
    ("wrist_2_joint", "revolute", "wrist_1_link", "wrist_2_link", (0, 0.093, 0), (0, 0, 0), (0, 0, 1),
     (-2 * _PI, 2 * _PI, 2 * _PI), None),
    ("wrist_3_joint", "revolute", "wrist_2_link", "wrist_3_link", (0, 0, 0.09465), (0, 0, 0), (0, 1, 0),
     (-2 * _PI, 2 * _PI, 2 * _PI), None),
    ("gripper_mount", "fixed", "wrist_3_link", "gripper_link", (0, 0.0823, 0), (-_PI / 2, 0, 0), None, None, None),
    ("finger_joint", "prismatic", "gripper_link", "finger_left_link", (0, 0, 0.05), (0, 0, 0), (0, 1, 0),
     (0.001, 0.06, 0.1), None),
    ("finger_right_joint", "prismatic", "gripper_link", "finger_right_link", (0, 0, 0.05), (0, 0, 0), (0, -1, 0),
     (0.001, 0.06, 0.1), "finger_joint"),
    ("tool0_joint", "fixed", "gripper_link", "tool0", (0, 0, 0.11), (0, 0, 0), None, None, None),
]  # fmt: skip


def _v(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


def _geometry(kind: str, size) -> str:
    if kind == "box":
        return f'<box size="{_v(size)}"/>'
    return f'<cylinder radius="{size[0]:.9g}" length="{size[1]:.9g}"/>'


def _link(name: str, shapes) -> list[str]:
    if not shapes:
        return [f'  <link name="{name}"/>']
    out = [f'  <link name="{name}">']
    for element in ("visual", "collision"):
        for kind, size, xyz, rpy in shapes:
            out += [
                f"    <{element}>",
                f'      <origin xyz="{_v(xyz)}" rpy="{_v(rpy)}"/>',
                f"      <geometry>{_geometry(kind, size)}</geometry>",
                *(['      <material name="robot_grey"/>'] if element == "visual" else []),
                f"    </{element}>",
            ]
    return out + ["  </link>"]


def _joint(name, kind, parent, child, xyz, rpy, axis, limit, mimic) -> list[str]:
    out = [
        f'  <joint name="{name}" type="{kind}">',
        f'    <parent link="{parent}"/>',
        f'    <child link="{child}"/>',
        f'    <origin xyz="{_v(xyz)}" rpy="{_v(rpy)}"/>',
    ]
    if axis is not None:
        out.append(f'    <axis xyz="{_v(axis)}"/>')
    if limit is not None:
        lo, hi, vel = limit
        effort = 50.0 if kind == "prismatic" else 150.0
        out.append(f'    <limit lower="{lo:.9g}" upper="{hi:.9g}" velocity="{vel:.9g}" effort="{effort:g}"/>')
    if mimic is not None:
        out.append(f'    <mimic joint="{mimic}" multiplier="1" offset="0"/>')
    return out + ["  </joint>"]


def arm_urdf() -> str:
    """The bundled arm's URDF (text, ends with a newline)."""
    lines = [
        '<?xml version="1.0"?>',
        "<!-- The mcit workcell's arm: a UR5's kinematics, links of boxes and cylinders, a two-finger gripper.",
        "     Written by app/robot/arm.py (mcit robot urdf); edit that file, not this one. -->",
        f'<robot name="{ARM_NAME}">',
        '  <material name="robot_grey"><color rgba="0.55 0.57 0.6 1"/></material>',
    ]
    for name, shapes in _LINKS.items():
        lines += _link(name, shapes)
    for joint in _JOINTS:
        lines += _joint(*joint)
    return "\n".join([*lines, "</robot>"]) + "\n"
