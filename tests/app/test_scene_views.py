"""A scene's cameras (views): a "cameras" list, each with a name and its own video; a scene with one
"camera" block has one view, "main"; bad lists are refused naming the field."""

import copy
import dataclasses

import numpy as np
import pytest

from app.scene import DEFAULT_VIEW, SceneError, scene_from_dict

from .test_scene import minimal


def two_cameras() -> dict:
    d = minimal()
    d.pop("video", None)
    front = {"name": "front", **d.pop("camera"), "video": {"file": "front.avi", "fps": 10}}
    side = {
        "name": "side",
        "width": 80,
        "height": 60,
        "K": [[60, 0, 39.5], [0, 60, 29.5], [0, 0, 1]],
        "T_world_cam": {"xyz": [2, 0, 0.5], "rpy_deg": [-100, 0, 90]},
        "video": {"file": "side.avi", "fps": 10},
    }
    d["cameras"] = [front, side]
    return d


def test_one_camera_block_is_one_view_named_main(tmp_path):
    scene = scene_from_dict(minimal(), tmp_path)
    assert scene.view_names == (DEFAULT_VIEW,) == ("main",)
    assert scene.view().camera is scene.camera and scene.view("main").video is scene.video


def test_a_list_of_cameras_gives_named_views_each_with_its_video(tmp_path):
    scene = scene_from_dict(two_cameras(), tmp_path)
    assert scene.view_names == ("front", "side")
    side = scene.view("side")
    assert (side.camera.width, side.camera.height) == (80, 60)
    assert side.video.path == (tmp_path / "side.avi").resolve() and side.video.fps == 10
    assert scene.camera is scene.view("front").camera  # the first camera is the scene's camera
    assert scene.video.path.name == "front.avi"
    assert not np.allclose(side.camera.center, scene.camera.center)


def test_replacing_the_first_camera_keeps_the_views_in_step(tmp_path):
    scene = scene_from_dict(two_cameras(), tmp_path)
    other = scene.view("side").camera
    moved = dataclasses.replace(scene, camera=other)
    assert moved.view("front").camera is other and moved.view("side").camera is other
    assert moved.view_names == ("front", "side")


@pytest.mark.parametrize(
    "mend, words",
    [
        (lambda d: d.update(camera=d["cameras"][0]), "either 'cameras'"),
        (lambda d: d.update(cameras=[]), "non-empty list"),
        (lambda d: d["cameras"][1].update(name="front"), "names two cameras"),
        (lambda d: d["cameras"][1].update(name="side view"), "letters, digits"),
        (lambda d: d["cameras"][1].pop("name"), "missing field 'name'"),
        (lambda d: d["cameras"][1].pop("K"), r"cameras\[1\]: give exactly one of"),
        (lambda d: d["cameras"][0]["video"].update(fps=-1), r"cameras\[0\]\.video\.fps"),
    ],
)
def test_a_bad_camera_list_is_refused_naming_the_field(tmp_path, mend, words):
    d = copy.deepcopy(two_cameras())
    mend(d)
    with pytest.raises(SceneError, match=words):
        scene_from_dict(d, tmp_path)


def test_an_unknown_camera_name_says_which_there_are(tmp_path):
    scene = scene_from_dict(two_cameras(), tmp_path)
    with pytest.raises(SceneError, match=r"no camera named 'top'; its cameras: \('front', 'side'\)"):
        scene.view("top")
