"""The robot: its kinematic tree from a URDF, forward and inverse kinematics, joint paths (pure numpy).

* ``RobotModel`` (``model``): joints and links, ``forward`` (every link's pose), ``tool_pose``,
  ``jacobian`` (geometric, at the TCP, base frame, rows v then ω), limits, and the links' shapes as
  B-Reps (``link_breps``: what the overlay, the renderer and the collision check place in the world).
* ``solve_ik`` (``ik``): bounded least squares from several seeds, joint limits held, the solution
  nearest the current joints preferred; a refusal says why (out of reach, or the joint limits).
* ``joint_path`` (``path``): a straight joint-space motion sampled so that no point of the robot moves
  more than a given step between samples (what makes a sampled collision check miss nothing thin).
"""

from .ik import IkResult, reach_m, solve_ik
from .model import JOINT_KINDS, Joint, LinkShape, Mimic, RobotModel
from .path import joint_path, lever_arms, pair_lever_arms, step_bound_m
from .shapes import box_shape, cylinder_shape, mesh_shape, sphere_shape

__all__ = [
    "RobotModel",
    "Joint",
    "Mimic",
    "LinkShape",
    "JOINT_KINDS",
    "IkResult",
    "solve_ik",
    "reach_m",
    "joint_path",
    "lever_arms",
    "pair_lever_arms",
    "step_bound_m",
    "box_shape",
    "cylinder_shape",
    "sphere_shape",
    "mesh_shape",
]
