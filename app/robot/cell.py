"""The site's robot as the interface uses it: its model, its controller, its base in the world, and the
motions it is sent on, each planned and checked against the database before it moves.

A motion to a point on a surface (``plan_approach``): the tool's z axis along the surface's inward
normal, its tip ``standoff_m`` off the surface; the tool's turn about that axis is the one nearest
the tool's present turn among those that pass the check (tried every 30°). The path goes from
where the robot is to a point ``APPROACH_M`` farther out along the normal, then straight in along it
(each leg a straight joint-space path, ``core.robot.joint_path``), sampled so that no point of the
robot moves more than half the thinnest link's thickness between samples, and every sample is checked
(``app.robot.collision``) against every database object with its margin — ``MARGIN_M`` for known and
modelled objects, ``STALE_MARGIN_M`` for stale ones (their pose is doubtful: the operator is told) —
and against itself. A path that collides or leaves a joint's limits is refused, naming the object or
the joint; nothing moves.

A motion to given joint positions (``plan_joints``: the calibration workflows' poses) is checked the same way,
along the straight joint path or, when that is refused, through given intermediate configurations.

``move(plan)`` sends a checked plan to the controller, refused when the robot moved since it was
planned, when it is moving, or when the plan was refused. ``stop()`` halts it at once.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from core.robot import RobotModel, joint_path, solve_ik
from core.transforms import check_T

from .collision import CollisionChecker
from .controller import ControllerError, JointState

__all__ = [
    "MARGIN_M",
    "STALE_MARGIN_M",
    "APPROACH_M",
    "Obstacle",
    "MovePlan",
    "RobotCell",
    "tool_frame",
    "obstacles_of",
]

MARGIN_M = 0.01  # clearance kept from known and modelled objects and the table
STALE_MARGIN_M = 0.04  # clearance kept from objects whose pose is stale
APPROACH_M = 0.08  # the last leg comes straight in along the normal from this far out
YAW_STEPS = 12  # turns about the approach axis tried (every 30°)
PLAN_MOVED_RAD = 1e-3  # the robot moved since the plan when a joint is farther than this from its start


@dataclass(frozen=True)
class Obstacle:
    """A database object as the collision check sees it: BRep at T_world_obj, kept ``margin_m`` away."""

    name: str
    brep: object
    T_world_obj: np.ndarray
    margin_m: float
    status: str = "known"


@dataclass
class MovePlan:
    """A planned motion: ``path`` (k, n) joint samples from the robot's joints at planning time to the goal.

    ok : it passed every check; ``reason`` says why not (one line naming the object or the joint).
    T_world_goal : the tool's pose at the end. target_X, normal : the surface point and its outward normal.
    warnings : what the operator must know even of a passing plan (stale objects, wider margins).
    preview_s : how long planning and checking took.
    """

    path: np.ndarray
    ok: bool
    reason: str
    T_world_goal: np.ndarray
    target_X: np.ndarray
    normal: np.ndarray
    standoff_m: float
    warnings: list[str] = field(default_factory=list)
    preview_s: float = 0.0
    samples_checked: int = 0

    @property
    def q_goal(self) -> np.ndarray:
        return self.path[-1]


def obstacles_of(objects, skip: tuple[str, ...] = ()) -> list[Obstacle]:
    """Every database object (``app.workflows.site.SiteObject``) as an obstacle: stale ones with the wider margin."""
    return [
        Obstacle(o.name, o.model, o.T_world_obj, STALE_MARGIN_M if o.status == "stale" else MARGIN_M, o.status)
        for o in objects
        if o.name not in skip
    ]


def tool_frame(X: np.ndarray, normal: np.ndarray, standoff_m: float, yaw: float) -> np.ndarray:
    """T_world_tool: z into the surface (−normal), origin ``standoff_m`` out from X along the normal,
    turned by ``yaw`` about z from the x axis nearest the world's horizontal."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    z = -n
    a = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([c * x + s * y, -s * x + c * y, z])
    T[:3, 3] = np.asarray(X, float) + standoff_m * n
    return T


