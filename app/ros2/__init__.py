"""The ROS 2 bridge of ``mcit serve --ros2`` (the optional extra ``mcit[ros2]``: ROS 2 Jazzy's Python client
from the package registry, talking over Fast DDS). docs/ros2.md gives the topics, types, frames and QoS.

* ``node.Ros2Node``: mcit's node, in its own rclpy context (the domain id of ``--ros2-domain``), spun on a
  thread of its own.
* ``video.RosImageSource``: a camera's ``sensor_msgs/Image`` (and its ``CameraInfo``, checked against the
  camera's calibration) as a view's video source, each frame stamped with its header's time.
* ``robot.RosController``: the robot's controller as mcit sees it (``app.robot.controller``): its joints from
  ``sensor_msgs/JointState``, its motions sent as ``trajectory_msgs/JointTrajectory``.
* ``publisher.Ros2Publisher``: the site's feed (``app.feed``) out as ROS messages: each object's pose
  (``geometry_msgs/PoseStamped`` and ``PoseWithCovarianceStamped``, stamped with the capture time of the image it
  was measured on), the database as a latched ``visualization_msgs/MarkerArray``, targets as ``PointStamped``.

Nothing here is imported unless ``--ros2`` (or a ``ros2:`` video) is asked for; ``require()`` says in one line
how to install the extra when it is missing.
"""

from __future__ import annotations

__all__ = ["Ros2Unavailable", "require", "INSTALL_HINT"]

INSTALL_HINT = "pip install 'mcit[ros2]' (ROS 2 Jazzy's Python client from the package registry; no ROS install needed)"


class Ros2Unavailable(RuntimeError):
    """ROS 2's Python client (rclpy and the message packages) cannot be imported here."""


def require() -> None:
    """Ros2Unavailable, saying how to install it, when rclpy or a message package mcit uses is missing."""
    try:
        import geometry_msgs.msg  # noqa: F401
        import rclpy  # noqa: F401
        import sensor_msgs.msg  # noqa: F401
        import trajectory_msgs.msg  # noqa: F401
        import visualization_msgs.msg  # noqa: F401
    except ImportError as exc:
        raise Ros2Unavailable(
            f"ROS 2 is not installed in this Python ({exc.name} is missing): {INSTALL_HINT}"
        ) from None
