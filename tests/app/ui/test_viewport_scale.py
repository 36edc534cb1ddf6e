"""app/ui/viewport.py: the view's scale is in the screen's pixels (CSS pixels) once the page has told the view's size,
whatever the page's pixel ratio; viser's camera report counts the canvas's own pixels (the screen's times the ratio)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.ui.viewport import Viewport, camera_now


def _viewport(image_height: int) -> Viewport:
    camera = SimpleNamespace(
        position=np.array([0.0, 0.0, -2.0]),
        look_at=np.zeros(3),
        wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
        fov=np.deg2rad(60.0),
        image_width=round(1.6 * image_height),
        image_height=image_height,
        on_update=lambda cb: cb,
    )
    client = SimpleNamespace(camera=camera, scene=SimpleNamespace(on_rect_select=lambda: lambda cb: cb))
    feed = SimpleNamespace(pixel_world=SimpleNamespace(k=0.01))
    panel = SimpleNamespace(client=client, guard=lambda fn: fn, feed=feed)
    return Viewport(panel)


def test_the_scale_is_per_screen_pixel_whatever_the_pages_pixel_ratio():
    visible = 2.0 * 2.0 * np.tan(np.deg2rad(30.0)) / 0.01  # video pixels across the view's height
    for ratio in (0.25, 1.0, 2.0):  # the canvas's own pixels per screen pixel
        vp = _viewport(image_height=round(500 * ratio))
        assert vp.image_px_per_screen_px() == pytest.approx(visible / round(500 * ratio))  # not told yet: the canvas's
        vp.on_canvas_size("800 500")
        assert vp.screen_size == (800, 500)
        assert vp.image_px_per_screen_px() == pytest.approx(visible / 500)


@pytest.mark.parametrize("said", ["", "800", "wide 500", "0 500", "800 -1", "800 1e9", "8e5 500"])
def test_what_is_not_a_size_is_ignored(said):
    vp = _viewport(image_height=250)
    vp.on_canvas_size("640 480")
    vp.on_canvas_size(said)
    assert vp.screen_size == (640, 480)


def test_a_camera_move_is_sent_even_where_the_page_last_reported_its_camera():
    """viser sends nothing for a camera value equal to the page's last report; a move sent before and still on its way
    may take the page elsewhere, so place_camera sends it all the same, ending on the asked values."""
    from viser import CameraHandle

    from app.ui.viewport import place_camera

    sent = []
    client = SimpleNamespace(_websock_connection=SimpleNamespace(queue_message=sent.append))
    cam = CameraHandle(client)
    reported = (np.array([2.5, 1.3, -2.8]), np.array([2.5, 1.3, 0.0]))  # the page's report
    cam._state.position, cam._state.look_at = reported[0].copy(), reported[1].copy()
    cam._state.up_direction, cam._state.update_timestamp = np.array([0.0, -1.0, 0.0]), 1.0
    place_camera(cam, *reported)
    positions = [m.position for m in sent if type(m).__name__ == "SetCameraPositionMessage"]
    looks = [m.look_at for m in sent if type(m).__name__ == "SetCameraLookAtMessage"]
    assert positions and looks, "nothing sent for a camera equal to the page's report"
    assert np.allclose(positions[-1], reported[0], rtol=0, atol=1e-12)
    assert np.allclose(looks[-1], reported[1], rtol=0, atol=1e-12)
    assert np.allclose(cam.position, reported[0], rtol=0, atol=1e-12)
    sent.clear()
    place_camera(cam, reported[0] + [0.0, 0.0, 0.5], reported[1])  # a camera elsewhere: sent as it is, once
    assert [type(m).__name__ for m in sent].count("SetCameraPositionMessage") == 1


class _ReportedMidRead:
    """A viser camera whose page reports a new camera while it is being read: the state behind it is replaced whole
    (viser's event loop) after the first read of its position."""

    def __init__(self, states):
        self.states, self.reads = list(states), 0

    def __getattr__(self, name):
        state = self.states[0]
        if name == "position":
            self.reads += 1
            if self.reads == 1 and len(self.states) > 1:
                self.states.pop(0)  # the next report lands between this read and the next
        return state[name]


def test_a_camera_is_read_as_one_report_of_the_page():
    def report(x):
        return dict(
            position=np.array([x, 0.0, -2.0]),
            look_at=np.array([x, 0.0, 0.0]),
            wxyz=np.array([1.0, 0.0, 0.0, x]),
            fov=0.5,
            image_width=800,
            image_height=500,
        )

    cam = camera_now(_ReportedMidRead([report(1.0), report(2.0)]))
    # before: the first report's position with the next's look-at, a camera tilted by 27 degrees the page never had
    assert cam.position[0] == cam.look_at[0] == cam.wxyz[3] == 2.0
    assert cam.aspect == pytest.approx(1.6)
    assert camera_now(SimpleNamespace(**{**report(0.0), "image_height": 0})) is None  # no view to read yet


def test_fit_view_again_shows_every_camera_until_the_operator_moves_the_view():
    """Fit view on a fitted view shows every camera's image, whether or not the page has yet reported the fit back
    (a loaded CI run's page had not: Fit view fitted the one image again); once the page reports a camera away from
    the fit, the operator moved it, and Fit view fits the shown image."""
    vp = _viewport(image_height=500)
    vp.panel.app = SimpleNamespace(views={"front": None, "side": None}, wake=lambda: None)
    vp.panel.dirty = False
    vp.panel.feed.pixel_world.fit_camera = lambda aspect, fov: (np.array([0.0, 0.0, -2.0]), np.zeros(3), None)
    vp._fitted_at, vp.fit_pending, vp._moved, vp.fitted_aspect = np.array([0.0, 0.0, -2.0]), True, False, 1.6
    vp._page_position = np.array([0.0, 0.0, -5.0])  # the page's last report: the camera before the fit
    vp.request_fit(again=True)
    assert vp.all_cameras  # the page has not reported the fit yet
    vp.request_fit(again=True)
    assert not vp.all_cameras  # again: the shown camera's alone
    vp.fit_pending = False
    vp.client.camera.position = np.array([0.3, 0.0, -1.0])  # the page's report: panned and zoomed by its controls
    vp.on_camera(vp.client.camera)
    vp.request_fit(again=True)
    assert not vp.all_cameras
