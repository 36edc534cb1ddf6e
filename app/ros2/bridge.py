"""``mcit serve --ros2``: the bridge's parts opened from the command line's flags (docs/ros2.md).

``Ros2Bridge.open(args)`` makes the node (None when neither ``--ros2`` nor a ``ros2:`` video asks for it);
``video(view, topic, ...)`` a camera's source, ``controller(model, q0)`` the robot's, ``attach(site)`` the feed's
publisher; ``close()`` releases them in order.
"""

from __future__ import annotations

import argparse
import logging
from typing import Any

import numpy as np

__all__ = ["ROS2_VIDEO_PREFIX", "Ros2Bridge", "add_ros2_arguments", "ros2_topic"]

log = logging.getLogger("mcit.ros2")

ROS2_VIDEO_PREFIX = "ros2:"


def ros2_topic(spec: Any) -> str | None:
    """The image topic of a ``--video`` source ``ros2:TOPIC`` (None for any other source); ValueError for a topic
    name ROS 2 refuses."""
    import re

    spec = str(spec)
    if not spec.startswith(ROS2_VIDEO_PREFIX):
        return None
    topic = spec[len(ROS2_VIDEO_PREFIX) :].strip()
    if not re.fullmatch(r"/?[A-Za-z_~][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*", topic):
        raise ValueError(
            f"--video {spec}: {topic!r} is not a ROS 2 topic name; give e.g. ros2:/camera/image_raw (letters, "
            "digits, _ and /)"
        )
    return topic if topic.startswith(("/", "~")) else "/" + topic


def add_ros2_arguments(p: argparse.ArgumentParser) -> None:
    """The serve command's ROS 2 flags."""
    from app.argtypes import number

    domain = number(int, lambda v: 0 <= v <= 232, kind="a DDS domain id (a whole number)", expected="0 to 232")
    g = p.add_argument_group("ROS 2 (the optional extra mcit[ros2]; docs/ros2.md)")
    g.add_argument(
        "--ros2",
        action="store_true",
        help="bridge to ROS 2: object poses, the database's markers and targets out; the robot's joint states in "
        "and its motions out (a --video ros2:TOPIC turns it on too)",
    )
    g.add_argument(
        "--ros2-domain", type=domain, default=None, metavar="ID", help="DDS domain id (default ROS_DOMAIN_ID, else 0)"
    )
    g.add_argument("--ros2-namespace", default="/mcit", metavar="NS", help="namespace of mcit's topics (default /mcit)")
    g.add_argument("--ros2-frame", default="world", metavar="FRAME", help="frame_id of mcit's world (default world)")
    g.add_argument(
        "--ros2-joint-states",
        default="/joint_states",
        metavar="TOPIC",
        help="the robot's sensor_msgs/JointState (default /joint_states)",
    )
    g.add_argument(
        "--ros2-trajectory",
        default="/joint_trajectory_controller/joint_trajectory",
        metavar="TOPIC",
        help="where the robot's motions go as trajectory_msgs/JointTrajectory "
        "(default /joint_trajectory_controller/joint_trajectory)",
    )


class Ros2Bridge:
    """The bridge's node and what was opened on it (see the module docstring)."""

    def __init__(self, node: Any, args: argparse.Namespace):
        self.node = node
        self.args = args
        self._closers: list = []

    @staticmethod
    def wanted(args: argparse.Namespace, video_specs: dict[str, str]) -> bool:
        """Whether the command line asks for the bridge; Ros2Unavailable (how to install it) when it does and
        ROS 2 is not installed, before anything is opened."""
        if not (getattr(args, "ros2", False) or any(ros2_topic(s) for s in video_specs.values())):
            return False
        from . import require

        require()
        return True

    @classmethod
    def open(cls, args: argparse.Namespace, video_specs: dict[str, str]) -> Ros2Bridge | None:
        if not cls.wanted(args, video_specs):
            return None
        from .node import Ros2Node

        node = Ros2Node("mcit", getattr(args, "ros2_domain", None))
        log.info("ROS 2: node /mcit on domain %d (Fast DDS)", node.domain)
        return cls(node, args)

    def video(self, topic: str, camera: Any, lens: Any, fps: float | None) -> Any:
        """A camera's ``RosImageSource`` on ``topic`` (camera: its ``core.camera.Camera``; lens: its lens or None)."""
        from .video import RosImageSource

        K, _ = camera.decompose()
        source = RosImageSource(
            self.node, topic, width=camera.width, height=camera.height, fps=fps or 30.0, K=K, has_lens=lens is not None
        )
        self._closers.append(source.close)
        return source

    def controller(self, model: Any, home: np.ndarray) -> Any:
        """The robot's ``RosController`` for ``model`` (an ``core.robot.RobotModel``)."""
        from .robot import RosController

        ctl = RosController(
            self.node,
            model.joint_names,
            model.lower,
            model.upper,
            model.velocity,
            home,
            joint_states=self.args.ros2_joint_states,
            trajectory=self.args.ros2_trajectory,
        )
        return ctl

    def attach(self, site: Any) -> Any:
        """Publish the site's poses, markers and targets (``Ros2Publisher``), from now on."""
        from .publisher import Ros2Publisher

        pub = Ros2Publisher(self.node, site, namespace=self.args.ros2_namespace, frame_id=self.args.ros2_frame)
        site.attach_feed(pub)
        self._closers.insert(0, pub.close)
        return pub

    def close(self) -> None:
        for close in self._closers:
            try:
                close()
            except Exception:  # noqa: BLE001 - at exit: the others still close
                log.debug("closing a ROS 2 part failed", exc_info=True)
        self.node.close()
