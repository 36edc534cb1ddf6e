"""The pixel convention of each camera format and of the renderer (issue 27): pixel (0, 0)'s centre is (0, 0).

ViSP (``vpCameraParameters``: u = u0 + px·x, the top-left pixel's centre at (0, 0)), OpenCV (``calibrateCamera``:
integer coordinates at pixel centres) and ROS ``camera_info`` (OpenCV's K) all put pixel (0, 0)'s centre at
(0, 0), as mcit does (DESIGN.md). So a reader must carry u0, v0 over unchanged — a reader that added or took
half a pixel would move every pose's projection by 0.5 px — and the renderer must draw an edge projected at
u = 200.0 between the half-covered pixel 200's neighbours, not half a pixel aside. Both are checked here.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from app.camera_io import read_intrinsics
from app.vision.synthetic import render_poses
from core.brep import BRep
from core.camera import Camera
from core.transforms import make_T

FX, FY, U0, V0 = 612.5, 611.25, 320.25, 239.75  # fractions that a half-pixel shift cannot hide


def _visp(path):
    path.write_text(
        '<?xml version="1.0"?>\n<root><camera><name>Camera</name><image_width>640</image_width>'
        "<image_height>480</image_height><model><type>perspectiveProjWithoutDistortion</type>"
        f"<px>{FX}</px><py>{FY}</py><u0>{U0}</u0><v0>{V0}</v0></model></camera></root>\n"
    )


def _opencv(path):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", np.array([[FX, 0, U0], [0, FY, V0], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.zeros((1, 5)))
    fs.release()


def _ros(path):
    path.write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: cam\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
        f"  data: [{FX}, 0, {U0}, 0, {FY}, {V0}, 0, 0, 1]\ndistortion_model: plumb_bob\n"
        "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0, 0, 0, 0, 0]\n"
    )


def _ros_echo(path):
    """A ``CameraInfo`` message as ``ros2 topic echo`` prints it (flat k)."""
    path.write_text(
        "header:\n  frame_id: cam\nheight: 480\nwidth: 640\ndistortion_model: plumb_bob\nd: [0.0, 0.0, 0.0, 0.0, 0.0]\n"
        f"k: [{FX}, 0.0, {U0}, 0.0, {FY}, {V0}, 0.0, 0.0, 1.0]\n---\n"
    )


@pytest.mark.parametrize(
    ("writer", "name"), [(_visp, "cam.xml"), (_opencv, "cam.yml"), (_ros, "ost.yaml"), (_ros_echo, "info.yaml")]
)
def test_every_camera_format_keeps_the_principal_point_where_the_file_puts_it(tmp_path, writer, name):
    """The optical axis projects to exactly (u0, v0) of the file: no half-pixel shift on reading."""
    path = tmp_path / name
    writer(path)
    K = read_intrinsics(path).K
    cam = Camera.from_intrinsics(K, np.eye(4), 640, 480)
    assert np.allclose(cam.project(np.array([[0.0, 0.0, 2.0]]))[0], [U0, V0], atol=1e-9)
    assert np.allclose(cam.project(np.array([[0.1, -0.05, 1.0]]))[0], [U0 + 0.1 * FX, V0 - 0.05 * FY], atol=1e-9)


def _crossing(profile: np.ndarray) -> float:
    """Where a dark-to-bright (or bright-to-dark) step along a row crosses its middle level, pixel-centre
    coordinates, by linear interpolation between the pixels either side."""
    lo, hi = np.median(profile[:20]), np.median(profile[-20:])
    mid = 0.5 * (lo + hi)
    s = np.sign(profile - mid)
    i = int(np.flatnonzero(s[:-1] != s[1:])[0])
    return i + (mid - profile[i]) / (profile[i + 1] - profile[i])


def test_the_renderer_draws_an_edge_where_the_camera_projects_it():
    """A box face seen head-on whose left edge projects at u = 200.0 and top edge at v = 150.0: the rendered
    step crosses its middle level there (pixel 200 half covered), within 0.1 px; half a pixel either way
    fails."""
    f, u0, v0, Z = 500.0, 319.5, 239.5, 1.0
    cam = Camera.from_intrinsics(np.array([[f, 0, u0], [0, f, v0], [0, 0, 1]]), np.eye(4), 640, 480)
    x_left, y_top = (200.0 - u0) * Z / f, (150.0 - v0) * Z / f
    w = h = 0.2
    T = make_T(np.eye(3), [x_left + w / 2, y_top + h / 2, Z])  # BRep.box spans z 0..0.1: its face z = 0 at depth Z
    img = render_poses(cam, BRep.box(w, h, 0.1), [T], noise_sigma=0.0, blur_sigma_px=0.0)[0].astype(float)
    row = img[200, 170:240]  # across the left edge, mid-height
    col = img[120:190, 260]  # across the top edge
    assert 170 + _crossing(row) == pytest.approx(200.0, abs=0.1)
    assert 120 + _crossing(col) == pytest.approx(150.0, abs=0.1)
