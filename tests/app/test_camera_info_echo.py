"""A ROS ``camera_info`` message as ``ros2 topic echo`` prints it (block lists, the closing ``---``), read by
``app.camera_io.read_intrinsics`` with PyYAML (docs/exchange.md), and used by ``mcit track --intrinsics``."""

import numpy as np
import pytest

from app.camera_io import read_intrinsics
from tests.app.box_frames import box_frames  # noqa: F401 - a fixture


def echo(K, D, width=640, height=480, frame="camera_color_optical_frame", sec=1700000000) -> str:
    """``ros2 topic echo --once /camera_info`` (sensor_msgs/msg/CameraInfo) as ROS 2 prints it: PyYAML's block
    style, a list's items at its key's indent, floats as Python writes them (1.0e-05), then ``---``."""
    import yaml

    def block(name, values):
        return yaml.safe_dump({name: [float(v) for v in values]}, default_flow_style=False)

    K = np.asarray(K, float)
    P = np.hstack([K, np.zeros((3, 1))])
    return (
        f"header:\n  stamp:\n    sec: {sec}\n    nanosec: 417623213\n  frame_id: {frame}\n"
        f"height: {height}\nwidth: {width}\ndistortion_model: plumb_bob\n"
        + block("d", D)
        + block("k", K.ravel())
        + block("r", np.eye(3).ravel())
        + block("p", P.ravel())
        + "binning_x: 0\nbinning_y: 0\nroi:\n  x_offset: 0\n  y_offset: 0\n  height: 0\n  width: 0\n"
        "  do_rectify: false\n---\n"
    )


K_ECHO = [[615.3, 0.0, 321.7], [0.0, 615.9, 238.2], [0.0, 0.0, 1.0]]
D_ECHO = [0.0912, -0.1874, 1.0e-05, -0.00042, 0.0]


def test_the_echo_is_what_ros2_prints():
    text = echo(K_ECHO, D_ECHO)
    assert "\nd:\n- 0.0912\n- -0.1874\n- 1.0e-05\n" in text and "\nk:\n- 615.3\n" in text
    assert text.endswith("  do_rectify: false\n---\n")


@pytest.mark.parametrize("suffix", [".yaml", ".yml"])
def test_an_echoed_camera_info_gives_k_size_and_distortion(tmp_path, suffix):
    f = tmp_path / f"camera_info{suffix}"
    f.write_text(echo(K_ECHO, D_ECHO))
    intr = read_intrinsics(f)
    np.testing.assert_array_equal(intr.K, K_ECHO)
    np.testing.assert_array_equal(intr.distortion, D_ECHO)
    assert (intr.width, intr.height, intr.distortion_model) == (640, 480, "plumb_bob") and intr.has_distortion


def test_of_several_echoed_messages_the_first_is_read(tmp_path):
    f = tmp_path / "camera_info.yaml"
    other = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
    f.write_text(echo(K_ECHO, D_ECHO) + echo(other, [0.0] * 5, sec=1700000001))
    np.testing.assert_array_equal(read_intrinsics(f).K, K_ECHO)


def test_a_ros1_echo_and_an_ost_yaml_read_the_same(tmp_path):
    """rostopic echo (ROS 1: upper-case K, D, flow lists) and the calibrator's ost.yaml: one reader, one answer."""
    ros1 = tmp_path / "ros1.yaml"
    ros1.write_text(
        "header:\n  seq: 7\n  stamp:\n    secs: 1\n    nsecs: 2\n  frame_id: cam\nheight: 480\nwidth: 640\n"
        f"distortion_model: plumb_bob\nD: {D_ECHO}\nK: {np.ravel(K_ECHO).tolist()}\n---\n"
    )
    ost = tmp_path / "ost.yaml"
    ost.write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: head\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
        f"  data: {np.ravel(K_ECHO).tolist()}\ndistortion_model: plumb_bob\ndistortion_coefficients:\n"
        f"  rows: 1\n  cols: 5\n  data: {D_ECHO}\n"
    )
    a, b = read_intrinsics(ros1), read_intrinsics(ost)
    np.testing.assert_array_equal(a.K, b.K)
    np.testing.assert_array_equal(a.distortion, b.distortion)
    assert (a.name, b.name) == (None, "head")


def test_an_opencv_matrix_tag_without_opencvs_directive(tmp_path):
    f = tmp_path / "cam.yaml"
    f.write_text(
        "image_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n"
        f"  data: {np.ravel(K_ECHO).tolist()}\n"
    )
    np.testing.assert_array_equal(read_intrinsics(f).K, K_ECHO)


def test_mcit_track_reads_an_echoed_camera_info(box_frames, capsys):  # noqa: F811 - the fixture
    from app.cli import main

    d = box_frames
    (d / "camera_info.yaml").write_text(echo([[420.0, 0, 159.5], [0, 420.0, 119.5], [0, 0, 1]], [0.0] * 5, 320, 240))
    args = ["track", str(d / "frames"), "--model", str(d / "box.cao"), "--pose", str(d / "box.pos")]
    args += ["--out", str(d / "echo.avi"), "--intrinsics", str(d / "camera_info.yaml"), "--quiet"]
    assert main(args) == 0
    assert "tracked 3 frames" in capsys.readouterr().out
    # the same message for other images: refused with both sizes named, status 1
    (d / "camera_info.yaml").write_text(echo([[840.0, 0, 319.5], [0, 840.0, 239.5], [0, 0, 1]], [0.0] * 5))
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "camera_info.yaml: the camera was calibrated on 640×480 images but the video's frames are 320×240" in err