class RobotCell:
    """The robot at the site (see the module docstring).

    model : core.robot.RobotModel. controller : an ``app.robot.controller`` controller in the model's joint
    order. T_world_base : the base's calibrated pose in the world. publish : called with each joint state
    (the live feed's robot lines go out through it), may be None.
    """

    def __init__(
        self,
        model: RobotModel,
        controller,
        T_world_base: np.ndarray,
        *,
        publish: Callable[[JointState], None] | None = None,
    ):
        if tuple(controller.names) != tuple(model.joint_names):
            raise ValueError(
                f"the controller's joints {list(controller.names)} are not the robot's {list(model.joint_names)}"
            )
        self.model = model
        self.controller = controller
        self.T_world_base = np.asarray(T_world_base, float)
        self.checker = CollisionChecker(model, self.T_world_base)
        self._check_lock = threading.Lock()  # one planning at a time uses the checker
        thick = [s.thickness_m for shapes in model.collision_shapes.values() for s in shapes]
        self.max_step_m = 0.5 * min(thick) if thick else 0.01
        self.revision = 0  # bumped on every joint state: the overlay redraws when it changes
        self._last: JointState | None = None
        self._publish = publish
        controller.add_listener(self._on_state)

    # ------------------------------------------------------------------ state
    def state(self) -> JointState:
        s = self.controller.state()
        self._last = s
        return s

    def last_state(self) -> JointState | None:
        """The last joint state heard (no call to the controller)."""
        return self._last

    def _on_state(self, s: JointState) -> None:
        self._last = s
        self.revision += 1
        if self._publish is not None:
            self._publish(s)

    def tool_pose(self, q: np.ndarray | None = None) -> np.ndarray:
        """T_world_tool at q (default: the last joint state)."""
        q = self._q(q)
        return self.T_world_base @ self.model.tool_pose(q)

    def set_base(self, T_world_base: np.ndarray) -> None:
        """Use another base pose (a calibration, or its undo): plans, checks and the drawing go through it."""
        T = check_T(T_world_base, "T_world_base")
        with self._check_lock:
            self.T_world_base = T
            self.checker.T_world_base = T

    def link_breps(self, q: np.ndarray | None = None) -> list:
        """[(link, BRep, T_world_shape)] of the drawn shapes at q (default: the last joint state)."""
        return self.model.link_breps(self._q(q), self.T_world_base)

    def _q(self, q) -> np.ndarray:
        if q is not None:
            return np.asarray(q, float)
        s = self._last if self._last is not None else self.state()
        return s.q

    # ------------------------------------------------------------------ planning
    def plan_approach(
        self, X: np.ndarray, normal: np.ndarray, standoff_m: float, obstacles: Sequence[Obstacle]
    ) -> MovePlan:
        """Plan and check a motion bringing the tool ``standoff_m`` off the surface point X (see the module)."""
        t0 = time.perf_counter()
        q0 = self.state().q
        X, n = np.asarray(X, float), np.asarray(normal, float)
        n = n / np.linalg.norm(n)
        warnings = [
            f"{o.name} is stale: kept {1000 * o.margin_m:.0f} mm away (its pose is doubtful)"
            for o in obstacles
            if o.status == "stale"
        ]
        too_near = [o for o in obstacles if self._near(o, X) and o.margin_m > standoff_m]
        if too_near:
            o = too_near[0]
            return self._refused(
                q0,
                X,
                n,
                standoff_m,
                t0,
                f"a standoff of {1000 * standoff_m:.0f} mm is inside the {1000 * o.margin_m:.0f} mm kept from "
                f"{o.name}: raise the standoff",
                warnings,
            )
        with self._check_lock:
            self.checker.set_obstacles([(o.name, o.brep, o.T_world_obj, o.margin_m) for o in obstacles])
            margins = {o.name: o.margin_m for o in obstacles}
            best, first_reason, checked, ik_why = None, "", 0, []
            for q_pre, q_goal in self._solutions(X, n, standoff_m, q0, ik_why):
                path = np.vstack(
                    [
                        joint_path(self.model, q0, q_pre, self.max_step_m),
                        joint_path(self.model, q_pre, q_goal, self.max_step_m)[1:],
                    ]
                )
                check = self.checker.check_path(path)
                checked += len(path)
                if check.ok:
                    best = path
                    break
                first_reason = first_reason or _collision_text(check, self.model.links, margins)
        T_goal = self.T_world_base @ self.model.tool_pose(best[-1] if best is not None else q0)
        if best is None:
            why = ik_why[0] if ik_why else "no joint solution"
            reason = first_reason or f"the robot cannot reach the target: {why}"
            plan = self._refused(q0, X, n, standoff_m, t0, reason, warnings)
            plan.samples_checked = checked
            return plan
        return MovePlan(
            best, True, "", T_goal, X, n, standoff_m, warnings, time.perf_counter() - t0, samples_checked=checked
        )

    def plan_joints(self, q_goal, obstacles: Sequence[Obstacle], via: Sequence[np.ndarray] = ()) -> MovePlan:
        """Plan and check a motion to the joint positions ``q_goal`` (n,): the straight joint path, else through
        each configuration of ``via`` in turn (e.g. home); refused naming the joint or what it would hit."""
        t0 = time.perf_counter()
        q0 = self.state().q
        q_goal = self.model.as_q(q_goal, "q_goal")
        T = self.T_world_base @ self.model.tool_pose(q_goal)
        beyond = self.model.within_limits(q_goal)
        if beyond is not None:
            return self._refused(q0, T[:3, 3], -T[:3, 2], 0.0, t0, f"the pose puts {beyond}", [])
        margins = {o.name: o.margin_m for o in obstacles}
        reason, checked = "", 0
        with self._check_lock:
            self.checker.set_obstacles([(o.name, o.brep, o.T_world_obj, o.margin_m) for o in obstacles])
            for legs in ([q0, q_goal], *([q0, np.asarray(v, float), q_goal] for v in via)):
                path = np.vstack(
                    [
                        joint_path(self.model, a, b, self.max_step_m)[1 if k else 0 :]
                        for k, (a, b) in enumerate(zip(legs, legs[1:]))
                    ]
                )
                check = self.checker.check_path(path)
                checked += len(path)
                if check.ok:
                    return MovePlan(path, True, "", T, T[:3, 3], -T[:3, 2], 0.0, [], time.perf_counter() - t0, checked)
                reason = reason or _collision_text(check, self.model.links, margins)
        plan = self._refused(q0, T[:3, 3], -T[:3, 2], 0.0, t0, reason, [])
        plan.samples_checked = checked
        return plan

    @staticmethod
    def _near(o: Obstacle, X: np.ndarray) -> bool:
        """The target point lies on (or within a millimetre of) obstacle o's bounds."""
        lo, hi = o.brep.bounds()
        Xo = np.linalg.solve(o.T_world_obj, np.append(X, 1.0))[:3]
        return bool(np.all(Xo >= lo - 1e-3) and np.all(Xo <= hi + 1e-3))

    def _solutions(self, X, n, standoff_m, q0, why: list):
        """(q_pre, q_goal) for the tool's turns about the approach axis, the turn nearest the tool's present
        one first (a lazy sequence: planning stops at the first that passes the check); ``why`` gets the
        inverse kinematics' reason for each turn that has no solution."""
        T_base_world = np.linalg.inv(self.T_world_base)
        x_now = (self.T_world_base @ self.model.tool_pose(q0))[:3, 0]
        T0 = tool_frame(X, n, standoff_m, 0.0)
        yaw_now = np.arctan2(x_now @ T0[:3, 1], x_now @ T0[:3, 0])
        yaws = 2 * np.pi * np.arange(YAW_STEPS) / YAW_STEPS
        for yaw in sorted(yaws, key=lambda a: abs(np.angle(np.exp(1j * (a - yaw_now))))):
            goal = solve_ik(self.model, T_base_world @ tool_frame(X, n, standoff_m, yaw), q0, seeds=4)
            if not goal.ok:
                why.append(goal.reason)
                continue
            pre = solve_ik(self.model, T_base_world @ tool_frame(X, n, standoff_m + APPROACH_M, yaw), goal.q, seeds=2)
            if pre.ok:
                yield pre.q, goal.q
            else:
                why.append(f"the approach {100 * APPROACH_M:.0f} cm out along the surface's normal: {pre.reason}")

    def _refused(self, q0, X, n, standoff_m, t0, reason, warnings) -> MovePlan:
        T = self.T_world_base @ self.model.tool_pose(q0)
        return MovePlan(q0[None].copy(), False, reason, T, X, n, standoff_m, warnings, time.perf_counter() - t0)

    # ------------------------------------------------------------------ motion
    def move(self, plan: MovePlan) -> None:
        """Send a checked plan to the controller (ControllerError when it cannot go; nothing moves then)."""
        if not plan.ok:
            raise ControllerError(f"this motion was refused: {plan.reason}")
        s = self.state()
        if s.moving:
            raise ControllerError("the robot is moving: stop it (Space) or wait for it to stop, then plan again")
        if np.max(np.abs(s.q - plan.path[0])) > PLAN_MOVED_RAD:
            raise ControllerError("the robot moved since this motion was planned: plan it again")
        self.controller.move(plan.path[1:] if len(plan.path) > 1 else plan.path)

    def stop(self) -> None:
        self.controller.stop()


def _collision_text(check, links, margins: dict) -> str:
    """One line naming what the path would hit (an obstacle, or the robot's own link)."""
    if check.other in links:
        return f"the path would bring the robot's {check.link} into its own {check.other}: choose another target"
    what = check.other
    if check.distance_m > 0:
        return (
            f"the path would pass the robot's {check.link} {1000 * check.distance_m:.0f} mm from {what}, inside the "
            f"{1000 * margins.get(what, 0.0):.0f} mm kept from it: choose another target, or move {what} first"
        )
    return f"the path would hit {what} with the robot's {check.link}: choose another target, or move {what} first"
