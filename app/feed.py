"""The live feed: accepted pose changes and designated targets, as JSON lines, for the robot's software.

Another program (a robot controller) reads the feed from a local Unix socket or from a file that
mcit appends to (docs/exchange.md gives the schema, ``mcit-feed/1``). Each line is one JSON object:

* ``{"type": "pose", ...}``: an object's pose after a change (added, moved, its status changed, an
  undo or restore) — or, with ``"action": "current"``, as it stands when a reader connects (a socket
  reader first receives every object's current pose, then the changes) or when the feed starts (file).
  Fields: those of ``app.db.export.object_record`` (object, version, ``T``, ``xyz_m``,
  ``quat_xyzw``, ``rotvec_rad``, ``sigma``, ``cov``, who, method, time, time_iso), plus ``seq`` (the
  history's change number; None for "current"), ``action`` and ``moved`` (the pose differs from
  before the change).
* ``{"type": "removed", ...}``: the object left the database (removed, or the undo of its addition).
* ``{"type": "target", ...}``: a target the operator designated (Designate target): the point to
  send (``xyz_m``: the range finder's point where it disagrees with the database, else the
  database's), the target frame ``T`` / ``quat_xyzw`` (z into the surface), the object and its version,
  the σ along the line of sight, the range finder's check and warning, who and when.
* ``{"type": "robot", ...}``: the robot's joint state (``robot_event``): joint positions by name, the
  tool's pose ``T`` in the world, moving or stopped, a fault; on each change of state and at least
  once a second while it moves.

Every line carries ``"feed": "mcit-feed/1"``. Lines are written whole (one ``write`` each, ending in
``\\n``); a reader may see the same object version twice (a change that happened while it
connected): ``(object_id, version)`` identifies a state.

``FeedPublisher(file=..., socket_path=..., snapshot=...)`` publishes: ``publish(event)`` never
blocks the caller (a writer thread sends); a socket reader that does not keep up (its buffer full for
2 s) is disconnected, and may reconnect. ``follow(path)`` is a reader (socket or file) for Python
programs and the tests.
"""

from __future__ import annotations

import json
import logging
import os
import queue
import socket
import stat
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from app.db.export import iso, object_record, pose_fields

__all__ = [
    "FEED_FORMAT",
    "WORLD_FRAME",
    "FeedFanout",
    "change_event",
    "object_event",
    "target_event",
    "robot_event",
    "FeedPublisher",
    "follow",
]

log = logging.getLogger("mcit.feed")

FEED_FORMAT = "mcit-feed/1"
SEND_TIMEOUT_S = 2.0


WORLD_FRAME = "world"  # the frame every pose and point of the feed is given in (ROS 2's frame_id too)


def _header(kind: str) -> dict[str, Any]:
    return {"feed": FEED_FORMAT, "type": kind, "frame_id": WORLD_FRAME}


def object_event(rec: Any, *, who: str | None = None, method: str | None = None) -> dict[str, Any]:
    """The ``pose`` line of an object as it stands (an ``app.db.ObjectRecord``): action "current"."""
    ev = _header("pose")
    ev.update({"seq": None, "action": "current", "moved": False, "image_time": None})
    ev.update(
        object_record(
            rec.name,
            rec.id,
            rec.kind,
            rec.status,
            rec.version,
            rec.T_world_obj,
            rec.cov,
            who=who,
            method=method,
            when=rec.updated_at,
        )
    )
    return ev


