"""The demo's overlay frames: the state shown at each time, the wireframes where C puts them."""

from __future__ import annotations

import numpy as np
import pytest

from app.demo.overlay_video import ascii_text, draw_overlay, state_at
from app.demo.replay import OverlayState
from app.overlay import STATUS_COLORS
from app.scene import default_scene_path, load_scene
from app.workflows.site import SiteObject


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


def _state(scene, t, objects=(), text=""):
    return OverlayState(t, tuple(objects), scene.camera, None, None, "", text)


def test_state_at_is_the_last_state_at_or_before_t(scene):
    tl = [
        _state(scene, 0.0, text="a"),
        _state(scene, 1.0, text="b"),
        _state(scene, 1.0, text="c"),
        _state(scene, 2.5, text="d"),
    ]
    assert [state_at(tl, t).text for t in (-1.0, 0.0, 0.99, 1.0, 2.0, 2.5, 9.0)] == ["a", "a", "a", "c", "c", "d", "d"]


def test_wireframe_drawn_where_the_camera_projects_it(scene):
    body = scene.body("parallelepiped")
    obj = SiteObject(1, body.name, body.kind, "known", body.model, body.pose_at(0.0), 1)
    frame = np.full((scene.camera.height, scene.camera.width), 60, np.uint8)
    img = draw_overlay(frame, _state(scene, 0.0, [obj], "next step"), 0.0, scale=2)
    assert img.shape == (2 * scene.camera.height, 2 * scene.camera.width, 3) and img.dtype == np.uint8
    green = np.array(STATUS_COLORS["known"][::-1])  # BGR
    V = body.model.vertices @ body.pose_at(0.0)[:3, :3].T + body.pose_at(0.0)[:3, 3]
    uv = scene.camera.project(V)
    # Midpoints of the visible edges, in the enlarged image: the known colour is there.
    wf = body.model.wireframe(scene.camera.center, body.pose_at(0.0))
    mids = scene.camera.project(wf.segments[wf.visible].mean(axis=1))
    px = np.round((mids + 0.5) * 2 - 0.5).astype(int)
    near = [np.abs(img[v - 1 : v + 2, u - 1 : u + 2].astype(int) - green).sum(axis=2).min() for u, v in px]
    assert np.median(near) < 60
    far = np.round((uv.mean(axis=0) + [0, 60] + 0.5) * 2 - 0.5).astype(int)  # below the box, on the bare frame
    assert np.all(img[far[1], far[0]] == 60)
    with pytest.raises(ValueError, match="grey image"):
        draw_overlay(np.zeros((4, 4, 3), np.uint8), _state(scene, 0.0), 0.0)


def test_ascii_text_spells_out_what_the_font_cannot_draw():
    assert ascii_text("size_x = 9.26 ± 0.33 cm, 55° → σ…") == "size_x = 9.26 +/- 0.33 cm, 55 deg -> s..."
    assert ascii_text("naïve").isascii()


def test_a_still_is_the_first_frame_after_the_action():
    from app.demo.overlay_video import still_frame

    assert still_frame(17.04, 12.0) == 205 and still_frame(17.0, 12.0) == 204 and still_frame(0.0, 12.0) == 0
