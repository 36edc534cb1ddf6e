"""The robot's side of the bridge, as a ROS 2 node of its own: it publishes a camera's images and CameraInfo and
the robot's joint states, and keeps what mcit publishes (object poses, markers, targets, trajectories). The tests,
``bench/ros2_latency.py`` and docs/ros2.md's try-out use it in place of a robot's ROS stack; it runs in its own
rclpy context, so it talks to mcit's node over DDS as another program's would.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from .messages import image_message, stamp_s, to_stamp
from .node import Ros2Node, qos

__all__ = ["RosPeer"]


class RosPeer:
    """A peer node (see the module docstring). domain : the DDS domain id; namespace : mcit's (``/mcit``)."""

    def __init__(self, domain: int, *, namespace: str = "/mcit", name: str = "mcit_peer"):
        from geometry_msgs.msg import PointStamped
        from sensor_msgs.msg import CameraInfo, Image, JointState
        from trajectory_msgs.msg import JointTrajectory
        from visualization_msgs.msg import MarkerArray

        self.ros = Ros2Node(name, domain)
        self.namespace = namespace.rstrip("/")
        self.lock = threading.Condition()
        self.poses: dict[str, list[tuple[float, Any]]] = {}  # topic → [(arrival, PoseStamped)]
        self.markers: list[tuple[float, Any]] = []
        self.targets: list[tuple[float, Any]] = []
        self.trajectories: list[tuple[float, Any]] = []
        n = self.ros.node
        self._Image, self._CameraInfo, self._JointState = Image, CameraInfo, JointState
        self._pubs: dict[str, Any] = {}
        self._subs = [
            n.create_subscription(MarkerArray, f"{self.namespace}/markers", self._keep(self.markers), qos("latched")),
            n.create_subscription(PointStamped, f"{self.namespace}/targets", self._keep(self.targets), qos("events")),
        ]
        self.watch_trajectories("/joint_trajectory_controller/joint_trajectory", JointTrajectory)

    def _keep(self, into: list):
        def on(msg: Any) -> None:
            with self.lock:
                into.append((time.time(), msg))
                self.lock.notify_all()

        return on

    def _pub(self, kind: Any, topic: str, profile: str = "events") -> Any:
        if topic not in self._pubs:
            self._pubs[topic] = self.ros.node.create_publisher(kind, topic, qos(profile))
        return self._pubs[topic]

    # ------------------------------------------------------------------ what the robot's side publishes
    def publish_image(self, rgb: np.ndarray, t: float, topic: str = "/camera/image_raw", encoding="rgb8") -> None:
        self._pub(self._Image, topic).publish(image_message(rgb, t, "camera", encoding))

    def publish_camera_info(
        self, K: np.ndarray, width: int, height: int, t: float, topic: str = "/camera/camera_info", d=()
    ) -> None:
        msg = self._CameraInfo(width=int(width), height=int(height), distortion_model="plumb_bob")
        msg.header.stamp, msg.header.frame_id = to_stamp(t), "camera"
        msg.k = [float(v) for v in np.asarray(K, float).reshape(9)]
        msg.d = [float(v) for v in d]
        self._pub(self._CameraInfo, topic).publish(msg)

    def publish_joints(self, names: Sequence[str], q: Sequence[float], t: float, topic: str = "/joint_states") -> None:
        msg = self._JointState(name=list(names), position=[float(v) for v in q])
        msg.header.stamp = to_stamp(t)
        self._pub(self._JointState, topic).publish(msg)

    # ------------------------------------------------------------------ what mcit publishes
    def watch_pose(self, object_token: str) -> str:
        """Keep the PoseStamped of one object (its topic token); returns the topic."""
        from geometry_msgs.msg import PoseStamped

        topic = f"{self.namespace}/objects/{object_token}/pose"
        into = self.poses.setdefault(topic, [])
        self._subs.append(self.ros.node.create_subscription(PoseStamped, topic, self._keep(into), qos("latched")))
        return topic

    def watch_trajectories(self, topic: str, kind: Any = None) -> None:
        if kind is None:
            from trajectory_msgs.msg import JointTrajectory as kind
        self._subs.append(self.ros.node.create_subscription(kind, topic, self._keep(self.trajectories), qos("events")))

    def wait(self, predicate, timeout_s: float = 30.0) -> bool:
        """Wait until ``predicate()`` (checked under the lock, on each message); False on timeout."""
        with self.lock:
            return self.lock.wait_for(predicate, timeout=timeout_s)

    @staticmethod
    def stamp_of(msg: Any) -> float:
        return stamp_s(msg.header.stamp)

    def close(self) -> None:
        self.ros.close()
