"""Inverse kinematics: joint positions that put the tool at a target pose, within the joint limits.

Minimises ``|p(q) − p_t|² + ℓ² |log(R(q) R_tᵀ)|²`` subject to ``lower ≤ q ≤ upper`` by a projected
Levenberg–Marquardt descent (Marquardt's scaled damping; a joint resting on a limit that the gradient
pushes further is held for the step; steps clipped to the limits) with the analytic Jacobian: the
geometric one, its rotation rows mapped through the inverse left Jacobian of SO(3). It runs from
several seeds at once, as one batch of numpy arrays (a batch of 8 costs about as much as one): q0
first, then seeded random joint positions within the limits. Joints that do not move the tool (a
gripper's fingers) stay at q0. Among the seeds that reach the target the solution nearest q0 is
returned, nearest meaning the least travel of the robot's points along the straight joint path
from q0 (the bound of ``core.robot.path``: a turn of the shoulder counts more than one of the wrist),
each revolute joint also tried whole turns away when its limits allow. ℓ
(``rot_scale_m``) weighs a radian of orientation against metres of position.

When none reaches it, the result says why: out of reach (farther than the arm's longest stretch, or
no descent reaches it even without the limits) or the joint limits (a descent without them reaches
it: the joint it puts beyond its limit is named).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..transforms import check_T, rotation_angle
from .model import RobotModel
from .path import lever_arms

__all__ = ["IkResult", "solve_ik", "reach_m"]


@dataclass(frozen=True)
class IkResult:
    """q : array, shape (n,), the solution (or, when not ok, the nearest pose found within the limits).
    ok : the target is reached within the tolerances. position_error_m, rotation_error_rad : how far the
    tool at q is from the target. reason : "" when ok, else one line saying why not. alternatives :
    array, shape (m, n), the other distinct solutions found, nearest q0 first (a caller whose first
    choice collides tries the next)."""

    q: np.ndarray
    ok: bool
    position_error_m: float
    rotation_error_rad: float
    reason: str = ""
    alternatives: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def _log_so3_many(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (k, 3) of rotations (k, 3, 3), accurate at every angle (``core.transforms.log_so3``)."""
    w = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    cos_t = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arctan2(0.5 * np.linalg.norm(w, axis=1), cos_t)
    small = theta < 1e-6
    factor = np.where(small, 0.5, theta / (2.0 * np.sin(np.where(small, 1.0, theta))))
    r = factor[:, None] * w
    for k in np.flatnonzero(np.pi - theta <= 1e-3):  # the antisymmetric part vanishes: axis from the symmetric part
        S = 0.5 * (R[k] + R[k].T)
        A = (S - cos_t[k] * np.eye(3)) / (1.0 - cos_t[k])
        axis = A[:, int(np.argmax(np.diag(A)))]
        axis = axis / np.linalg.norm(axis)
        r[k] = theta[k] * (axis if w[k] @ axis >= 0 else -axis)
    return r