def change_event(rec: Any) -> dict[str, Any] | None:
    """The line of one history change (an ``app.db.ChangeRecord``): ``pose``, ``removed``, or None
    for a change that is not an object's (a calibration)."""
    if rec.object_id is None or rec.action == "calibration":
        return None
    after, before = rec.after or {}, rec.before or {}
    if not after or after.get("removed"):
        ev = _header("removed")
        ev.update(
            {
                "seq": int(rec.id),
                "action": rec.action,
                "object": rec.object_name,
                "object_id": rec.object_id,
                "version": rec.version,
                "who": rec.client,
                "method": rec.method,
                "time": float(rec.time),
                "time_iso": iso(rec.time),
            }
        )
        return ev
    T = np.asarray(after["T_world_obj"], float)
    moved = (
        not before or bool(before.get("removed")) or not np.array_equal(np.asarray(before.get("T_world_obj"), float), T)
    )
    cov = after.get("cov")
    ev = _header("pose")
    seen = getattr(rec, "seen_at", None)
    ev.update({"seq": int(rec.id), "action": rec.action, "moved": bool(moved), "image_time": seen})
    ev.update(
        object_record(
            after.get("name", rec.object_name),
            rec.object_id,
            after.get("kind"),
            after.get("status"),
            rec.version,
            T,
            None if cov is None else np.asarray(cov, float),
            who=rec.client,
            method=rec.method,
            when=rec.time,
        )
    )
    return ev


def _target_frame(X: np.ndarray, normal: np.ndarray, camera_centre: np.ndarray | None) -> np.ndarray:
    """T_world_target (4, 4): origin X; z into the surface (−normal), or along the line of sight when
    the normal is unknown; x horizontal where it can be (perpendicular to the world's z)."""
    n = np.asarray(normal, float)
    if np.all(np.isfinite(n)) and np.linalg.norm(n) > 0:
        z = -n / np.linalg.norm(n)
    elif camera_centre is not None:
        z = X - np.asarray(camera_centre, float)
        z = z / np.linalg.norm(z)
    else:
        z = np.array([0.0, 0.0, -1.0])
    a = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = X
    return T


def target_event(
    target: Any,
    *,
    index: int,
    who: str,
    when: float,
    version: int | None,
    camera_centre: np.ndarray | None = None,
    image_time: float | None = None,
) -> dict[str, Any]:
    """The ``target`` line of a designated target (``app.workflows.designate.Target``).

    index : the target's number in the operator's list (1, 2, …). version : the object's database
    version the target was found on (None when the point is not on a database object). image_time : when
    the image it was clicked on was taken (unix seconds; None: not known).
    """
    X_db = np.asarray(target.X_world, float)
    rf = None if target.rangefinder_X is None else np.asarray(target.rangefinder_X, float)
    use_rf = bool(target.warning) and rf is not None and bool(np.all(np.isfinite(rf)))
    X = rf if use_rf else X_db
    on_db = np.all(np.isfinite(np.asarray(target.normal, float)))
    T = _target_frame(X, target.normal, camera_centre)
    fields = pose_fields(T, None)
    sigma = float(target.sigma_m)
    ev = _header("target")
    ev.update(
        {
            "target": int(index),
            "object": target.object if on_db else None,
            "version": None if version is None else int(version),
            "point": "rangefinder" if use_rf else "database",
            "T": fields["T"],
            "xyz_m": fields["xyz_m"],
            "quat_xyzw": fields["quat_xyzw"],
            "rotvec_rad": fields["rotvec_rad"],
            "normal": [float(v) for v in target.normal] if on_db else None,
            "database_xyz_m": [float(v) for v in X_db] if on_db else None,
            "rangefinder_xyz_m": None if rf is None else [float(v) for v in rf],
            "range_m": float(target.range_m),
            "sigma": {"along_sight_m": sigma} if np.isfinite(sigma) else None,
            "pixel_uv": [float(v) for v in target.uv],
            "check": target.check,
            "warning": target.warning or None,
            "who": who,
            "time": float(when),
            "time_iso": iso(when),
            "image_time": None if image_time is None else float(image_time),
        }
    )
    return ev


