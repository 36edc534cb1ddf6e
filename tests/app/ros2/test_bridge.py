"""``mcit serve --ros2`` against a real rclpy node (``app.ros2.peer.RosPeer``, in its own context: the messages
cross Fast DDS as another program's would): images in as a view's frames with their stamps, a written pose out as
PoseStamped with its image's stamp, joint states in as the robot's (the feed's robot lines follow them), motions out
as JointTrajectory; and what does not fit said once while the rest runs."""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 extra is not installed: pip install '.[ros2]'")

from app.ros2.peer import RosPeer  # noqa: E402

WAIT_S = 60.0  # what the tests wait for: a loaded machine slows them, never fails them
T0 = 1_733_400_000.0  # the images' stamps: far from now, so that a stamp taken from the clock would show
_counter = iter(range(1000))


@pytest.fixture
def domain():
    """A DDS domain of this test alone (xdist workers and tests never hear each other)."""
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0)
    return 100 + 40 * worker + next(_counter) % 40


@pytest.fixture
def peer(domain):
    p = RosPeer(domain)
    yield p
    p.close()


class Publishing:
    """Images (and CameraInfo) published by the peer every ``period_s`` on a thread, with stamps T0 + k·0.1 s."""

    def __init__(self, peer, image, K, *, topic="/cam/image_raw", encoding="rgb8", period_s=0.05):
        import threading

        self.peer, self.image, self.K, self.topic, self.encoding = peer, image, K, topic, encoding
        self.stamps: list[float] = []
        self._stop = threading.Event()
        self._period = period_s
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        k = 0
        while not self._stop.is_set():
            t = T0 + 0.1 * k
            k += 1
            self.stamps.append(t)
            h, w = self.image.shape[:2]
            self.peer.publish_image(self.image, t, self.topic, self.encoding)
            self.peer.publish_camera_info(self.K, w, h, t, self.topic.rsplit("/", 1)[0] + "/camera_info")
            self._stop.wait(self._period)

    def stop(self):
        self._stop.set()
        self._thread.join(timeout=2.0)


def _serve(tmp_path, domain, *extra):
    from app.ui.serve import add_serve_parser, build_interface
    from tests.e2e.harness import free_port

    parser = argparse.ArgumentParser()
    add_serve_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(
        ["serve", "--port", str(free_port()), "--db", str(tmp_path / "site.sqlite"), "--no-devices"]
        + ["--feed-file", str(tmp_path / "feed.jsonl"), "--ros2", "--ros2-domain", str(domain), *extra]
    )
    return build_interface(args)


def _close(server, closers):
    server.server.stop()
    for close in closers:
        close()


def _wait(predicate, what: str, timeout_s: float = WAIT_S):
    from tests.e2e.harness import wait_until

    wait_until(predicate, timeout_s, what)


def _feed(tmp_path, kind: str) -> list[dict]:
    path = tmp_path / "feed.jsonl"
    if not path.exists():
        return []
    return [
        x for x in (json.loads(line) for line in path.read_text().splitlines() if line.strip()) if x["type"] == kind
    ]


@pytest.fixture
def scene():
    from app.scene import default_scene_path, load_scene

    return load_scene(default_scene_path())


