"""The emulated site's truth with its robot: what the live video, the range finder and the checks see.

The scene's bodies play their scripted motions (``app.render.live.scene_bodies``, looping as the
recording does) until the robot moves one: from then on the body is where the robot left it. The
robot's links are at its controller's joints, its base at the scene's true base pose (the database's
calibrated one may differ: that is what calibration is for). The gripper grasps a body when it closes
with the body between its fingers (the point ``GRASP_DEPTH_M`` inside the fingertips lies in the
body's bounds) and the body then rides with the tool; it stays where it is when the gripper opens.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from app.render.live import RenderBody, scene_bodies
from app.scene import Appearance, Scene
from core.robot import RobotModel

from .controller import JointState

__all__ = ["EmulatedWorld", "GRASP_DEPTH_M", "ROBOT_APPEARANCE"]

GRASP_DEPTH_M = 0.02  # a body is grasped when this point between the fingers (from their tips) is inside it
GRIP_TOL_M = 0.002  # ... and the fingers closed to its width (within this)
ROBOT_APPEARANCE = Appearance(albedo=0.55, texture=0.03, texture_scale_m=0.04)
GRASPABLE = ("box", "cylinder", "cone", "polyhedron", "sphere")


@dataclass(frozen=True)
class _BodyAt:
    """A body as app.render.raycast.BeamCaster reads one: name, model, moves, pose_at(t)."""

    name: str
    model: object
    world: EmulatedWorld
    index: int

    moves = True

    def pose_at(self, t_s: float) -> np.ndarray:
        return self.world.pose_of(self.index, t_s)


class EmulatedWorld:
    """The truth of an emulated site with a robot (see the module docstring).

    scene : the scene (bodies, scripted motions, the robot's true base pose ``scene.robot.T_world_base``).
    model : the robot's RobotModel; controller : its emulated controller (listened to for grasps).
    finger_joint : the gripper's joint (closing: its value decreases), None for a robot with no gripper.
    clock : scene time (seconds) now, for where a scripted body is when it is grasped.
    """

    def __init__(
        self,
        scene: Scene,
        model: RobotModel,
        controller,
        *,
        finger_joint: str | None = None,
        clock: Callable[[], float] | None = None,
        home: np.ndarray | None = None,
    ):
        self.scene = scene
        self.clock = clock if clock is not None else (lambda: 0.0)
        self.model = model
        self.controller = controller
        spec = scene.robot
        self.T_world_base = np.asarray(spec.T_world_base, float)
        self.appearance = getattr(spec, "appearance", None) or ROBOT_APPEARANCE
        self.finger = model.joint_names.index(finger_joint) if finger_joint in model.joint_names else None
        # where it is drawn until the controller's first state (a real robot's may not have come yet)
        self._q = np.asarray(controller.state().q if home is None else home, float)
        self._overrides: dict[int, np.ndarray] = {}  # body index → pose the robot left it at
        self.carried: tuple[int, np.ndarray] | None = None  # (body index, T_tool_body)
        self._width = 0.0  # the carried body's width across the fingers
        self._lock = threading.Lock()
        controller.add_listener(self.on_state)

    # ------------------------------------------------------------------ the truth
    def tool_pose(self, q: np.ndarray | None = None) -> np.ndarray:
        return self.T_world_base @ self.model.tool_pose(self._q if q is None else q)

    def pose_of(self, index: int, t_s: float) -> np.ndarray:
        """The true pose of scene body ``index`` at scene time t_s."""
        with self._lock:
            if self.carried is not None and self.carried[0] == index:
                return self.tool_pose() @ self.carried[1]
            if index in self._overrides:
                return self._overrides[index].copy()
        return self.scene.bodies[index].pose_at(_looped(self.scene, t_s))

    def bodies_at(self, t_s: float) -> list[RenderBody]:
        """What the cameras see at scene time t_s: the scene's bodies (moved by the robot where it did) and
        the robot's links."""
        out = []
        for i, b in enumerate(scene_bodies(self.scene, t_s)):
            with self._lock:
                moved = i in self._overrides or (self.carried is not None and self.carried[0] == i)
            out.append(RenderBody(b.name, b.brep, self.pose_of(i, t_s), b.appearance, b.salt) if moved else b)
        with self._lock:
            q = self._q.copy()
        for k, (link, brep, T) in enumerate(self.model.link_breps(q, self.T_world_base)):
            out.append(RenderBody(f"robot/{link}/{k}", brep, T, self.appearance))
        return out

    def beam_bodies(self) -> list:
        """The bodies as the range finder's caster reads them (the robot's links among them)."""
        out = [_BodyAt(b.name, b.model, self, i) for i, b in enumerate(self.scene.bodies)]
        links = self.model.link_breps(self._q, self.T_world_base)
        return out + [_LinkAt(f"robot/{link}", brep, self, k) for k, (link, brep, _) in enumerate(links)]

    def link_pose(self, k: int) -> np.ndarray:
        with self._lock:
            q = self._q.copy()
        return self.model.link_breps(q, self.T_world_base)[k][2]

    def carried_name(self) -> str | None:
        """The name of the body in the gripper (the gripper's own sensor), None when it holds nothing."""
        c = self.carried
        return None if c is None else self.scene.bodies[c[0]].name

    # ------------------------------------------------------------------ grasping
    def on_state(self, s: JointState) -> None:
        q = np.asarray(s.q, float)
        with self._lock:
            before = self._q
            self._q = q
        if self.finger is None:
            return
        dq = q[self.finger] - before[self.finger]
        gap = 2.0 * q[self.finger]  # the fingers' opening (each moves its joint's value off the centre)
        if dq < -1e-9 and self.carried is None:
            self._grasp(gap)
        elif dq > 1e-9 and self.carried is not None and gap > self._width + GRIP_TOL_M:
            self._release()

    def _across(self, b, T: np.ndarray, T_tool: np.ndarray) -> float:
        """The body's extent (m) along the direction the fingers close (the tool's y)."""
        lo, hi = b.model.bounds()
        return float(np.abs(T[:3, :3].T @ T_tool[:3, 1]) @ (hi - lo))

    def _grasp(self, gap: float) -> None:
        """The fingers closed to ``gap``: a body between them as wide as the gap is held from now on."""
        T_tool = self.tool_pose()
        P = T_tool @ np.array([0.0, 0.0, -GRASP_DEPTH_M, 1.0])
        for i, b in enumerate(self.scene.bodies):
            if b.kind not in GRASPABLE:
                continue
            T = self.pose_of(i, self.clock())
            lo, hi = b.model.bounds()
            p = np.linalg.solve(T, P)[:3]
            width = self._across(b, T, T_tool)
            if np.all(p >= lo) and np.all(p <= hi) and gap <= width + GRIP_TOL_M:
                with self._lock:
                    self.carried = (i, np.linalg.solve(T_tool, T))
                    self._width = width
                return

    def _release(self) -> None:
        T = self.tool_pose() @ self.carried[1]
        with self._lock:
            self._overrides[self.carried[0]] = T
            self.carried = None


@dataclass(frozen=True)
class _LinkAt:
    """A robot link as the range finder's caster reads a body."""

    name: str
    model: object
    world: EmulatedWorld
    k: int

    moves = True

    def pose_at(self, t_s: float) -> np.ndarray:
        return self.world.link_pose(self.k)


def _looped(scene: Scene, t_s: float) -> float:
    from app.render.live import scene_loop_s

    loop = scene_loop_s(scene)
    return float(t_s) % loop if loop else float(t_s)
