"""A camera's ROS 2 images as a view's video source (``mcit serve --video [NAME=]ros2:TOPIC``).

``RosImageSource`` subscribes to ``sensor_msgs/Image`` on TOPIC and to ``sensor_msgs/CameraInfo`` beside it
(image_transport's convention: ``/camera/image_raw`` → ``/camera/camera_info``). Each frame is the newest image,
decoded on the video's thread (the ROS thread only keeps it), stamped with its header's time: a pose measured on it
goes out with that stamp. What does not fit is said once in the video's status (``warning``) and logged, and the
video goes on: an encoding mcit cannot read (those frames are dropped), a CameraInfo that contradicts the camera's
calibration, images arriving at ten times the expected rate or more (only the newest is shown).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import numpy as np

from app.video import VideoSource

from .messages import UnsupportedEncoding, camera_info_disagreement, image_rgb, stamp_s
from .node import Ros2Node, qos

__all__ = ["RosImageSource", "info_topic_of", "FIRST_FRAME_WAIT_S", "FLOOD_FACTOR"]

log = logging.getLogger("mcit.ros2")

FIRST_FRAME_WAIT_S = 3.0  # how long opening waits for a first image (its size); the camera's size meanwhile
FLOOD_FACTOR = 10.0  # images at this many times the expected rate are said


def info_topic_of(image_topic: str) -> str:
    """The CameraInfo topic beside an image topic: the last name replaced by ``camera_info``."""
    head = image_topic.rstrip("/").rsplit("/", 1)[0] if "/" in image_topic.strip("/") else ""
    return f"{head}/camera_info" if head else "camera_info"


class RosImageSource(VideoSource):
    """One camera's images from ROS 2 (see the module docstring).

    node : the bridge's ``Ros2Node``. topic : the image topic. width, height : the camera's calibrated size (the
    source's size until a first image says otherwise). fps : the expected rate. K, has_lens : the camera's
    intrinsics and whether mcit undistorts its frames (to check CameraInfo against).
    """

    live = True
    reconnects = False  # DDS rediscovers a publisher that comes back by itself

    def __init__(
        self,
        node: Ros2Node,
        topic: str,
        *,
        width: int,
        height: int,
        fps: float = 30.0,
        K: np.ndarray | None = None,
        has_lens: bool = False,
        info_topic: str | None = None,
    ):
        super().__init__()
        from sensor_msgs.msg import CameraInfo, Image

        self.node, self.topic = node, topic
        self.info_topic = info_topic or info_topic_of(topic)
        self.width, self.height, self.fps = int(width), int(height), float(fps)
        self.description = f"ROS 2 {topic}"
        self.K, self.has_lens = K, has_lens
        self._cond = threading.Condition()
        self._msg: Any = None
        self._new = False
        self._closed = False
        self._last_stamp: float | None = None
        self._said: dict[str, str] = {}  # what was said once, by kind (the status shows them)
        self._arrivals: list[float] = []
        self.received = 0
        self._subs = [
            node.node.create_subscription(Image, topic, self._on_image, qos("sensor")),
            node.node.create_subscription(CameraInfo, self.info_topic, self._on_info, qos("sensor")),
        ]
        with self._cond:  # the first image's size, when one comes soon
            self._cond.wait_for(lambda: self._msg is not None, timeout=FIRST_FRAME_WAIT_S)
            if self._msg is not None:
                self.width, self.height = int(self._msg.width), int(self._msg.height)

    # ------------------------------------------------------------------ on the ROS thread: keep, return
    def _on_image(self, msg: Any) -> None:
        now = time.monotonic()
        with self._cond:
            self._msg, self._new = msg, True
            self.received += 1
            self._arrivals.append(now)
            while self._arrivals and now - self._arrivals[0] > 1.0:
                self._arrivals.pop(0)
            rate = len(self._arrivals)
            self._cond.notify_all()
        if rate >= FLOOD_FACTOR * self.fps and rate >= 20:
            self._say(
                "rate",
                f"{self.topic}: images arrive at {rate}/s, {rate / self.fps:.0f}× the expected {self.fps:g}/s: only "
                "the newest is shown (give --fps if that rate is meant)",
            )

    def _on_info(self, msg: Any) -> None:
        if self.K is None or "info" in self._said:
            return
        why = camera_info_disagreement(msg, self.K, self.width, self.height, self.has_lens)
        if why:
            self._say("info", f"{self.info_topic}: {why}")

    def _say(self, kind: str, text: str) -> None:
        with self._cond:
            if kind in self._said:
                return
            self._said[kind] = text
        log.warning(text)

    @property
    def warning(self) -> str:
        """What the operator must know of this camera's ROS input ("" when nothing)."""
        with self._cond:
            return "; ".join(self._said.values())

    # ------------------------------------------------------------------ on the video's thread
    def _read(self) -> np.ndarray | None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._new or self._closed)
                if self._closed:
                    return None
                msg, self._new = self._msg, False
            try:
                image = image_rgb(msg)
            except UnsupportedEncoding as exc:
                self._say("encoding", f"{self.topic}: {exc}")
                continue
            except ValueError as exc:
                self._say("malformed", f"{self.topic}: a malformed image was dropped ({exc})")
                continue
            if image.shape[:2] != (self.height, self.width):
                self._say(
                    "size",
                    f"{self.topic}: images of {image.shape[1]}×{image.shape[0]} after {self.width}×{self.height} ones "
                    "are dropped; restart mcit serve for the new size",
                )
                continue
            self._last_stamp = stamp_s(msg.header.stamp) or None  # a zero stamp: the publisher gave none
            return image

    def _stamp(self) -> float | None:
        return self._last_stamp if self._last_stamp is not None else time.time()

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        for sub in self._subs:
            try:
                self.node.node.destroy_subscription(sub)
            except Exception:  # noqa: BLE001 - the node may be gone already
                pass
        self._subs = []