def test_images_are_a_views_frames_and_a_written_pose_goes_out_stamped_with_its_image(tmp_path, domain, peer, scene):
    from tests.e2e.harness import site_frame

    image = site_frame(scene)
    K, _ = scene.camera.decompose()
    pub = Publishing(peer, image, K)
    server, closers = _serve(tmp_path, domain, "--video", "ros2:/cam/image_raw")
    try:
        grabber = server.views[scene.views[0].name].grabber
        _wait(lambda: grabber.latest() is not None, "a ROS 2 image as the first camera's frame")
        frame = grabber.latest()
        assert np.array_equal(frame.image, image)  # the published image, whole
        assert frame.stamp in pub.stamps  # stamped with its header's time, not the clock's
        assert grabber.source.description == "ROS 2 /cam/image_raw" and grabber.status().live
        assert grabber.source.warning == ""  # CameraInfo agrees with the camera

        # the database out: markers (latched) and each object's pose
        topic = peer.watch_pose("parallelepiped")
        assert peer.wait(lambda: peer.markers and peer.poses[topic], WAIT_S), "no markers or pose from mcit"
        assert {m.ns for m in peer.markers[-1][1].markers[1:]} == {o.name for o in server.site.objects()}
        # a pose written from this frame: its PoseStamped carries the frame's stamp, as the feed's line does
        site = server.site
        obj = site.object("parallelepiped")
        T = obj.T_world_obj.copy()
        T[:3, 3] += [0.01, 0.0, 0.0]
        site.update_pose(obj, T, None, method="test", client="test", seen_at=frame.stamp)
        assert peer.wait(lambda: any(abs(peer.stamp_of(m) - frame.stamp) < 1e-6 for _, m in peer.poses[topic]), WAIT_S)
        msg = next(m for _, m in reversed(peer.poses[topic]) if abs(peer.stamp_of(m) - frame.stamp) < 1e-6)
        assert msg.header.frame_id == "world" and np.isclose(msg.pose.position.x, T[0, 3])
        _wait(lambda: any(x.get("seq") for x in _feed(tmp_path, "pose")), "the pose line on the feed")
        line = [x for x in _feed(tmp_path, "pose") if x.get("seq")][-1]
        assert line["frame_id"] == "world" and abs(line["image_time"] - frame.stamp) < 1e-6
        moved = lambda: any(  # noqa: E731 - the markers sent again, the box where it was written
            m.ns == "parallelepiped" and np.isclose(m.pose.position.x, T[0, 3]) for m in peer.markers[-1][1].markers
        )
        assert peer.wait(moved, WAIT_S), "the markers were not sent again after the change"
    finally:
        pub.stop()
        _close(server, closers)


def test_joint_states_drive_the_robot_and_its_motions_go_out_as_trajectories(tmp_path, domain, peer, caplog):
    from app.robot.controller import ControllerSilent

    server, closers = _serve(tmp_path, domain, "--recorded")
    try:
        cell = server.site.robot
        names = cell.model.joint_names
        with pytest.raises(ControllerSilent, match="no joint state on /joint_states yet"):
            cell.controller.state()  # nothing heard: the robot is not moved, and the operator is told why
        from app.workflows import Session, WorkflowError

        wf = Session(server.site, client="alice").start("move_robot")
        with pytest.raises(WorkflowError, match="no joint state on /joint_states"):
            wf.click(server.site.camera.project(np.array([[0.15, -0.25, 0.0]]))[0])
        assert wf.plan is None and not peer.trajectories
        wf.cancel()
        q = np.array([0.3, -0.8, 1.1, -0.2, 0.4, 0.1, 0.02])[: len(names)]
        stamp = T0 + 5.0
        with caplog.at_level(logging.WARNING, logger="mcit.ros2"):

            def heard():  # as a driver does, again until heard (a first message may precede DDS's discovery)
                peer.publish_joints([*names, "not_a_joint"], [*q, 0.0], stamp)
                return any(np.allclose(list(x["joints"].values()), q) for x in _feed(tmp_path, "robot"))

            _wait(heard, "robot line")
            line = next(x for x in _feed(tmp_path, "robot") if np.allclose(list(x["joints"].values()), q))
            assert list(line["joints"]) == list(names) and abs(line["time"] - stamp) < 1e-6
            T_tool = cell.T_world_base @ cell.model.tool_pose(q)
            assert np.allclose(line["T"], T_tool, atol=1e-9) and line["frame_id"] == "world"
            for _ in range(3):  # the unknown joint is said once, not at every message
                peer.publish_joints([*names, "not_a_joint"], [*q, 0.0], stamp)
            time.sleep(0.3)
        said = [r.getMessage() for r in caplog.records if "not_a_joint" in r.getMessage()]
        assert len(said) == 1 and "are not the URDF's" in said[0]

        # a motion goes out as one JointTrajectory from where the robot is, timed by its speed limits
        goal = q + np.r_[0.2, np.zeros(len(names) - 1)]
        keep = threading_keep_publishing(peer, names, q)
        try:
            n = len(peer.trajectories)  # (the Stop of the cancelled workflow above may be among them)
            cell.controller.move(goal[None, :])
            assert peer.wait(lambda: len(peer.trajectories) > n, WAIT_S), "no JointTrajectory from mcit"
            traj = peer.trajectories[n][1]
            assert list(traj.joint_names) == list(names) and np.allclose(traj.points[-1].positions, goal)
            dt = traj.points[-1].time_from_start.sec + 1e-9 * traj.points[-1].time_from_start.nanosec
            assert np.isclose(dt, 0.2 / (cell.model.velocity[0] * 0.5))  # the slowest joint at half its speed limit
            assert cell.controller.state().moving
            cell.controller.stop()
            assert peer.wait(lambda: len(peer.trajectories) >= n + 2 and not peer.trajectories[-1][1].points, WAIT_S)
            assert not cell.controller.state().moving
            # a robot that does not follow (its joints stay): the motion's fault once its time and a second passed,
            # and Stop sent
            n = len(peer.trajectories)
            cell.controller.move(goal[None, :])
            _wait(lambda: cell.controller.state().fault is not None, "the motion's fault")
            assert cell.controller.state().fault.startswith(f"joint {names[0]} did not reach its command: 11.5°")
            assert not cell.controller.state().moving
            assert peer.wait(lambda: len(peer.trajectories) >= n + 2 and not peer.trajectories[-1][1].points, WAIT_S)
        finally:
            keep.set()
    finally:
        _close(server, closers)