def robot_event(robot: str, state: Any, T_world_tool: np.ndarray, *, carrying: str | None = None) -> dict[str, Any]:
    """The ``robot`` line of the robot's joint state (an ``app.robot.controller.JointState``).

    Fields: ``robot`` (its name), ``joints`` ({name: position}, rad or m), ``T`` (the tool's 4×4 pose
    in the world, from the joints and the calibrated base) with ``xyz_m`` / ``quat_xyzw`` /
    ``rotvec_rad``, ``moving``, ``fault`` (None, or what went wrong), ``carrying`` (the object in the
    gripper, or None), ``time`` / ``time_iso`` (the state's wall-clock time).
    """
    fields = pose_fields(T_world_tool, None)
    ev = _header("robot")
    now = getattr(state, "stamp", None) or time.time()  # the controller's stamp where it gives one (ROS 2)
    ev.update(
        {
            "robot": robot,
            "joints": state.by_name(),
            "T": fields["T"],
            "xyz_m": fields["xyz_m"],
            "quat_xyzw": fields["quat_xyzw"],
            "rotvec_rad": fields["rotvec_rad"],
            "moving": bool(state.moving),
            "fault": state.fault,
            "carrying": carrying,
            "time": now,
            "time_iso": iso(now),
        }
    )
    return ev


class FeedFanout:
    """Several readers of one site's lines (the feed socket or file, the ROS 2 bridge): ``publish`` sends each
    line to every one; one that fails is logged and the others still get it."""

    def __init__(self, *sinks: Any):
        self.sinks = list(sinks)

    def publish(self, event: dict | None) -> None:
        for sink in self.sinks:
            try:
                sink.publish(event)
            except Exception:  # noqa: BLE001 - one reader's failure is not the others'
                log.exception("a line could not be sent to %s", type(sink).__name__)


def _line(event: dict) -> bytes:
    return (json.dumps(event, allow_nan=False, separators=(",", ":")) + "\n").encode()


