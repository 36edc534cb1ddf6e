"""Joint-space paths sampled finely enough that no point of the robot jumps more than a given step.

A point p of a link moves, for joint velocities q̇, at ``|ṗ| ≤ Σ_j |q̇_j| · r_j`` over the joints j of
its chain, with r_j the point's distance from joint j's axis (a revolute joint) or 1 (a prismatic
one). ``lever_arms`` bounds r_j for every point of each link, in every configuration: the distance
from the joint's origin to the link's farthest point through the joint offsets along the way (the
triangle inequality). Along a straight joint-space segment from q0 to q1 a point of link l then
moves at most ``C[l] @ |Δq|``; ``joint_path`` cuts the segment into equal steps below
``max_step_m`` each.
"""

from __future__ import annotations

import numpy as np

from .model import RobotModel

__all__ = ["lever_arms", "pair_lever_arms", "joint_path", "step_bound_m"]


def _link_radius(model: RobotModel) -> dict[str, float]:
    """Per link: an upper bound of the distance from its origin to any point of its shapes (drawn or collision)."""
    shapes = {**model.link_shapes}
    for link, items in model.collision_shapes.items():
        shapes[link] = shapes.get(link, ()) + items
    return {k: max((s.radius_about_link_origin() for s in shapes.get(k, ())), default=0.0) for k in model.links}


def _levers(model: RobotModel, link: str, radius: dict[str, float], above: frozenset = frozenset()) -> np.ndarray:
    """(n,): how far a unit move of each actuated joint moves a point of ``link`` at most, counting the joints of
    its chain below the joints ``above`` (indices; the chain of an ancestor link)."""
    row = np.zeros(model.n)
    reach = radius[link]
    for i in reversed(model.chain(link)):  # from the link up towards the base, the reach growing
        if i in above:
            break
        j = model.joints[i]
        drive = model.drive(i)
        if drive is not None:
            k, mult, offset = drive
            row[k] += abs(mult) * (1.0 if j.kind == "prismatic" else reach)
            if j.kind == "prismatic":
                reach += abs(mult) * max(abs(model.lower[k]), abs(model.upper[k])) + abs(offset)
        reach += float(np.linalg.norm(j.T_parent_joint[:3, 3]))
    return row


def lever_arms(model: RobotModel) -> np.ndarray:
    """C (L, n): a point of link ``links[l]`` moves at most ``C[l] @ |Δq|`` (m) for a joint motion Δq (n,)
    along a straight joint-space segment (rad, or m for a prismatic joint), its mimic joints included.

    For each joint j on the link's chain, C adds |multiplier| × (1 for a prismatic joint, else the distance
    from j's origin to the link's farthest point: the joint offsets and strokes after j along the chain
    plus the link's own radius).
    """
    radius = _link_radius(model)
    return np.array([_levers(model, link, radius) for link in model.links])


def pair_lever_arms(model: RobotModel, link_a: str, link_b: str) -> np.ndarray:
    """(n,): the distance between a point of ``link_a`` and one of ``link_b`` changes by at most this @ |Δq|.

    A motion of the joints above both links (their common ancestor's chain) moves them together and
    changes no distance between them: only the joints below it count, each link's own lever arms.
    """
    chain_a, chain_b = model.chain(link_a), model.chain(link_b)
    shared = 0
    while shared < min(len(chain_a), len(chain_b)) and chain_a[shared] == chain_b[shared]:
        shared += 1
    above = frozenset(chain_a[:shared])
    radius = _link_radius(model)
    return _levers(model, link_a, radius, above) + _levers(model, link_b, radius, above)


def step_bound_m(model: RobotModel, q0, q1) -> float:
    """An upper bound (m) of the distance any point of the robot travels along the straight path q0 → q1."""
    dq = model.as_q(q1, "q1") - model.as_q(q0, "q0")
    return float((lever_arms(model) @ np.abs(dq)).max())


def joint_path(model: RobotModel, q0, q1, max_step_m: float) -> np.ndarray:
    """Samples (k, n) of the straight joint-space path from q0 to q1 (both included, k ≥ 2) so that no
    point of any link moves more than ``max_step_m`` (m) between consecutive samples."""
    if not (np.isfinite(max_step_m) and max_step_m > 0):
        raise ValueError(f"max_step_m must be a positive distance in metres, got {max_step_m}")
    q0 = model.as_q(q0, "q0")
    q1 = model.as_q(q1, "q1")
    steps = max(int(np.ceil(step_bound_m(model, q0, q1) / max_step_m)), 1)
    a = np.linspace(0.0, 1.0, steps + 1)[:, None]
    return (1.0 - a) * q0 + a * q1