def _inv_left_jacobians(phi: np.ndarray) -> np.ndarray:
    """J_l⁻¹(φ) (k, 3, 3) of SO(3) for rotation vectors φ (k, 3): d log(exp(δ) R) = J_l⁻¹(log R) δ."""
    theta = np.linalg.norm(phi, axis=1)
    safe = np.where(theta < 1e-4, 1.0, theta)
    c = np.where(theta < 1e-4, 1.0 / 12.0, 1.0 / safe**2 - 1.0 / (2.0 * safe * np.tan(safe / 2.0)))
    K = np.zeros((len(phi), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -phi[:, 2], phi[:, 1], -phi[:, 0]
    K -= np.transpose(K, (0, 2, 1))
    return np.eye(3) - 0.5 * K + c[:, None, None] * (K @ K)


def reach_m(model: RobotModel) -> tuple[np.ndarray, float]:
    """(origin (3,) of the first moving joint in the base, an upper bound of the TCP's distance from it, m).

    The bound adds the lengths of the joint offsets along the tool's chain, the prismatic strokes and the TCP offset.
    """
    chain = model.chain(model.tool)
    moving = [i for i in chain if model.joints[i].moves]
    if not moving:
        return model.tool_pose(np.zeros(model.n))[:3, 3], 0.0
    first = moving[0]
    T_links = model.forward(np.zeros(model.n))
    origin = (T_links[model.joints[first].parent] @ model.joints[first].T_parent_joint)[:3, 3]
    total = float(np.linalg.norm(model.T_tool_tcp[:3, 3]))
    for i in chain[chain.index(first) + 1 :]:
        total += float(np.linalg.norm(model.joints[i].T_parent_joint[:3, 3]))
    for i in chain:
        if model.joints[i].kind == "prismatic":
            k, mult, offset = model.drive(i)
            total += abs(mult) * max(abs(model.lower[k]), abs(model.upper[k])) + abs(offset)
    return origin, total


def _seeds(model: RobotModel, q0: np.ndarray, count: int, vary: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(count, n): q0 within the limits, then random joint positions within them (±π for a continuous
    joint) for the joints that ``vary`` (n,) bool, the others at q0."""
    start = np.clip(q0, model.lower, model.upper)
    lo = np.where(np.isfinite(model.lower), model.lower, -np.pi)
    hi = np.where(np.isfinite(model.upper), model.upper, np.pi)
    X = np.tile(start, (max(count, 1), 1))
    X[1:] = np.where(vary, rng.uniform(lo, hi, size=(len(X) - 1, model.n)), start)
    return X


class _Target:
    """The residual of the tool against a target, for k configurations at once."""

    def __init__(self, model: RobotModel, T_t: np.ndarray, scale: float, vary: np.ndarray):
        self.model, self.R_t, self.p_t, self.scale, self.vary = model, T_t[:3, :3], T_t[:3, 3], scale, vary

    def __call__(self, X: np.ndarray):
        """(residuals (k, 6), Jacobians (k, 6, m) over the varied joints, position errors (k,) and rotation
        errors (k,))."""
        T, J = self.model.poses_and_jacobians(X)
        dp = T[:, :3, 3] - self.p_t
        r = _log_so3_many(T[:, :3, :3] @ self.R_t.T)
        J_rot = _inv_left_jacobians(r) @ J[:, 3:]
        e = np.concatenate([dp, self.scale * r], axis=1)
        Je = np.concatenate([J[:, :3], self.scale * J_rot], axis=1)[:, :, self.vary]
        return e, Je, np.linalg.norm(dp, axis=1), np.linalg.norm(r, axis=1)


def _lm_step(e, J, x, lo, hi, lam, max_step: float = 0.5):
    """One projected Levenberg–Marquardt step per row: x (k, m) → x + δ clipped to [lo, hi], δ scaled down
    to at most ``max_step`` on any joint (a descent stays near its seed's branch instead of leaping)."""
    m = x.shape[1]
    g = np.einsum("kri,kr->ki", J, e)
    A = np.einsum("kri,krj->kij", J, J)
    held = ((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0))  # on a limit and pushed beyond it: held this step
    keep = ~held
    A = A * keep[:, :, None] * keep[:, None, :] + np.eye(m) * held[:, None, :]
    g = np.where(held, 0.0, g)
    d = np.einsum("kii->ki", A)
    A = A + lam[:, None, None] * (d[:, :, None] * np.eye(m) + 1e-9 * np.eye(m))
    step = -np.linalg.solve(A, g[:, :, None])[:, :, 0]
    step *= np.minimum(1.0, max_step / np.maximum(np.abs(step).max(axis=1, keepdims=True), 1e-300))
    return np.clip(x + step, lo, hi)


def _descend(target: _Target, X: np.ndarray, limits, tols, max_iter: int):
    """LM descents from each row of X (k, n), within ``limits`` (lower, upper) (n,) each: (X, pos (k,), rot (k,)).

    A row stops when it reaches the tolerances, or stalls: its damping grows past 1e8 (no step helps)
    or its cost falls by less than 10 % over 10 iterations (a local minimum, often a stretched elbow).
    """
    X = X.copy()
    lo, hi = (b[target.vary] for b in limits)
    e, J, pos, rot = target(X)
    cost = np.einsum("kr,kr->k", e, e)
    lam = np.full(len(X), 1e-3)
    live = np.ones(len(X), dtype=bool)
    before = cost.copy()
    for it in range(1, max_iter + 1):
        live &= ((pos > tols[0]) | (rot > tols[1])) & (lam < 1e8)
        run = np.flatnonzero(live)
        if not len(run):
            break
        X_new = X[run]
        X_new[:, target.vary] = _lm_step(e[run], J[run], X_new[:, target.vary], lo, hi, lam[run])
        e_n, J_n, pos_n, rot_n = target(X_new)
        cost_n = np.einsum("kr,kr->k", e_n, e_n)
        better = cost_n < cost[run]
        rows = run[better]
        X[rows], e[rows], J[rows] = X_new[better], e_n[better], J_n[better]
        pos[rows], rot[rows], cost[rows] = pos_n[better], rot_n[better], cost_n[better]
        lam[rows] = np.maximum(lam[rows] / 3.0, 1e-9)
        lam[run[~better]] *= 4.0
        if it % 10 == 0:
            live &= cost < 0.9 * before
            before = cost.copy()
    return X, pos, rot


def _nearest_turn(q: np.ndarray, q0: np.ndarray, model: RobotModel) -> np.ndarray:
    """q with each revolute joint turned by whole turns: within its limits when a turn brings it there,
    nearest q0 among those (the same tool pose either way)."""
    q = q.copy()
    for k, name in enumerate(model.joint_names):
        if model.joint(name).kind == "prismatic":
            continue
        options = q[k] + 2.0 * np.pi * np.arange(-3, 4)
        outside = np.maximum(model.lower[k] - options, 0.0) + np.maximum(options - model.upper[k], 0.0)
        options = options[outside == outside.min()]
        q[k] = options[np.argmin(np.abs(options - q0[k]))]
    return q


def _errors(model: RobotModel, q: np.ndarray, T_t: np.ndarray) -> tuple[float, float]:
    T = model.tool_pose(q)
    return float(np.linalg.norm(T[:3, 3] - T_t[:3, 3])), rotation_angle(T[:3, :3], T_t[:3, :3])


def solve_ik(
    model: RobotModel,
    T_base_target: np.ndarray,
    q0,
    *,
    seeds: int = 8,
    rng: np.random.Generator | int | None = 0,
    position_tol_m: float = 1e-5,
    rotation_tol_rad: float = 1e-4,
    rot_scale_m: float = 0.2,
    max_iter: int = 100,
    explain: bool = True,
) -> IkResult:
    """Joint positions q (n,) within the limits with ``model.tool_pose(q) ≈ T_base_target`` (4, 4), nearest q0.

    seeds : descents run (q0 first, then random ones from ``rng``). A solution is within
    ``position_tol_m`` and ``rotation_tol_rad`` of the target. The nearest to q0 among the solutions
    (the least travel of the robot's points from q0; see the module docstring) is returned, the others
    in ``alternatives``; without one, the nearest pose found within the limits (smallest cost), ``ok``
    False and the reason. ``explain`` False spares the descents without the limits that tell "out of reach"
    from "the joint limits" (a caller trying many targets explains one; the reason is then unsaid).
    """
    T_t = check_T(T_base_target, "T_base_target")
    q0 = model.as_q(q0, "q0")
    tols = (position_tol_m, rotation_tol_rad)
    origin, reach = reach_m(model)
    distance = float(np.linalg.norm(T_t[:3, 3] - origin))
    if distance > reach * (1.0 + 1e-9) + position_tol_m:
        q = np.clip(q0, model.lower, model.upper)
        why = f"out of reach: the target is {distance:.3f} m from the arm's first joint, which reaches {reach:.3f} m"
        return IkResult(q, False, *_errors(model, q, T_t), why)
    vary = model.moves_tool() & (model.upper > model.lower)
    target = _Target(model, T_t, rot_scale_m, vary)
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    starts = _seeds(model, q0, seeds, vary, rng)
    X, pos, rot = _descend(target, starts, (model.lower, model.upper), tols, max_iter)
    ok = np.flatnonzero((pos <= tols[0]) & (rot <= tols[1]))
    if len(ok):
        levers = lever_arms(model)
        found = sorted(
            (_nearest_turn(X[k], q0, model) for k in ok),
            key=lambda x: (float((levers @ np.abs(x - q0)).max()), float(np.linalg.norm(x - q0))),
        )
        distinct = [found[0]]
        for x in found[1:]:
            if min(float(np.abs(x - y).max()) for y in distinct) > 1e-3:
                distinct.append(x)
        others = np.array(distinct[1:]).reshape(-1, model.n)
        return IkResult(found[0], True, *_errors(model, found[0], T_t), alternatives=others)
    best = int(np.argmin(pos**2 + (rot_scale_m * rot) ** 2))
    q, off_m, off_rad = X[best], float(pos[best]), float(rot[best])
    if not explain:
        return IkResult(q, False, off_m, off_rad, "out of reach or beyond the joint limits")
    free = (np.full(model.n, -np.inf), np.full(model.n, np.inf))
    X, pos, rot = _descend(target, np.vstack([q, starts]), free, tols, max_iter)
    reached = np.flatnonzero((pos <= tols[0]) & (rot <= tols[1]))
    reason = "out of reach"
    if len(reached):  # reached without the limits: name the joint the target needs beyond its limit
        q_free = _nearest_turn(X[reached[0]], q0, model)
        beyond = model.within_limits(q_free)
        if beyond is None:
            return IkResult(q_free, True, *_errors(model, q_free, T_t))
        reason = f"joint limits: the target needs {beyond}"
    off = (
        f"the nearest pose within the limits is {off_m * 1e3:.1f} mm and {np.degrees(off_rad):.1f}° off the target (a "
        f"target is reached within {tols[0] * 1e3:.2f} mm and {np.degrees(tols[1]):.3f}°)"
    )
    return IkResult(q, False, off_m, off_rad, f"{reason}; {off}")
