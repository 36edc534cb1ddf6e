"""The robot's controller through ROS 2 (``app.robot.controller``'s interface): joints from ``/joint_states``,
motions out as ``trajectory_msgs/JointTrajectory`` (ros2_control's joint_trajectory_controller takes them).

* Joint states may come in several messages (an arm's and a gripper's): each updates the joints it names. Names the
  URDF does not have are said once and left out; a URDF joint no message has named yet is drawn at its home value
  and said once; a message with a NaN position is dropped (said once).
* ``move(path)`` publishes the path, each segment timed by its slowest joint at ``speed_scale`` of the URDF's
  speed limits (as the emulated controller times it). The motion is under way until its time has passed and the
  joints have settled; a joint then farther than ``GOAL_TOL`` from its goal is the motion's fault, said.
* ``stop()`` publishes an empty trajectory (the controller's "hold where you are").
* No joint state for ``SILENT_S``: the controller does not answer (``ControllerSilent``), and the robot is not
  moved; Stop is still sent.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from app.robot.controller import ControllerError, ControllerSilent, JointState, StateListeners, path_times

from .messages import stamp_s, trajectory_message
from .node import Ros2Node, qos

__all__ = ["RosController", "SILENT_S", "GOAL_TOL", "SETTLE_S"]

log = logging.getLogger("mcit.ros2")

SILENT_S = 1.0  # no joint state for this long: the controller does not answer
GOAL_TOL = np.radians(0.5)  # a joint farther than this from its goal after a motion: a fault (rad, or m: 0.0087)
SETTLE_S = 1.0  # how long after a motion's time the joints may take to settle
RATE_HZ = 50.0  # the listeners are told at most this often (a 1 kHz driver would flood the interface)
EXPECTED_HZ = 500.0  # joint states faster than ten times this are said


class RosController(StateListeners):
    """The robot's controller over ROS 2 (see the module docstring).

    node : the bridge's ``Ros2Node``. names, lower, upper, velocity, home : the URDF's joints (mcit's order).
    joint_states, trajectory : the topics. speed_scale : the share of the speed limits a motion uses.
    """

    def __init__(
        self,
        node: Ros2Node,
        names: Sequence[str],
        lower: np.ndarray,
        upper: np.ndarray,
        velocity: np.ndarray,
        home: np.ndarray,
        *,
        joint_states: str = "/joint_states",
        trajectory: str = "/joint_trajectory_controller/joint_trajectory",
        speed_scale: float = 0.5,
    ):
        from sensor_msgs.msg import JointState as JointStateMsg
        from trajectory_msgs.msg import JointTrajectory

        self.node = node
        self.names = tuple(names)
        self.lower, self.upper = np.asarray(lower, float), np.asarray(upper, float)
        self.velocity = np.asarray(velocity, float)
        self.speed_scale = float(speed_scale)
        self.topics = (joint_states, trajectory)
        self._index = {n: k for k, n in enumerate(self.names)}
        self._lock = threading.RLock()  # a fault found while settling sends Stop under it
        self._q = np.asarray(home, float).copy()
        self._heard = np.zeros(len(self.names), bool)  # joints some message has named
        self._last_mono: float | None = None
        self._stamp: float | None = None
        self._goal: np.ndarray | None = None
        self._motion_end: float | None = None  # monotonic time the sent motion is due to end
        self._fault: str | None = None
        self._said: set[str] = set()
        super().__init__()
        self._told = 0.0
        self._arrivals: list[float] = []
        self._pub = node.node.create_publisher(JointTrajectory, trajectory, qos("events"))
        self._sub = node.node.create_subscription(JointStateMsg, joint_states, self._on_joint_state, qos("sensor"))

    # ------------------------------------------------------------------ in: joint states (the ROS thread)
    def _on_joint_state(self, msg: Any) -> None:
        now = time.monotonic()
        names, pos = list(msg.name), np.asarray(msg.position, float)
        if len(names) != len(pos):
            self._say("length", f"{self.topics[0]}: {len(names)} names but {len(pos)} positions: message dropped")
            return
        if not np.all(np.isfinite(pos)):
            self._say("nan", f"{self.topics[0]}: a joint state with NaN or infinite positions was dropped")
            return
        unknown = [n for n in names if n not in self._index]
        if unknown:
            self._say(
                "unknown",
                f"{self.topics[0]}: joints {unknown} are not the URDF's (its joints: {list(self.names)}): left out; "
                "check the robot's description against its driver",
            )
        with self._lock:
            for n, v in zip(names, pos):
                k = self._index.get(n)
                if k is not None:
                    self._q[k] = v
                    self._heard[k] = True
            self._last_mono = now
            self._stamp = stamp_s(msg.header.stamp) or time.time()
            self._arrivals.append(now)
            while self._arrivals and now - self._arrivals[0] > 1.0:
                self._arrivals.pop(0)
            rate = len(self._arrivals)
            self._settle_locked(now)
            state = self._state_locked()
            missing = [n for n, h in zip(self.names, self._heard) if not h]
            tell = now - self._told >= 1.0 / RATE_HZ or not state.moving
            if tell:
                self._told = now
        if missing and rate > 5:
            self._say("missing", f"{self.topics[0]}: no state of joints {missing}: drawn at their home values")
        if rate > 10 * EXPECTED_HZ:
            self._say("rate", f"{self.topics[0]}: {rate} joint states a second: the interface follows {RATE_HZ:g}/s")
        if tell:
            self._tell(state)

    def _settle_locked(self, now: float) -> None:
        """End the sent motion once its time (and the settling time) has passed, or the joints reached the goal;
        a joint short of its goal then is the motion's fault."""
        if self._motion_end is None or self._goal is None:
            return
        off = np.abs(self._q - self._goal)
        if now < self._motion_end and np.any(off > GOAL_TOL):
            return
        if now < self._motion_end + SETTLE_S and np.any(off > GOAL_TOL):
            return
        self._motion_end = None
        if np.any(off > GOAL_TOL):
            j = int(np.argmax(off))
            self._fault = (
                f"joint {self.names[j]} did not reach its command: {np.degrees(off[j]):.1f}° short after the "
                "motion's time; the robot is stopped where it is"
            )
            self.stop()

    def _say(self, kind: str, text: str) -> None:
        with self._lock:
            if kind in self._said:
                return
            self._said.add(kind)
        log.warning(text)

    def _state_locked(self) -> JointState:
        return JointState(
            self.names,
            self._q.copy(),
            self._motion_end is not None,
            time.monotonic(),
            self._fault,
            None if self._goal is None else self._goal.copy(),
            self._stamp,
        )

    # ------------------------------------------------------------------ the interface
    def state(self) -> JointState:
        with self._lock:
            if self._last_mono is None or time.monotonic() - self._last_mono > SILENT_S:
                since = "yet" if self._last_mono is None else f"for {time.monotonic() - self._last_mono:.0f} s"
                raise ControllerSilent(
                    f"no joint state on {self.topics[0]} {since}: is the robot's driver running (ros2 topic list)?"
                )
            self._settle_locked(time.monotonic())
            return self._state_locked()

    def move(self, path: np.ndarray) -> None:
        """Send ``path`` (k, n) as one JointTrajectory from where the robot is."""
        current = self.state()  # ControllerSilent when the robot does not answer: nothing sent
        P = np.atleast_2d(np.asarray(path, float))
        if P.ndim != 2 or P.shape[1] != len(self.names) or len(P) == 0 or not np.all(np.isfinite(P)):
            raise ControllerError(
                f"a path needs finite waypoints of {len(self.names)} joints, got shape {P.shape}; plan it for this "
                "robot"
            )
        out = np.flatnonzero(np.any((P < self.lower - 1e-9) | (P > self.upper + 1e-9), axis=0))
        if len(out):
            raise ControllerError(f"the path takes joint {self.names[int(out[0])]} outside its limits: not sent")
        with self._lock:
            if self._motion_end is not None:
                raise ControllerError("the robot is moving: stop it first, or wait for the motion to end")
            P = np.vstack([current.q, P])
            times = path_times(P, self.velocity * self.speed_scale)
            keep = np.concatenate([[True], np.diff(times) > 0])  # JTC refuses points not strictly later
            self._goal = P[-1].copy()
            self._fault = None
            self._motion_end = time.monotonic() + float(times[-1])
        self._pub.publish(trajectory_message(self.names, P[keep][1:], times[keep][1:]))

    def stop(self) -> None:
        """Hold where the robot is: an empty trajectory (sent even when the robot does not answer)."""
        with self._lock:
            self._motion_end = None
        self._pub.publish(trajectory_message(self.names, np.zeros((0, len(self.names))), np.zeros(0)))

    def _idle(self) -> bool:
        with self._lock:
            self._settle_locked(time.monotonic())
            return self._motion_end is None

    def close(self) -> None:
        try:
            self.node.node.destroy_subscription(self._sub)
            self.node.node.destroy_publisher(self._pub)
        except Exception:  # noqa: BLE001 - the node may be gone already
            pass
