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

A robot that already stands inside an object's margin (not touching it: a base calibrated since, an object
modelled beside the arm) may move, but not nearer: for that motion the object's margin is where the robot stands
(``_set_obstacles``), and the operator is told. Without it every motion was refused at its first sample, Move robot's
too, and the robot could not be moved clear.

``move(plan)`` sends a checked plan to the controller, refused when the robot moved since it was
planned, when it is moving, or when the plan was refused. ``stop()`` halts it at once.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

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
    "joints_in_order",
    "PickPlan",
    "grasp_frame",
    "placed_pose",
]

MARGIN_M = 0.01  # clearance kept from known and modelled objects and the table
STALE_MARGIN_M = 0.04  # clearance kept from objects whose pose is stale
APPROACH_M = 0.08  # the last leg comes straight in along the normal from this far out
LEAVE_SLACK_M = 1e-4  # a start inside a margin: the motion may come this much nearer (the distance's own precision)
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
    q_contact: np.ndarray | None = None  # a refused plan's pose where the first contact was found

    @property
    def q_goal(self) -> np.ndarray:
        return self.path[-1]


def joints_in_order(model: RobotModel, names: Sequence[str], q: Sequence[float]) -> np.ndarray:
    """A reported joint state (names, positions) in the model's joint order; ValueError (one line, what to fix)
    for a joint the robot does not have, one missing, or a position that is not a finite number."""
    names = [str(n) for n in names]
    q = np.asarray(q, float).reshape(-1)
    if len(names) != len(q):
        raise ValueError(f"a joint state of {len(names)} names and {len(q)} positions: give one position per joint")
    unknown = sorted(set(names) - set(model.joint_names))
    if unknown:
        raise ValueError(
            f"the joint state names {unknown}, which robot {model.name} does not have (its joints: "
            f"{list(model.joint_names)}): check the controller's joint names against the URDF"
        )
    missing = [n for n in model.joint_names if n not in names]
    if missing:
        raise ValueError(f"the joint state lacks {missing}: the controller must report every joint")
    out = np.array([q[names.index(n)] for n in model.joint_names])
    bad = [n for n, v in zip(model.joint_names, out) if not np.isfinite(v)]
    if bad:
        raise ValueError(f"the joint state gives {bad} no finite position: the robot's state is unknown")
    return out


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
        prismatic = [k for k, n in enumerate(model.joint_names) if model.joint(n).kind == "prismatic"]
        self.finger = prismatic[0] if prismatic else None  # the gripper's joint in q (closing: it decreases)
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
            margins = {o.name: o.margin_m for o in obstacles}
            warnings += self._set_obstacles(self.checker, q0, obstacles)
            best, checked, ik_why = None, 0, []
            refusal: list = []  # (reason, pose) of the first contact found

            def goal_free(q_goal) -> bool:
                """One pose: a goal in contact spares solving and checking its path."""
                contacts = self.checker.check(q_goal)
                if contacts and not refusal:
                    refusal.append((_collision_text(contacts[0], self.model.links, margins), q_goal))
                return not contacts

            for q_pre, q_goal in self._solutions(X, n, standoff_m, q0, ik_why, goal_free):
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
                if not refusal:
                    refusal.append((_collision_text(check, self.model.links, margins), path[check.index]))
        T_goal = self.T_world_base @ self.model.tool_pose(best[-1] if best is not None else q0)
        if best is None:
            why = ik_why[0] if ik_why else "no joint solution"
            reason, contact = refusal[0] if refusal else (f"the robot cannot reach the target: {why}", None)
            plan = self._refused(q0, X, n, standoff_m, t0, reason, warnings)
            plan.samples_checked, plan.q_contact = checked, contact
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
            warnings = self._set_obstacles(self.checker, q0, obstacles)
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
                    dt = time.perf_counter() - t0
                    return MovePlan(path, True, "", T, T[:3, 3], -T[:3, 2], 0.0, warnings, dt, checked)
                reason = reason or _collision_text(check, self.model.links, margins, targets=False)
        plan = self._refused(q0, T[:3, 3], -T[:3, 2], 0.0, t0, reason, warnings)
        plan.samples_checked = checked
        return plan

    def _set_obstacles(self, checker: CollisionChecker, q0: np.ndarray, obstacles: Sequence[Obstacle]) -> list[str]:
        """Give ``checker`` the obstacles for a motion starting at q0 (the module's docstring): one the robot stands
        inside the margin of, not touching it, kept no nearer than the robot stands; what to tell of those."""
        checker.set_obstacles([(o.name, o.brep, o.T_world_obj, o.margin_m) for o in obstacles])
        near: dict[str, float] = {}
        for c in checker.check(q0):
            if c.other not in self.model.links and c.distance_m > LEAVE_SLACK_M:
                near[c.other] = min(near.get(c.other, np.inf), c.distance_m)
        if not near:
            return []
        kept = [replace(o, margin_m=near[o.name] - LEAVE_SLACK_M) if o.name in near else o for o in obstacles]
        checker.set_obstacles([(o.name, o.brep, o.T_world_obj, o.margin_m) for o in kept])
        margins = {o.name: o.margin_m for o in obstacles}
        return [
            f"the robot stands {1000 * d:.1f} mm from {name}, inside the {1000 * margins[name]:.0f} mm kept from it: "
            "this motion may take it away but not nearer"
            for name, d in near.items()
        ]

    @staticmethod
    def _near(o: Obstacle, X: np.ndarray) -> bool:
        """The target point lies on (or within a millimetre of) obstacle o's bounds."""
        lo, hi = o.brep.bounds()
        Xo = np.linalg.solve(o.T_world_obj, np.append(X, 1.0))[:3]
        return bool(np.all(Xo >= lo - 1e-3) and np.all(Xo <= hi + 1e-3))

    def _solutions(self, X, n, standoff_m, q0, why: list, goal_free):
        """(q_pre, q_goal) for the tool's turns about the approach axis, the turn nearest the tool's present
        one first (a lazy sequence: planning stops at the first that passes the check); ``why`` gets the
        inverse kinematics' reason for each turn that has no solution. ``goal_free(q_goal)`` is asked before
        the approach's joints are solved (a goal in contact needs none)."""
        T_base_world = np.linalg.inv(self.T_world_base)
        x_now = (self.T_world_base @ self.model.tool_pose(q0))[:3, 0]
        T0 = tool_frame(X, n, standoff_m, 0.0)
        yaw_now = np.arctan2(x_now @ T0[:3, 1], x_now @ T0[:3, 0])
        yaws = 2 * np.pi * np.arange(YAW_STEPS) / YAW_STEPS
        for k, yaw in enumerate(sorted(yaws, key=lambda a: abs(np.angle(np.exp(1j * (a - yaw_now)))))):
            # the nearest turns with more seeds: the others mostly repeat what those found
            T_goal = T_base_world @ tool_frame(X, n, standoff_m, yaw)
            goal = solve_ik(self.model, T_goal, q0, seeds=4 if k < 3 else 2, explain=k == 0)  # why: said once
            if not goal.ok:
                why.append(goal.reason)
                continue
            if not goal_free(goal.q):
                continue
            pre = solve_ik(self.model, T_base_world @ tool_frame(X, n, standoff_m + APPROACH_M, yaw), goal.q, seeds=2)
            if pre.ok:
                yield pre.q, goal.q
            else:
                why.append(f"the approach {100 * APPROACH_M:.0f} cm out along the surface's normal: {pre.reason}")

    def _refused(self, q0, X, n, standoff_m, t0, reason, warnings) -> MovePlan:
        T = self.T_world_base @ self.model.tool_pose(q0)
        return MovePlan(q0[None].copy(), False, reason, T, X, n, standoff_m, warnings, time.perf_counter() - t0)

    # ------------------------------------------------------------------ pick and place
    def plan_pick_place(
        self,
        name: str,
        brep,
        T_world_obj: np.ndarray,
        X_place: np.ndarray,
        support: str,
        obstacles: Sequence[Obstacle],
        stands_on: str | None = None,
    ) -> PickPlan:
        """Plan and check picking body ``name`` (``brep`` at ``T_world_obj``, as the database has it) and putting
        it down with its bottom's centre at X_place on ``support`` (see ``PickPlan``; the module docstring's
        checks, with three exceptions the gripper's work needs: the body is no obstacle while the fingers come
        down around it, close and carry it (it is checked as part of the robot, against everything else, while
        carried), and the surfaces it stands on (``stands_on``) and is put on (``support``) are no obstacles for
        the straight lift up and down with it). The lift is ``LIFTS_M[0]``; a plan refused there is tried again
        lifting higher (the body carried over what stands between, not past it): the first refusal is said."""
        t0 = time.perf_counter()
        try:  # no grasp at all (no gripper, too wide, tilted): no lift helps
            if self.finger is None:
                raise ValueError("this robot has no gripper")
            grasp = grasp_frame(brep, T_world_obj, 2.0 * self.model.upper[self.finger])
        except ValueError as exc:
            return self._pick_refused(name, self.state().q, str(exc), t0)
        first = None
        for lift_m in LIFTS_M:
            plan = self._plan_pick_place(name, brep, T_world_obj, X_place, support, obstacles, stands_on, grasp, lift_m)
            if plan.ok:
                plan.preview_s = time.perf_counter() - t0
                return plan
            first = first or plan
        first.preview_s = time.perf_counter() - t0
        return first

    def _plan_pick_place(
        self, name, brep, T_world_obj, X_place, support, obstacles, stands_on, grasp, lift_m: float
    ) -> PickPlan:
        """``plan_pick_place`` with the grasp ``grasp`` (``grasp_frame``), lifting ``lift_m`` there and at the place."""
        t0 = time.perf_counter()
        q0 = self.state().q
        T_grasp, width = grasp
        T_put = placed_pose(brep, T_world_obj, X_place)
        T_tool_obj = np.linalg.solve(T_grasp, T_world_obj)
        T_place = T_put @ np.linalg.inv(T_tool_obj)
        lift = np.eye(4)
        lift[2, 3] = lift_m
        qs, seed = [], q0
        for what, T in (
            ("above the grasp", lift @ T_grasp),
            ("the grasp", T_grasp),
            ("above the place", lift @ T_place),
            ("the place", T_place),
        ):
            r = solve_ik(self.model, np.linalg.solve(self.T_world_base, T), seed)
            if not r.ok:
                return self._pick_refused(name, q0, f"the robot cannot reach {what}: {r.reason}", t0)
            qs.append(r.q)
            seed = r.q
        f = self.finger
        opened = float(np.clip(width / 2 + GRIP_CLEARANCE_M, self.model.lower[f], self.model.upper[f]))
        closed = float(np.clip(width / 2 - SQUEEZE_M, self.model.lower[f], self.model.upper[f]))

        def at(q, finger):
            q = q.copy()
            q[f] = finger
            return q

        q_open = at(q0, opened)
        pre_g, grasp, pre_p, place = (at(q, opened) for q in qs)
        shut = at(grasp, closed)
        carried = [shut, at(pre_g, closed), at(pre_p, closed), at(place, closed)]
        back = at(q0, opened)
        others = [o for o in obstacles if o.name != name]
        legs = [
            (self.checker, [q0, q_open, pre_g], obstacles),
            (self.checker, [pre_g, grasp, shut], others),
            ("payload", carried[:2], [o for o in others if o.name != stands_on]),
            ("payload", carried[1:3], others),
            ("payload", carried[2:], [o for o in others if o.name != support]),
            (self.checker, [carried[3], place, pre_p], others),
            # back where it started, out of the cameras' way for the look that follows, the body an obstacle where
            # it now stands
            (self.checker, [pre_p, back], [*others, Obstacle(name, brep, T_put, MARGIN_M)]),
        ]
        payload = self._payload_checker(name, brep, T_tool_obj)
        path, warnings = [q0[None]], []
        with self._check_lock:
            for checker, waypoints, obs in legs:
                checker = payload if checker == "payload" else checker
                if waypoints[0] is q0 or waypoints[-1] is back:  # from where the robot stands, and back there
                    said = self._set_obstacles(checker, q0, obs)
                    warnings += [w for w in said if w not in warnings]
                else:
                    checker.set_obstacles([(o.name, o.brep, o.T_world_obj, o.margin_m) for o in obs])
                for a, b in zip(waypoints, waypoints[1:]):
                    seg = joint_path(self.model, a, b, self.max_step_m)[1:]
                    check = checker.check_path(np.vstack([a[None], seg]))
                    if not check.ok:
                        margins = {o.name: o.margin_m for o in obs}
                        return self._pick_refused(name, q0, _collision_text(check, checker.model.links, margins), t0)
                    path.append(seg)
        return PickPlan(
            np.vstack(path), True, "", name, T_put, T_tool_obj, shut, carried[3], width, warnings,
            preview_s=time.perf_counter() - t0,
        )  # fmt: skip

    def _payload_checker(self, name: str, brep, T_tool_obj: np.ndarray) -> CollisionChecker:
        """The collision check of the robot carrying the body: the body is a link of the hand; it touches the
        fingers, so the hand's links (those the last arm joint moves) are not checked against it."""
        from core.robot import LinkShape

        model = self.model.with_payload(name, LinkShape(brep, T_tool_obj))
        last = max(i for i in model.chain(model.tool) if model.joints[i].kind in ("revolute", "continuous"))
        hand = [k for k in model.links if last in model.chain(k)]
        payload = f"payload:{name}"
        pairs = [tuple(p) for p in self.checker.ignored_pairs if len(p) == 2]
        pairs += [(payload, k) for k in hand if k != payload]
        return CollisionChecker(model, self.T_world_base, pairs)

    def _pick_refused(self, name: str, q0: np.ndarray, reason: str, t0: float) -> PickPlan:
        I = np.eye(4)
        return PickPlan(q0[None].copy(), False, reason, name, I, I, q0, q0, preview_s=time.perf_counter() - t0)

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