class FeedPublisher:
    """Publishes feed lines to a file (appended) and/or a local Unix socket (every connected reader).

    file : path of the JSON-lines file (created; appended to). socket_path : path of the Unix socket
    to listen on (a stale socket file left by a dead process is replaced; one in use is refused).
    snapshot : callable returning the lines of the current state (``object_event`` of every object),
    sent to each socket reader when it connects and written to the file when the feed starts.
    """

    def __init__(
        self,
        *,
        file: str | Path | None = None,
        socket_path: str | Path | None = None,
        snapshot: Callable[[], list[dict]] | None = None,
    ):
        if file is None and socket_path is None:
            raise ValueError("a feed needs a file or a socket path to publish to")
        self.file = None if file is None else Path(file)
        self.socket_path = None if socket_path is None else Path(socket_path)
        self._snapshot = snapshot
        self._queue: queue.Queue = queue.Queue()
        self._clients: list[socket.socket] = []
        self._closed = threading.Event()
        self._fh = None
        self._server: socket.socket | None = None
        self.published = 0  # lines handed to the writer
        if self.file is not None:
            try:
                self.file.parent.mkdir(parents=True, exist_ok=True)
                self._fh = open(self.file, "ab", buffering=0)
            except OSError as exc:
                raise ValueError(f"{self.file}: cannot open the feed file ({exc.strerror})") from None
        if self.socket_path is not None:
            try:
                self._server = self._listen(self.socket_path)
            except (OSError, ValueError):
                if self._fh is not None:
                    self._fh.close()
                raise
        if self._fh is not None and snapshot is not None:
            for ev in snapshot():
                self._fh.write(_line(ev))
        self._writer = threading.Thread(target=self._write_loop, name="mcit-feed-writer", daemon=True)
        self._writer.start()
        if self._server is not None:
            self._acceptor = threading.Thread(target=self._accept_loop, name="mcit-feed-accept", daemon=True)
            self._acceptor.start()

    @staticmethod
    def _listen(path: Path) -> socket.socket:
        if len(os.fsencode(str(path))) > 100:
            raise ValueError(f"{path}: a Unix socket path must be under about 100 bytes; choose a shorter one")
        if path.exists() or path.is_symlink():
            if not stat.S_ISSOCK(path.lstat().st_mode):
                raise ValueError(f"{path}: exists and is not a socket; choose another path for the feed")
            probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                probe.connect(str(path))
            except OSError:
                path.unlink()  # left by a process that is gone
            else:
                raise ValueError(f"{path}: another program is already publishing on this socket; choose another path")
            finally:
                probe.close()
        path.parent.mkdir(parents=True, exist_ok=True)
        server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            server.bind(str(path))
            os.chmod(path, 0o660)  # this user and group only
            server.listen(8)
        except OSError as exc:
            server.close()
            raise ValueError(f"{path}: cannot listen on this socket ({exc.strerror})") from None
        server.settimeout(0.2)
        return server

    def publish(self, event: dict | None) -> None:
        """Queue one line (never blocks; None is ignored)."""
        if event is None or self._closed.is_set():
            return
        self._queue.put(("line", _line(event)))
        self.published += 1

    def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait until every line published so far has been written; False on timeout."""
        done = threading.Event()
        self._queue.put(("mark", done))
        return done.wait(timeout_s)

    # ------------------------------------------------------------------ threads
    def _accept_loop(self) -> None:
        while not self._closed.is_set():
            try:
                conn, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.settimeout(SEND_TIMEOUT_S)
            self._queue.put(("client", conn))

    def _send(self, conn: socket.socket, data: bytes) -> bool:
        try:
            conn.sendall(data)
            return True
        except OSError:  # gone, or not reading for SEND_TIMEOUT_S
            try:
                conn.close()
            except OSError:
                pass
            return False

    def _write_loop(self) -> None:
        while True:
            kind, item = self._queue.get()
            if kind == "stop":
                return
            if kind == "mark":
                item.set()
            elif kind == "client":
                lines = b""
                if self._snapshot is not None:
                    try:
                        lines = b"".join(_line(ev) for ev in self._snapshot())
                    except Exception:  # noqa: BLE001 - a reader still gets the changes
                        log.exception("feed: the current state could not be read for a new reader")
                if not lines or self._send(item, lines):
                    self._clients.append(item)
            else:
                if self._fh is not None:
                    try:
                        self._fh.write(item)
                    except OSError:
                        log.exception("feed: cannot write to %s", self.file)
                self._clients = [c for c in self._clients if self._send(c, item)]

    def close(self) -> None:
        """Send what is queued, disconnect the readers, remove the socket file."""
        if self._closed.is_set():
            return
        self.flush()
        self._closed.set()
        self._queue.put(("stop", None))
        self._writer.join(5.0)
        if self._server is not None:
            self._acceptor.join(2.0)
            self._server.close()
            try:
                if self.socket_path.exists() and stat.S_ISSOCK(self.socket_path.lstat().st_mode):
                    self.socket_path.unlink()
            except OSError:
                pass
        for c in self._clients:
            try:
                c.close()
            except OSError:
                pass
        if self._fh is not None:
            self._fh.close()

    def __enter__(self) -> FeedPublisher:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def follow(path: str | Path, *, timeout_s: float | None = None, from_start: bool = True) -> Iterator[dict]:
    """Read a feed: the lines of a Unix socket (``path`` is a socket) or of a feed file, as dicts.

    A file is read from its start (``from_start``) or its end, then followed as it grows. The
    iterator ends when the publisher closes the socket, or after ``timeout_s`` without a line.
    """
    path = Path(path)
    if path.exists() and stat.S_ISSOCK(path.stat().st_mode):
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.connect(str(path))
        s.settimeout(timeout_s)
        buf = b""
        try:
            while True:
                try:
                    chunk = s.recv(65536)
                except TimeoutError:
                    return
                if not chunk:
                    return
                buf += chunk
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    yield json.loads(line)
        finally:
            s.close()
    with open(path, "rb") as fh:
        if not from_start:
            fh.seek(0, os.SEEK_END)
        buf = b""
        last = time.monotonic()
        while True:
            chunk = fh.readline()
            if chunk:
                buf += chunk
                if buf.endswith(b"\n"):
                    yield json.loads(buf)
                    buf = b""
                last = time.monotonic()
                continue
            if timeout_s is not None and time.monotonic() - last > timeout_s:
                return
            time.sleep(0.05)
