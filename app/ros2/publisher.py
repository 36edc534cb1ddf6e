"""The site's feed out as ROS 2 messages (a feed sink: ``Site.attach_feed``).

Under the namespace (``/mcit`` by default), in the world frame (``frame_id``):

* ``objects/<name>/pose`` (``geometry_msgs/PoseStamped``, latched) and ``objects/<name>/pose_with_covariance``
  (``PoseWithCovarianceStamped``, latched): an object's pose on each change, stamped with the capture time of the
  image it was measured on (the change's time when it was not measured on an image). ``<name>`` is the object's
  name as a topic token (``messages.topic_token``);
* ``markers`` (``visualization_msgs/MarkerArray``, latched): the whole database, again after each change;
* ``targets`` (``geometry_msgs/PointStamped``): each designated target, stamped with its image's capture time.

``publish`` never blocks its caller (the database's writer): lines are queued and sent from a thread of the
bridge's; the markers of a burst of changes are built once.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any

import numpy as np

from .messages import object_markers, point_message, pose_cov_message, pose_message, topic_token
from .node import Ros2Node, qos

__all__ = ["Ros2Publisher"]

log = logging.getLogger("mcit.ros2")


class Ros2Publisher:
    """See the module docstring. site : the ``app.workflows.Site`` (its objects, for the markers)."""

    def __init__(self, node: Ros2Node, site: Any, *, namespace: str = "/mcit", frame_id: str = "world"):
        from geometry_msgs.msg import PointStamped
        from visualization_msgs.msg import MarkerArray

        self.node, self.site = node, site
        self.namespace = "/" + namespace.strip("/") if namespace.strip("/") else ""
        self.frame_id = frame_id
        self._markers = node.node.create_publisher(MarkerArray, f"{self.namespace}/markers", qos("latched"))
        self._targets = node.node.create_publisher(PointStamped, f"{self.namespace}/targets", qos("events"))
        self._poses: dict[str, tuple[Any, Any]] = {}  # object name → (PoseStamped, PoseWithCovariance) publishers
        self._topics: dict[str, str] = {}  # object name → its token (unique)
        self._queue: queue.Queue = queue.Queue()
        self.sent = 0  # messages published (benches, tests)
        self._thread = threading.Thread(target=self._run, name="mcit-ros2-out", daemon=True)
        self._thread.start()
        for rec in site.db.objects():  # every object as it stands, for a viewer that starts before any change
            self.publish(
                {"type": "pose", "object": rec.name, "T": rec.T_world_obj, "cov": rec.cov, "time": rec.updated_at}
            )

    def topic_of(self, name: str) -> str:
        """The pose topic of object ``name`` (one topic per name: a clash of tokens gets a suffix)."""
        token = self._topics.get(name)
        if token is None:
            token, k = topic_token(name), 2
            taken = set(self._topics.values())
            while token in taken:
                token, k = f"{topic_token(name)}_{k}", k + 1
            self._topics[name] = token
        return f"{self.namespace}/objects/{token}/pose"

    # ------------------------------------------------------------------ the feed's side
    def publish(self, event: dict | None) -> None:
        if event is not None and event.get("type") in ("pose", "removed", "target"):
            self._queue.put(event)

    def close(self) -> None:
        self._queue.put(None)
        self._thread.join(timeout=2.0)

    # ------------------------------------------------------------------ the bridge's thread
    def _run(self) -> None:
        while True:
            event = self._queue.get()
            if event is None:
                return
            batch = [event]
            while True:  # a burst of changes: one marker array for all
                try:
                    more = self._queue.get_nowait()
                except queue.Empty:
                    break
                if more is None:
                    self._send(batch)
                    return
                batch.append(more)
            self._send(batch)

    def _send(self, events: list[dict]) -> None:
        changed = False
        for ev in events:
            try:
                if ev["type"] == "pose":
                    self._send_pose(ev)
                    changed = True
                elif ev["type"] == "removed":
                    changed = True
                else:
                    self._send_target(ev)
            except Exception:  # noqa: BLE001 - one bad line is logged; the bridge goes on
                log.exception("a %s line could not be sent on ROS 2", ev.get("type"))
        if changed:
            try:
                objects = self.site.objects()
                self._markers.publish(object_markers(objects, time.time(), self.frame_id))
                self.sent += 1
            except Exception:  # noqa: BLE001
                log.exception("the database's markers could not be sent on ROS 2")

    def _send_pose(self, ev: dict) -> None:
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped

        name = ev["object"]
        if name not in self._poses:
            topic = self.topic_of(name)
            self._poses[name] = (
                self.node.node.create_publisher(PoseStamped, topic, qos("latched")),
                self.node.node.create_publisher(PoseWithCovarianceStamped, f"{topic}_with_covariance", qos("latched")),
            )
        T = np.asarray(ev["T"], float)
        cov = ev.get("cov")
        t = ev.get("image_time") or ev.get("time") or time.time()
        plain, with_cov = self._poses[name]
        plain.publish(pose_message(T, t, self.frame_id))
        with_cov.publish(pose_cov_message(T, None if cov is None else np.asarray(cov, float), t, self.frame_id))
        self.sent += 2

    def _send_target(self, ev: dict) -> None:
        t = ev.get("image_time") or ev.get("time") or time.time()
        self._targets.publish(point_message(ev["xyz_m"], t, self.frame_id))
        self.sent += 1