def _collision_text(check, links, margins: dict, targets: bool = True) -> str:
    """One line naming what the path would hit (an obstacle, or the robot's own link); ``targets``: the motion went
    to a target the operator chose (else to a pose given them: a calibration's), which another target may spare."""
    what = check.other
    advice = ""
    if targets:  # another target may spare it; an object, moved out of the way
        advice = ": choose another target" + ("" if what in links else f", or move {what} first")
    if check.other in links:
        return f"the path would bring the robot's {check.link} into its own {check.other}{advice}"
    if getattr(check, "index", -1) == 0:  # where it stands now (touching: a start inside the margin may leave it)
        return (
            f"the database has the robot's {check.link} touching {what} where it stands: check {what}'s pose "
            "(Update pose) and the robot's base (Calibrate robot), then try again"
        )
    if check.distance_m > 0:
        return (
            f"the path would pass the robot's {check.link} {1000 * check.distance_m:.1f} mm from {what}, inside the "
            f"{1000 * margins.get(what, 0.0):.0f} mm kept from it{advice}"
        )
    return f"the path would hit {what} with the robot's {check.link}{advice}"


# ---------------------------------------------------------------------- pick and place
GRASP_DEPTH_M = 0.03  # the fingertips this far below the body's top (at most half its height)
GRIP_CLEARANCE_M = 0.008  # each finger this far off the body's side while it comes down
# up and down this far, straight, at the grasp and at the place; a plan refused is tried again lifting higher (a
# carried box passed 9.6-9.8 mm from a cylinder beside its way, inside the 10 mm kept, in 7 of 46 places tried)
LIFTS_M = (0.10, 0.18, 0.26)
SQUEEZE_M = 0.003  # each finger commanded this far past the body's side (a gripper stops at contact and holds)
UPRIGHT_COS = np.cos(np.radians(5.0))  # the body's z within 5° of the world's: grasped from above


