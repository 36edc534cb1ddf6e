"""The live feed (issue 15.6): accepted pose changes and designated targets as JSON lines, read by a
second process from a Unix socket or a file, as a robot controller would."""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from app.feed import FeedPublisher, change_event, follow
from app.workflows import DesignateTarget
from core.transforms import exp_so3, make_T

ROOT = Path(__file__).resolve().parents[3]
WAIT_S = 60.0  # a liveness guard for a second process on a loaded machine, not a speed check

# The second process: a minimal controller that connects to the feed and prints each line it reads.
READER = """
import socket, sys
s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
s.connect(sys.argv[1])
f = s.makefile("r", encoding="utf-8")
for line in f:
    sys.stdout.write(line)
    sys.stdout.flush()
"""


def _lines(stream, q):
    for line in stream:
        q.put(line)
    q.put(None)


class Reader:
    """A second process; ``next()`` is its next line as a dict (None when it ended)."""

    def __init__(self, args):
        self.proc = subprocess.Popen(
            args,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        self.q: queue.Queue = queue.Queue()
        threading.Thread(target=_lines, args=(self.proc.stdout, self.q), daemon=True).start()

    def next(self):
        try:
            line = self.q.get(timeout=WAIT_S)
        except queue.Empty:
            raise AssertionError(f"the second process printed nothing for {WAIT_S} s") from None
        return None if line is None else json.loads(line)

    def raw(self):
        return self.q.get(timeout=WAIT_S)

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            self.proc.wait(WAIT_S)
        finally:
            self.proc.stdout.close()
            self.proc.stderr.close()


@pytest.fixture
def sock_path():
    with tempfile.TemporaryDirectory(prefix="mcit-feed-") as d:  # short: a Unix socket path is ~100 bytes at most
        yield Path(d) / "feed.sock"


def _check_pose_line(ev, T):
    assert ev["feed"] == "mcit-feed/1" and ev["type"] == "pose"
    np.testing.assert_allclose(ev["T"], T, atol=1e-12)
    np.testing.assert_allclose(ev["xyz_m"], T[:3, 3], atol=1e-12)
    np.testing.assert_allclose(Rotation.from_quat(ev["quat_xyzw"]).as_matrix(), T[:3, :3], atol=1e-12)


def test_a_second_process_reads_pose_changes_and_targets_from_the_socket(site, sock_path):
    feed = FeedPublisher(socket_path=sock_path, snapshot=site.feed_snapshot)
    site.attach_feed(feed)
    reader = Reader([sys.executable, "-c", READER, str(sock_path)])
    try:
        # first, every object as it stands
        names = sorted(o.name for o in site.objects())
        current = [reader.next() for _ in names]
        assert sorted(e["object"] for e in current) == names
        assert all(e["action"] == "current" and e["seq"] is None for e in current)
        for e in current:
            _check_pose_line(e, site.object(e["object"]).T_world_obj)
        # an accepted pose change: the new pose, its σ, the version, who, when
        box = site.object("parallelepiped")
        T_new = make_T(exp_so3([0.0, 0.0, 0.05]) @ box.T_world_obj[:3, :3], box.T_world_obj[:3, 3] + [0.01, -0.02, 0.0])
        cov = np.diag([4e-6, 4e-6, 1e-6, 1e-4, 1e-4, 4e-4])
        rec = site.update_pose(box, T_new, cov, method="p3l+refine", client="viser:7")
        ev = reader.next()
        _check_pose_line(ev, T_new)
        assert (ev["object"], ev["version"], ev["who"], ev["method"], ev["action"], ev["moved"]) == (
            "parallelepiped",
            rec.version,
            "viser:7",
            "p3l+refine",
            "update",
            True,
        )
        assert ev["seq"] == site.change_seq
        np.testing.assert_allclose(ev["sigma"]["xyz_m"], [2e-3, 2e-3, 1e-3])
        np.testing.assert_allclose(ev["sigma"]["rot_rad"], [1e-2, 1e-2, 2e-2])
        assert ev["time"] == site.db.change(ev["seq"]).time  # when the change was written (the history's time)
        # a status change is a pose line that did not move
        site.set_status("parallelepiped", "stale", client="viser:8")
        ev = reader.next()
        assert (ev["status"], ev["moved"], ev["who"], ev["version"]) == ("stale", False, "viser:8", rec.version + 1)
        # a designated target: the point on the box's top, z into the surface
        box = site.object("parallelepiped")
        X = box.T_world_obj[:3, :3] @ np.array([0.05, -0.03, 0.132]) + box.T_world_obj[:3, 3]
        wf = DesignateTarget(site, client="viser:9")
        t = wf.click(site.camera.project(X))
        ev = reader.next()
        assert ev["type"] == "target" and ev["object"] == "parallelepiped" and ev["version"] == box.version
        assert ev["who"] == "viser:9" and ev["target"] == 1 and ev["point"] == "database" and ev["sigma"] is None
        np.testing.assert_allclose(ev["xyz_m"], X, atol=1e-6)
        np.testing.assert_allclose(ev["T"][0][3], X[0], atol=1e-6)
        z = np.array(ev["T"])[:3, 2]
        np.testing.assert_allclose(z, -t.normal, atol=1e-9)
        np.testing.assert_allclose(
            Rotation.from_quat(ev["quat_xyzw"]).as_matrix(), np.array(ev["T"])[:3, :3], atol=1e-12
        )
        # an object removed
        site.db.remove("table", client="cli")
        site.poll()  # another process's change (here the database directly) joins the feed when polled
        ev = reader.next()
        assert (ev["type"], ev["object"], ev["who"]) == ("removed", "table", "cli")
    finally:
        feed.close()
        reader.stop()
    assert not sock_path.exists()  # the socket file is removed on close


def test_mcit_db_feed_publishes_to_a_file_another_process_writes_the_database(db, tmp_path):
    """The publisher is the second process here: ``mcit db feed`` follows the database that this
    process writes, and this process reads the file as a controller would."""
    out = tmp_path / "feed.jsonl"
    pub = Reader(
        [
            sys.executable,
            "-m",
            "app.cli",
            "db",
            "feed",
            "--db",
            str(db.path),
            "--file",
            str(out),
            "--interval-s",
            "0.05",
        ]
    )
    try:
        assert "publishing the changes of" in pub.raw()
        lines = follow(out, timeout_s=WAIT_S)
        names = sorted(o.name for o in db.objects())
        assert sorted(next(lines)["object"] for _ in names) == names  # the state when the feed started
        obj = db.get("parallelepiped")
        T = make_T(obj.T_world_obj[:3, :3], obj.T_world_obj[:3, 3] + [0.0, 0.0, 0.01])
        db.update_pose(obj.id, T, None, expected_version=obj.version, method="test", client="elsewhere")
        ev = next(lines)
        _check_pose_line(ev, T)
        assert (ev["who"], ev["version"], ev["sigma"], ev["moved"]) == ("elsewhere", obj.version + 1, None, True)
        db.undo(db.last_change_id(), client="elsewhere")
        ev = next(lines)
        _check_pose_line(ev, obj.T_world_obj)
        assert ev["action"] == "undo" and ev["version"] == obj.version + 2
    finally:
        pub.stop()
    assert pub.proc.returncode == 0, pub.proc.stderr


def test_change_events_of_every_kind(db):
    from core.brep import BRep

    rec = db.add_object(
        "crate",
        "box",
        BRep.box(0.3, 0.2, 0.1),
        make_T(np.eye(3), [1.0, 2.0, 0.0]),
        method="model_box",
        client="viser:1",
    )
    ev = change_event(db.history(rec.id)[-1])
    assert (ev["type"], ev["action"], ev["moved"], ev["version"], ev["status"]) == ("pose", "add", True, 1, "modelled")
    db.add_calibration("turret", {"T_world_turret": np.eye(4)}, None, method="t")
    cal = db.history_since(db.last_change_id() - 1)[-1]
    assert cal.action == "calibration" and change_event(cal) is None  # not a pose: not on the feed
    removed = db.remove("crate", client="viser:1")
    ev = change_event(removed)
    assert (ev["type"], ev["object"], ev["action"], ev["who"]) == ("removed", "crate", "remove", "viser:1")
    back = db.undo(removed.id, client="viser:2")
    ev = change_event(back)
    assert (ev["type"], ev["action"], ev["moved"], ev["who"]) == ("pose", "undo", True, "viser:2")
    first = db.history("crate")[0]
    gone = db.undo(first.id, client="viser:3")  # undoing the addition removes it
    assert change_event(gone)["type"] == "removed"
    json.dumps(ev, allow_nan=False)  # strict JSON: no NaN


def test_publisher_refuses_a_path_in_use(tmp_path, sock_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="exists and is not a socket"):
        FeedPublisher(socket_path=tmp_path / "file")
    with FeedPublisher(socket_path=sock_path):
        with pytest.raises(ValueError, match="another program is already publishing on this socket"):
            FeedPublisher(socket_path=sock_path)
    with pytest.raises(ValueError, match="needs a file or a socket path"):
        FeedPublisher()


def test_mcit_serve_feed_flags(tmp_path, sock_path, capsys):
    import cv2

    from app.cli import build_parser, main
    from app.ui.serve import build_interface
    from tests.e2e.harness import free_port

    cv2.imwrite(str(tmp_path / "f0.png"), np.full((240, 320), 90, np.uint8))
    argv = [
        "serve",
        "--video",
        str(tmp_path),
        "--db",
        str(tmp_path / "site.sqlite"),
        "--no-devices",
        "--port",
        str(free_port()),
        "--feed-socket",
        str(sock_path),
        "--feed-file",
        str(tmp_path / "feed.jsonl"),
    ]
    server, closers = build_interface(build_parser().parse_args(argv))
    try:
        assert server.site.feed is not None
        names = sorted(o.name for o in server.site.objects())
        lines = follow(sock_path, timeout_s=WAIT_S)
        assert sorted(next(lines)["object"] for _ in names) == names
        # a socket another program publishes on: one line, exit status 1 (README "Exit status"), nothing left open
        again = [str(free_port()) if a == argv[argv.index("--port") + 1] else a for a in argv[:-4]]  # its own port
        assert main(again + ["--feed-socket", str(sock_path)]) == 1
        err = capsys.readouterr().err
        assert err.startswith("mcit serve: error: ") and err.count("\n") == 1, err
        assert "another program is already publishing on this socket" in err
    finally:
        server.server.stop()
        for close in closers:
            close()
    assert [json.loads(x)["action"] for x in (tmp_path / "feed.jsonl").read_text().splitlines()] == ["current"] * len(
        names
    )


def test_a_failing_feed_never_fails_a_write_or_a_target(site, caplog):
    class Broken:
        def publish(self, event):
            raise OSError("disk full")

    site.attach_feed(Broken())
    box = site.object("parallelepiped")
    rec = site.update_pose(box, box.T_world_obj, None, method="test", client="viser:1")
    assert rec.version == box.version + 1 and site.object("parallelepiped").version == rec.version
    X = box.T_world_obj[:3, :3] @ np.array([0.05, -0.03, 0.132]) + box.T_world_obj[:3, 3]
    t = DesignateTarget(site).click(site.camera.project(X))
    assert t.object == "parallelepiped"
    assert "could not be sent on the live feed" in caplog.text
