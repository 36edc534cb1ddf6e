"""ROS 2 messages ↔ mcit's values: stamps, images, camera info, poses, markers, trajectories.

Images: the encodings of ``sensor_msgs/image_encodings`` that cameras publish — rgb8, bgr8, rgba8, bgra8, mono8,
mono16 (and 8UC1/8UC3/16UC1 read as mono8/bgr8/mono16), the four 8-bit Bayer patterns, yuv422 (UYVY) and
yuv422_yuy2 (YUYV) — with their row ``step`` and byte order; any other is refused with ``UnsupportedEncoding``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = [
    "UnsupportedEncoding",
    "ENCODINGS",
    "stamp_s",
    "to_stamp",
    "image_rgb",
    "image_message",
    "camera_info_disagreement",
    "pose_message",
    "pose_cov_message",
    "point_message",
    "object_markers",
    "trajectory_message",
    "topic_token",
]


class UnsupportedEncoding(ValueError):
    """An image encoding mcit cannot read."""


# encoding → (OpenCV conversion to RGB or None, channels, bytes per channel)
_CV = {
    "rgb8": (None, 3, 1),
    "bgr8": ("COLOR_BGR2RGB", 3, 1),
    "8UC3": ("COLOR_BGR2RGB", 3, 1),
    "rgba8": ("COLOR_RGBA2RGB", 4, 1),
    "bgra8": ("COLOR_BGRA2RGB", 4, 1),
    "mono8": ("COLOR_GRAY2RGB", 1, 1),
    "8UC1": ("COLOR_GRAY2RGB", 1, 1),
    "mono16": ("COLOR_GRAY2RGB", 1, 2),
    "16UC1": ("COLOR_GRAY2RGB", 1, 2),
    # OpenCV names a Bayer pattern by its second row's first two pixels: ROS's rggb8 is OpenCV's BayerBG
    "bayer_rggb8": ("COLOR_BayerBG2RGB", 1, 1),
    "bayer_bggr8": ("COLOR_BayerRG2RGB", 1, 1),
    "bayer_gbrg8": ("COLOR_BayerGR2RGB", 1, 1),
    "bayer_grbg8": ("COLOR_BayerGB2RGB", 1, 1),
    "yuv422": ("COLOR_YUV2RGB_UYVY", 2, 1),
    "uyvy": ("COLOR_YUV2RGB_UYVY", 2, 1),
    "yuv422_yuy2": ("COLOR_YUV2RGB_YUY2", 2, 1),
    "yuyv": ("COLOR_YUV2RGB_YUY2", 2, 1),
}
ENCODINGS = tuple(_CV)


def stamp_s(stamp: Any) -> float:
    """A ``builtin_interfaces/Time`` as unix seconds."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def to_stamp(t: float) -> Any:
    """Unix seconds as a ``builtin_interfaces/Time``."""
    from builtin_interfaces.msg import Time

    ns = int(round(float(t) * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def image_rgb(msg: Any) -> np.ndarray:
    """A ``sensor_msgs/Image`` as RGB uint8 (H, W, 3); UnsupportedEncoding for an encoding not in
    ``ENCODINGS``, ValueError for a message whose data does not hold its size."""
    import cv2

    enc = str(msg.encoding)
    if enc not in _CV:
        raise UnsupportedEncoding(
            f"images in encoding {enc!r} cannot be read; publish one of {', '.join(ENCODINGS[:6])} (or a Bayer "
            "or YUV 4:2:2 encoding), e.g. through image_proc"
        )
    code, channels, depth = _CV[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * channels * depth
    data = np.frombuffer(bytes(msg.data) if not isinstance(msg.data, (bytes, np.ndarray)) else msg.data, np.uint8)
    if h <= 0 or w <= 0 or step < row or data.size < step * (h - 1) + row:
        raise ValueError(f"a {w}×{h} {enc} image with step {step} needs {step * h} bytes, got {data.size}")
    rows = np.lib.stride_tricks.as_strided(data, shape=(h, row), strides=(step, 1))
    if depth == 2:
        dtype = np.dtype(">u2" if msg.is_bigendian else "<u2")
        img = np.ascontiguousarray(rows).view(dtype).reshape(h, w)
        img = (img >> 8).astype(np.uint8)  # the display's 8 bits: the high byte
    else:
        img = np.ascontiguousarray(rows).reshape(h, w, channels) if channels > 1 else np.ascontiguousarray(rows)
    if code is None:
        return img
    return np.ascontiguousarray(cv2.cvtColor(img, getattr(cv2, code)))


def image_message(rgb: np.ndarray, t: float, frame_id: str, encoding: str = "rgb8") -> Any:
    """An RGB uint8 (H, W, 3) image as a ``sensor_msgs/Image`` in ``encoding`` (rgb8, bgr8 or mono8)."""
    import cv2
    from sensor_msgs.msg import Image

    rgb = np.asarray(rgb, np.uint8)
    if encoding == "bgr8":
        data = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    elif encoding == "mono8":
        data = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    elif encoding == "rgb8":
        data = rgb
    else:
        raise ValueError(f"image_message writes rgb8, bgr8 or mono8, not {encoding!r}")
    msg = Image()
    msg.header.stamp = to_stamp(t)
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(rgb.shape[0]), int(rgb.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(data.shape[1] * (1 if data.ndim == 2 else data.shape[2]))
    msg.data = np.ascontiguousarray(data).tobytes()
    return msg


def camera_info_disagreement(msg: Any, K: np.ndarray, width: int, height: int, has_lens: bool) -> str:
    """ "" when a ``sensor_msgs/CameraInfo`` agrees with mcit's camera (its size, and K within 1 % of the focal
    lengths and 2 px of the principal point); else what differs, as a sentence."""
    w, h = int(msg.width), int(msg.height)
    if (w, h) != (int(width), int(height)):
        return (
            f"CameraInfo says {w}×{h} images but mcit's camera is calibrated for {width}×{height}: give the camera "
            "file of this camera (mcit site new --camera, or --intrinsics) or Calibrate camera"
        )
    k = np.asarray(msg.k, float).reshape(3, 3)
    if not np.any(k):
        return ""  # an uncalibrated camera's info carries no K: nothing to compare
    K = np.asarray(K, float)
    f_off = np.abs(k[[0, 1], [0, 1]] / K[[0, 1], [0, 1]] - 1.0).max()
    c_off = np.abs(k[[0, 1], [2, 2]] - K[[0, 1], [2, 2]]).max()
    if f_off > 0.01 or c_off > 2.0:
        return (
            f"CameraInfo's K (fx {k[0, 0]:.1f}, fy {k[1, 1]:.1f}, cx {k[0, 2]:.1f}, cy {k[1, 2]:.1f}) differs from "
            f"mcit's camera (fx {K[0, 0]:.1f}, fy {K[1, 1]:.1f}, cx {K[0, 2]:.1f}, cy {K[1, 2]:.1f}): the overlay "
            "may not lie on the image; give this camera's file or Calibrate camera"
        )
    d = np.asarray(msg.d, float)
    if not has_lens and d.size and np.abs(d).max() > 1e-3:
        return (
            f"CameraInfo gives lens distortion ({msg.distortion_model}, {np.round(d[:5], 4).tolist()}) but mcit's "
            "camera has none: frames are not undistorted; give the camera file with its lens (--intrinsics)"
        )
    return ""


def _pose(T: np.ndarray) -> Any:
    from geometry_msgs.msg import Point, Pose, Quaternion

    from app.db.export import quat_xyzw

    T = np.asarray(T, float)
    x, y, z, w = quat_xyzw(T[:3, :3])
    return Pose(
        position=Point(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
        orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)),
    )


def pose_message(T: np.ndarray, t: float, frame_id: str) -> Any:
    """A 4×4 pose as a ``geometry_msgs/PoseStamped``."""
    from geometry_msgs.msg import PoseStamped

    msg = PoseStamped(pose=_pose(T))
    msg.header.stamp, msg.header.frame_id = to_stamp(t), frame_id
    return msg


def pose_cov_message(T: np.ndarray, cov: np.ndarray | None, t: float, frame_id: str) -> Any:
    """A 4×4 pose and its 6×6 covariance (δt, δr about the world's axes, as ROS orders it) as a
    ``geometry_msgs/PoseWithCovarianceStamped``; an unknown covariance is all −1 (REP 103's "unknown")."""
    from geometry_msgs.msg import PoseWithCovarianceStamped

    msg = PoseWithCovarianceStamped()
    msg.header.stamp, msg.header.frame_id = to_stamp(t), frame_id
    msg.pose.pose = _pose(T)
    C = np.full(36, -1.0) if cov is None else np.asarray(cov, float).reshape(36)
    msg.pose.covariance = [float(v) for v in C]
    return msg


def point_message(xyz: Sequence[float], t: float, frame_id: str) -> Any:
    """A point as a ``geometry_msgs/PointStamped``."""
    from geometry_msgs.msg import PointStamped

    msg = PointStamped()
    msg.header.stamp, msg.header.frame_id = to_stamp(t), frame_id
    msg.point.x, msg.point.y, msg.point.z = (float(v) for v in xyz)
    return msg


# an object's colour by status, as the interface draws it (known white, modelled yellow, stale red)
_STATUS_RGBA = {"known": (1.0, 1.0, 1.0, 1.0), "modelled": (1.0, 0.85, 0.2, 1.0), "stale": (1.0, 0.25, 0.25, 1.0)}


def object_markers(objects: Sequence[Any], t: float, frame_id: str, line_width_m: float = 0.004) -> Any:
    """The database as a ``visualization_msgs/MarkerArray``: a DELETEALL first (objects removed since go), then
    for each object (``app.workflows.site.SiteObject``-like: name, status, model, T_world_obj) its edges as a
    LINE_LIST at its pose (id 0), its name as a TEXT_VIEW_FACING above it (id 1) and its surface as a translucent
    TRIANGLE_LIST (id 2); ``ns`` is the object's name."""
    from geometry_msgs.msg import Point
    from visualization_msgs.msg import Marker, MarkerArray

    stamp = to_stamp(t)
    out = MarkerArray()
    clear = Marker(action=Marker.DELETEALL)
    clear.header.frame_id = frame_id
    out.markers.append(clear)
    for obj in objects:
        r, g, b, a = _STATUS_RGBA.get(obj.status, _STATUS_RGBA["known"])
        edges = obj.model.edge_segments()  # (E, 2, 3) in the object's frame
        lines = Marker(type=Marker.LINE_LIST, action=Marker.ADD, ns=obj.name, id=0, pose=_pose(obj.T_world_obj))
        lines.header.stamp, lines.header.frame_id = stamp, frame_id
        lines.scale.x = float(line_width_m)
        lines.color.r, lines.color.g, lines.color.b, lines.color.a = r, g, b, a
        lines.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in edges.reshape(-1, 3)]
        out.markers.append(lines)
        V, F = obj.model.triangles()  # its surface, translucent (a cylinder's round faces have no edges to draw)
        faces = Marker(type=Marker.TRIANGLE_LIST, action=Marker.ADD, ns=obj.name, id=2, pose=lines.pose)
        faces.header.stamp, faces.header.frame_id = stamp, frame_id
        faces.scale.x = faces.scale.y = faces.scale.z = 1.0
        faces.color.r, faces.color.g, faces.color.b, faces.color.a = r, g, b, 0.25
        faces.points = [
            Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in np.asarray(V)[np.asarray(F)].reshape(-1, 3)
        ]
        out.markers.append(faces)
        top = obj.T_world_obj @ np.array([0.0, 0.0, 0.0, 1.0])
        if len(edges):
            top[2] = float((obj.T_world_obj[:3, :3] @ edges.reshape(-1, 3).T)[2].max() + obj.T_world_obj[2, 3])
        text = Marker(type=Marker.TEXT_VIEW_FACING, action=Marker.ADD, ns=obj.name, id=1, text=obj.name)
        text.header.stamp, text.header.frame_id = stamp, frame_id
        text.pose.position.x, text.pose.position.y, text.pose.position.z = float(top[0]), float(top[1]), top[2] + 0.04
        text.pose.orientation.w = 1.0
        text.scale.z = 0.04
        text.color.r, text.color.g, text.color.b, text.color.a = r, g, b, a
        out.markers.append(text)
    return out


def trajectory_message(names: Sequence[str], path: np.ndarray, times: np.ndarray) -> Any:
    """A joint path (k, n) reached at ``times`` (k,) seconds from its start as a
    ``trajectory_msgs/JointTrajectory``. Its stamp is zero: "start on arrival" for ros2_control's
    joint_trajectory_controller (a stamp already past when it arrives would skip the path's start). No points:
    the controller's "stop where you are"."""
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    msg = JointTrajectory(joint_names=list(names))
    for q, s in zip(np.asarray(path, float), np.asarray(times, float)):
        ns = int(round(s * 1e9))
        msg.points.append(
            JointTrajectoryPoint(
                positions=[float(v) for v in q], time_from_start=Duration(sec=ns // 1_000_000_000, nanosec=ns % 10**9)
            )
        )
    return msg


def topic_token(name: str) -> str:
    """An object's name as one token of a ROS topic name: letters, digits and single underscores, not starting
    with a digit ("Box 2" → "Box_2", "2nd" → "o_2nd")."""
    import re

    token = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", name)).strip("_") or "object"
    return f"o_{token}" if token[0].isdigit() else token
