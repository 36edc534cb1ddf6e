"""mcit's ROS 2 node: its own rclpy context (so that a program, or a test, may run other nodes beside it), the
domain id asked for, and an executor spun on a thread of its own. Callbacks run on that thread: they must be
quick (the video's and the robot's keep the newest message and return).

QoS (docs/ros2.md): ``SENSOR`` for what mcit reads (best effort, keep last 5: it matches reliable and best-effort
publishers, and a late message is worth less than the next); ``LATCHED`` for what a viewer joining later must
still get (reliable, transient local, keep last 1: the database's markers, each object's pose); ``EVENTS`` for
what mcit sends that must arrive (reliable, volatile, keep last 10: targets, trajectories).
"""

from __future__ import annotations

import logging
import os
import threading

from . import require

__all__ = ["Ros2Node", "qos"]

log = logging.getLogger("mcit.ros2")


def qos(kind: str):
    """The QoS profile of one kind of topic: "sensor", "latched" or "events" (see the module docstring)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    if kind == "sensor":
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=5,
            reliability=ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.VOLATILE,
        )
    if kind == "latched":
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
    if kind == "events":
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=10,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
    raise ValueError(f"unknown QoS kind {kind!r}: sensor, latched or events")


def domain_id(value: int | None) -> int:
    """The domain id: ``value``, else ROS_DOMAIN_ID, else 0; ValueError outside 0..232 (DDS's range)."""
    if value is None:
        env = os.environ.get("ROS_DOMAIN_ID", "").strip()
        if not env:
            return 0
        try:
            value = int(env)
        except ValueError:
            raise ValueError(
                f"ROS_DOMAIN_ID={env!r} is not a number; set it to 0..232, or give --ros2-domain"
            ) from None
    if not 0 <= int(value) <= 232:
        raise ValueError(f"ROS 2 domain id {value} is outside 0..232; give one in that range")
    return int(value)


class Ros2Node:
    """One rclpy node in its own context, spun on a thread (see the module docstring).

    name : the node's name. domain : the DDS domain id (None: ROS_DOMAIN_ID, else 0). ``node`` is the rclpy
    node (publishers and subscriptions are made on it); ``close()`` stops the thread and shuts the context down.
    """

    def __init__(self, name: str = "mcit", domain: int | None = None):
        require()
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.domain = domain_id(domain)
        self.context = Context()
        # mcit's own Ctrl-C and SIGTERM handling stays: rclpy installs none
        rclpy.init(context=self.context, domain_id=self.domain, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self.node = rclpy.create_node(name, context=self.context)
            self.executor = SingleThreadedExecutor(context=self.context)
            self.executor.add_node(self.node)
        except BaseException:
            rclpy.shutdown(context=self.context)
            raise
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._spin, name="mcit-ros2", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        while not self._closed.is_set():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except ExternalShutdownException:
                return
            except Exception:  # noqa: BLE001 - a callback's bug is logged; the node keeps spinning
                if self._closed.is_set() or not self.context.ok():
                    return
                log.exception("a ROS 2 callback failed")

    def now(self) -> float:
        """The node clock's time (unix seconds)."""
        return self.node.get_clock().now().nanoseconds * 1e-9

    def close(self) -> None:
        """Stop spinning, destroy the node and shut its context down (idempotent)."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._thread.join(timeout=2.0)
        import rclpy

        try:
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        finally:
            if self.context.ok():
                rclpy.shutdown(context=self.context)
