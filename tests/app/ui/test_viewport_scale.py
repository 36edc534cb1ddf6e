"""app/ui/viewport.py: the view's scale is in the screen's pixels (CSS pixels) once the page has told the view's size,
whatever the page's pixel ratio; viser's camera report counts the canvas's own pixels (the screen's times the ratio)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.ui.viewport import Viewport


def _viewport(image_height: int) -> Viewport:
    camera = SimpleNamespace(
        position=np.array([0.0, 0.0, -2.0]), fov=np.deg2rad(60.0), image_height=image_height, on_update=lambda cb: cb
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