@dataclass
class PickPlan:
    """A pick and place: ``path`` (k, n) the whole motion (open, down, close, up, across, down, open, up).

    T_world_obj_place : the body's pose where it is put. T_tool_obj : the body in the tool while carried.
    q_release : the joints when the fingers open at the place (the pose written comes from them).
    """

    path: np.ndarray
    ok: bool
    reason: str
    name: str
    T_world_obj_place: np.ndarray
    T_tool_obj: np.ndarray
    q_grasp: np.ndarray
    q_release: np.ndarray
    width_m: float = 0.0
    warnings: list[str] = field(default_factory=list)
    preview_s: float = 0.0


def grasp_frame(brep, T_world_obj: np.ndarray, max_opening_m: float) -> tuple[np.ndarray, float]:
    """(T_world_tool at the grasp, the body's width across the fingers): the tool pointing down over the body's
    centre, the fingers closing along the narrower of its horizontal axes, the tips ``GRASP_DEPTH_M`` below its
    top. ValueError (what to do) for a body not upright or wider than the gripper opens."""
    R = T_world_obj[:3, :3]
    if R[2, 2] < UPRIGHT_COS:
        raise ValueError("the robot grasps upright bodies from above: this one is tilted more than 5°")
    lo, hi = brep.bounds()
    size = hi - lo
    axis = 0 if size[0] <= size[1] else 1
    width = float(size[axis])
    if width + 2 * GRIP_CLEARANCE_M > max_opening_m:
        raise ValueError(
            f"it is {1000 * width:.1f} mm across its narrower side; the gripper opens {1000 * max_opening_m:.0f} mm "
            f"and comes down with {1000 * GRIP_CLEARANCE_M:.0f} mm each side: bodies up to "
            f"{1000 * (max_opening_m - 2 * GRIP_CLEARANCE_M):.0f} mm across"
        )
    depth = min(GRASP_DEPTH_M, 0.5 * size[2])
    top_centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] - depth])
    y = R[:, axis]
    z = np.array([0.0, 0.0, -1.0])
    y = y - (y @ z) * z
    y /= np.linalg.norm(y)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([np.cross(y, z), y, z])
    T[:3, 3] = T_world_obj[:3, :3] @ top_centre + T_world_obj[:3, 3]
    return T, width


def placed_pose(brep, T_world_obj: np.ndarray, X_place: np.ndarray) -> np.ndarray:
    """The body's pose put down with its bottom's centre at X_place, turned as it is."""
    lo, hi = brep.bounds()
    bottom = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    T = T_world_obj.copy()
    T[:3, 3] = np.asarray(X_place, float) - T_world_obj[:3, :3] @ bottom
    return T
