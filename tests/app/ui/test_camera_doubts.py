"""What the interface says of a camera that cannot show the database: a video of another size than its
calibration, or a C that puts every object behind it (a mirrored reconstruction's P: a new user saw no
wireframe and no word of why); and a camera matrix with a NaN names the entry."""

from types import SimpleNamespace

import numpy as np
import pytest

from app.scene import SceneError, _matrix
from app.ui.server import InterfaceServer
from core.camera import Camera


def _server(C: np.ndarray, size=(640, 480), z: float = 2.0):
    cam = Camera(C, 640, 480)
    box = SimpleNamespace(vertices_world=lambda: np.array([[0.0, 0.0, z], [0.1, 0.0, z], [0.0, 0.1, z + 0.1]]))
    site = SimpleNamespace(camera_of=lambda _v: cam, objects=lambda: [box])
    pw = SimpleNamespace(width=size[0], height=size[1])
    return SimpleNamespace(site=site, views={"a": SimpleNamespace(pixel_world=pw)})


K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])


def test_a_camera_that_sees_the_objects_is_not_doubted():
    assert InterfaceServer.camera_doubt(_server(K @ np.eye(3, 4)), "a") == ""


def test_a_camera_with_every_object_behind_it_is_said():
    # a mirrored reconstruction: C's sign fixed by its determinant, every object at negative depth (VGG's house)
    said = InterfaceServer.camera_doubt(_server(K @ np.eye(3, 4), z=-2.0), "a")
    assert "behind it" in said and "mirrored" in said


def test_a_video_of_another_size_is_said_first():
    said = InterfaceServer.camera_doubt(_server(K @ np.eye(3, 4), size=(768, 576)), "a")
    assert said.startswith("the video is 768×576 but the camera is calibrated for 640×480")


def test_a_nan_in_a_camera_matrix_names_its_entry():
    C = np.eye(3, 4)
    C[1, 2] = np.nan
    with pytest.raises(SceneError, match=r"cameras\[1\]\.C: entry \(2, 3\) is nan; every entry must be a finite"):
        _matrix(C.tolist(), (3, 4), "cameras[1].C")
