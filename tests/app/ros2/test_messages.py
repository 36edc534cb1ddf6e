"""ROS 2 messages ↔ mcit's values (no DDS: the message classes only)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 extra is not installed: pip install '.[ros2]'")

from app.ros2.messages import (  # noqa: E402
    UnsupportedEncoding,
    camera_info_disagreement,
    image_message,
    image_rgb,
    object_markers,
    pose_cov_message,
    stamp_s,
    to_stamp,
    topic_token,
    trajectory_message,
)


def _rgb(h=6, w=8):
    rng = np.random.default_rng(3)
    return rng.integers(0, 255, (h, w, 3), dtype=np.uint8)


def test_stamps_round_trip_to_the_nanosecond():
    t = 1_733_400_000.123456789
    s = to_stamp(t)
    assert s.sec == 1_733_400_000 and abs(s.nanosec - 123456789) <= 256  # a double's own resolution at 1.7e9 s
    assert abs(stamp_s(s) - t) < 1e-6


@pytest.mark.parametrize("encoding", ["rgb8", "bgr8", "mono8"])
def test_images_read_back_in_each_encoding_with_padded_rows(encoding):
    import cv2

    rgb = _rgb()
    msg = image_message(rgb, 1.0, "cam", encoding)
    # rows padded to 64 bytes, as some drivers send them
    row = msg.step
    data = np.frombuffer(msg.data, np.uint8).reshape(msg.height, row)
    padded = np.zeros((msg.height, 64), np.uint8)
    padded[:, :row] = data
    msg.data, msg.step = padded.tobytes(), 64
    out = image_rgb(msg)
    want = rgb if encoding != "mono8" else np.repeat(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)[:, :, None], 3, axis=2)
    assert out.shape == (6, 8, 3) and np.array_equal(out, want)


def test_16_bit_bayer_and_yuv_images_are_read():
    from sensor_msgs.msg import Image

    msg = Image(height=2, width=2, encoding="mono16", is_bigendian=1, step=4)
    msg.data = np.array([[0x1234, 0xFF00], [0x0001, 0x8000]], ">u2").tobytes()
    assert image_rgb(msg)[:, :, 0].tolist() == [[0x12, 0xFF], [0x00, 0x80]]
    bayer = Image(height=4, width=4, encoding="bayer_rggb8", step=4)
    bayer.data = np.tile(np.array([[200, 100], [100, 20]], np.uint8), (2, 2)).tobytes()  # R=200, G=100, B=20
    assert np.allclose(image_rgb(bayer)[1:3, 1:3].reshape(-1, 3).mean(axis=0), [200, 100, 20], atol=2)
    yuv = Image(height=1, width=2, encoding="yuv422", step=4)
    yuv.data = bytes([128, 235, 128, 235])  # U Y V Y: white
    assert image_rgb(yuv).min() >= 250


def test_an_unknown_encoding_or_short_data_is_refused_in_a_sentence():
    from sensor_msgs.msg import Image

    msg = Image(height=2, width=2, encoding="32FC1", step=8, data=bytes(16))
    with pytest.raises(UnsupportedEncoding, match="'32FC1' cannot be read; publish one of rgb8"):
        image_rgb(msg)
    short = Image(height=2, width=2, encoding="rgb8", step=6, data=bytes(7))
    with pytest.raises(ValueError, match="needs 12 bytes, got 7"):
        image_rgb(short)


def test_camera_info_is_checked_against_the_camera():
    from sensor_msgs.msg import CameraInfo

    K = np.array([[500.0, 0, 256], [0, 500.0, 128], [0, 0, 1]])
    info = CameraInfo(width=512, height=256, k=[float(v) for v in K.reshape(9)], d=[0.0] * 5)
    assert camera_info_disagreement(info, K, 512, 256, False) == ""
    info.k[0] = 520.0  # fx 4 % off
    assert "differs from mcit's camera" in camera_info_disagreement(info, K, 512, 256, False)
    info.k[0] = 500.0
    info.d = [-0.2, 0.05, 0, 0, 0]
    assert "frames are not undistorted" in camera_info_disagreement(info, K, 512, 256, False)
    assert camera_info_disagreement(info, K, 512, 256, True) == ""  # mcit undistorts them
    assert "640×480 images" in camera_info_disagreement(CameraInfo(width=640, height=480), K, 512, 256, False)


def test_a_pose_with_covariance_and_markers_of_the_database(tmp_path):
    from app.scene import default_scene_path, load_scene
    from app.workflows import Site

    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.3]
    cov = np.diag([1e-6, 2e-6, 3e-6, 1e-4, 2e-4, 3e-4])
    msg = pose_cov_message(T, cov, 5.0, "world")
    assert msg.header.frame_id == "world" and msg.pose.pose.position.z == 0.3 and msg.pose.pose.orientation.w == 1.0
    assert np.allclose(np.reshape(msg.pose.covariance, (6, 6)), cov)
    assert np.all(np.array(pose_cov_message(T, None, 5.0, "world").pose.covariance) == -1.0)

    from app.db import Database, seed_from_scene

    scene = load_scene(default_scene_path())
    with Database.open(tmp_path / "site.sqlite") as db:
        seed_from_scene(db, scene)
        objects = Site(scene, db, frames=None).objects()
        arr = object_markers(objects, 5.0, "world")
    assert arr.markers[0].action == 3  # DELETEALL: objects removed since go
    names = {m.ns for m in arr.markers[1:]}
    assert names == {o.name for o in objects}
    box = next(o for o in objects if o.name == "parallelepiped")
    lines = next(m for m in arr.markers if m.ns == "parallelepiped" and m.id == 0)
    pts = np.array([[p.x, p.y, p.z] for p in lines.points])
    assert len(pts) == 2 * len(box.model.edges) and np.allclose(pts, box.model.edge_segments().reshape(-1, 3))
    assert np.isclose(lines.pose.position.x, box.T_world_obj[0, 3])


def test_a_trajectory_starts_on_arrival_and_an_empty_one_stops():
    msg = trajectory_message(["a", "b"], np.array([[0.1, 0.2], [0.3, 0.4]]), np.array([0.5, 1.25]))
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 0)
    assert [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points] == [0.5, 1.25]
    assert list(msg.points[1].positions) == [0.3, 0.4]
    assert trajectory_message(["a", "b"], np.zeros((0, 2)), np.zeros(0)).points == []


def test_object_names_become_topic_tokens():
    assert topic_token("parallelepiped") == "parallelepiped"
    assert topic_token("Box 2 (red)") == "Box_2_red"
    assert topic_token("2nd") == "o_2nd"
    assert topic_token("<script>") == "script"
    assert topic_token("***") == "object"
