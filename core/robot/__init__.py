"""The robot: its kinematic tree from a URDF, forward and inverse kinematics, joint paths (pure numpy).

* ``RobotModel`` (``model``): joints and links, ``forward`` (every link's pose), ``tool_pose``,
  ``jacobian`` (geometric, at the TCP, base frame, rows v then ω), limits, and the links' shapes as
  B-Reps (``link_breps``: what the overlay, the renderer and the collision check place in the world).
* ``solve_ik`` (``ik``): bounded least squares from several seeds, joint limits held, the solution
  nearest the current joints preferred; a refusal says why (out of reach, or the joint limits).
* ``joint_path`` (``path``): a straight joint-space motion sampled so that no point of the robot moves
  more than a given step between samples (what makes a sampled collision check miss nothing thin).

Our own kinematics, not Pinocchio's, chosen by ``bench/robot.py`` (the workcell's arm, one core of
this shared machine, load ≈ 0.3): Pinocchio is far faster per call (tool pose 1.6 µs against our
57 µs; Jacobian 0.9 µs against 98 µs; our batch of 200 configurations costs 1.0 µs each) and its
documented closed-loop IK takes 1.5 ms per target against our 13.8 ms (medians over 100 reachable
targets from home). But the time that matters is the preview of a click — IK, the sampled joint path
and its collision check — and that takes 33 ms (median; 42 ms at most over 12 workcell targets)
with ours, a third of the 100 ms target, of which IK is 8–15 ms: Pinocchio would save about 10 ms
and change nothing the operator sees. Ours solves 100 % of the targets within the joint limits (8
seeds in one numpy batch) where the CLIK, limits by clipping, solved 94 % from the same 8 starts;
its batches give the collision check every sampled configuration's link poses in one pass; and core
stays numpy and scipy (Pinocchio brings eigenpy and a Boost build through cmeel). The bench prints
our tool pose within 7e-16 of Pinocchio's on the same URDF, and keeps Pinocchio as the anchor.
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
