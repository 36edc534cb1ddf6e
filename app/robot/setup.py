"""The site's robot opened for ``mcit serve``: its URDF loaded, its controller (emulated here), the emulated
world it moves in, and its joint states on the live feed.

``open_robot(scene, clock=..., publish=...)`` returns a ``RobotSetup`` (None for a scene with no robot):
``cell`` (app.robot.cell.RobotCell, what the workflows use), ``world`` (app.robot.emulated.EmulatedWorld,
the truth the live video and the range finder see) and ``close()``.

The feed's robot lines (``app.feed.robot_event``) go out on each change of motion or fault and at least
every ``FEED_PERIOD_S`` while the robot moves (a controller's 50 Hz states would flood a reader).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from app.scene import Scene

from .cell import RobotCell
from .controller import EmulatedController, JointState
from .emulated import EmulatedWorld

__all__ = ["RobotSetup", "open_robot", "FEED_PERIOD_S", "RobotFeed"]

log = logging.getLogger("mcit.robot")

FEED_PERIOD_S = 0.5


class RobotFeed:
    """Throttles joint states into the live feed's robot lines (see the module docstring)."""

    def __init__(self, publish: Callable[[dict], None], robot: str, tool_pose: Callable, carrying: Callable):
        self.publish = publish
        self.robot = robot
        self.tool_pose = tool_pose
        self.carrying = carrying
        self._last: tuple[bool, str | None, bytes] | None = None
        self._last_t = 0.0

    def __call__(self, s: JointState) -> None:
        from app.feed import robot_event

        now = time.monotonic()
        key = (bool(s.moving), s.fault, np.round(s.q, 6).tobytes())
        changed = self._last is None or key[:2] != self._last[:2] or (not s.moving and key[2] != self._last[2])
        if not changed and not (s.moving and now - self._last_t >= FEED_PERIOD_S):
            return
        self._last, self._last_t = key, now
        try:
            self.publish(robot_event(self.robot, s, self.tool_pose(s.q), carrying=self.carrying()))
        except Exception:  # noqa: BLE001 - the robot's state goes on; one log line
            log.exception("the robot's state could not be sent on the live feed")


@dataclass
class RobotSetup:
    cell: RobotCell
    world: EmulatedWorld
    controller: EmulatedController  # or a real robot's (app.ros2.robot.RosController)

    def close(self) -> None:
        self.controller.close()


def _finger(model) -> str | None:
    """The gripper's joint: the first actuated prismatic joint (the fingers), None without one."""
    return next((n for n in model.joint_names if model.joint(n).kind == "prismatic"), None)


def open_robot(
    scene: Scene,
    *,
    clock: Callable[[], float] | None = None,
    publish: Callable[[dict], None] | None = None,
    T_world_base: np.ndarray | None = None,
    make_controller: Callable | None = None,
) -> RobotSetup | None:
    """The scene's robot, emulated (see the module docstring); None when the scene has no robot block.

    make_controller : ``(model, home) -> controller`` for a real robot's controller (ROS 2's: ``app.ros2``), default
    the emulated one.

    T_world_base : the base's calibrated pose (the database's), default the scene's nominal one (the drawing's,
    ``RobotSpec.nominal_base``; a ``Site`` then adopts the database's latest calibration of it). The emulated
    world keeps the scene's true base (``RobotSpec.T_world_base``).
    """
    spec = scene.robot
    if spec is None:
        return None
    from .urdf import load_scene_robot

    model, q0 = load_scene_robot(spec)
    if make_controller is not None:
        controller = make_controller(model, q0)
    else:
        controller = EmulatedController(model.joint_names, model.lower, model.upper, model.velocity, q0)
    try:
        world = EmulatedWorld(scene, model, controller, finger_joint=_finger(model), clock=clock, home=q0)
        T = spec.nominal_base if T_world_base is None else T_world_base
        feed = None
        if publish is not None:
            feed = RobotFeed(publish, model.name, lambda q: cell.T_world_base @ model.tool_pose(q), world.carried_name)
        cell = RobotCell(model, controller, T, publish=feed)
    except BaseException:
        controller.close()
        raise
    return RobotSetup(cell, world, controller)