def threading_keep_publishing(peer, names, q):
    """Joint states at 50 Hz on a thread until the returned event is set (a driver that stays alive)."""
    import threading

    stop = threading.Event()

    def run():
        while not stop.wait(0.02):
            peer.publish_joints(names, q, time.time())

    threading.Thread(target=run, daemon=True).start()
    return stop


def test_what_does_not_fit_is_said_once_and_the_video_goes_on(tmp_path, domain, peer, scene, caplog):
    from tests.e2e.harness import site_frame

    image = site_frame(scene)
    K, _ = scene.camera.decompose()
    wrong = K.copy()
    wrong[0, 0] *= 1.1  # CameraInfo's fx 10 % off the camera's
    pub = Publishing(peer, image, wrong, encoding="bgr8", period_s=0.02)
    with caplog.at_level(logging.WARNING, logger="mcit.ros2"):
        server, closers = _serve(tmp_path, domain, "--video", "ros2:/cam/image_raw", "--fps", "2")
        try:
            grabber = server.views[scene.views[0].name].grabber
            _wait(lambda: grabber.latest() is not None, "a frame")
            assert np.array_equal(grabber.latest().image, image)  # bgr8 read as it is
            _wait(lambda: "differs from mcit's camera" in grabber.source.warning, "the CameraInfo said")
            # images at up to 50/s where 2/s are expected: said, the newest shown
            _wait(lambda: "only the newest is shown" in grabber.source.warning, "the rate said")
            # an encoding mcit cannot read: said, its frames dropped, the video goes on when they are readable again
            pub.stop()
            from sensor_msgs.msg import Image

            msg = Image(height=image.shape[0], width=image.shape[1], encoding="32FC1", step=4 * image.shape[1])
            msg.data = bytes(4 * image.shape[0] * image.shape[1])
            peer._pub(Image, "/cam/image_raw").publish(msg)
            _wait(lambda: "'32FC1' cannot be read" in grabber.source.warning, "the encoding said")
            # its frame dropped: the frame shown is still the last readable one (the bgr8 frames still on their way
            # when the publisher stopped may land before it: the frame count is read once it has been said)
            n = grabber.latest().index
            assert np.array_equal(grabber.latest().image, image)
            pub2 = Publishing(peer, image, K)
            try:
                _wait(lambda: grabber.latest().index > n, "frames again")
            finally:
                pub2.stop()
            text = server._video_status(server.views[scene.views[0].name])
            assert "cannot be read" in str(text)  # the panel says it
        finally:
            pub.stop()
            _close(server, closers)
    for kind in ("differs from mcit's camera", "only the newest is shown", "cannot be read"):
        assert sum(kind in r.getMessage() for r in caplog.records) == 1, kind


def test_ros2_without_the_extra_is_one_line_saying_how_to_install_it(tmp_path, monkeypatch, capsys):
    from app.cli import main

    monkeypatch.setitem(sys.modules, "rclpy", None)  # as where the extra is not installed
    db = tmp_path / "site.sqlite"
    assert main(["serve", "--ros2", "--db", str(db), "--no-devices", "--port", "0"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'mcit[ros2]'" in err and "Traceback" not in err
    assert not db.exists()  # nothing opened, nothing written
