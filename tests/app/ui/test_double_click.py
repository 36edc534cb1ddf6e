"""A double click told by the page whose first click reaches the server after it (the two travel as
different messages; on a loaded machine they swapped) is one gesture: the late first click is not a
new click (as an edge's first point it hid the found poses' Accept)."""

from types import SimpleNamespace

import numpy as np

from app.ui.client import ClientPanel


class _Workflow:
    name, finished, double_click_is_one, actions, message = "update_pose", False, False, {"click"}, ""

    def __init__(self):
        self.clicks = []

    def current_step(self):
        return SimpleNamespace(clicks=True, enabled=frozenset())

    view = "front"

    def click_in(self, view, uv):
        assert view == self.view
        self.clicks.append(tuple(np.round(uv, 1)))


def _panel():
    wf = _Workflow()
    panel = SimpleNamespace(
        session=SimpleNamespace(workflow=wf, selected="box_1"),
        app=SimpleNamespace(grabber=SimpleNamespace(latest=lambda: None)),
        _last_double=None,
        camera_view="front",
        feed=SimpleNamespace(grabber=SimpleNamespace(latest=lambda: None)),
        show_live=False,
        frozen=None,
        error="",
        warning="",
        confirm_pending=None,
    )
    return panel, wf


def _click(panel, uv, at, double=False):
    ClientPanel.on_pixel_click(panel, np.array(uv, float), at=at, double=double)


def test_the_first_click_arriving_after_its_double_is_dropped():
    panel, wf = _panel()
    _click(panel, (100, 100), at=10.0, double=True)  # the double, told by the page
    _click(panel, (103, 101), at=10.9)  # its first click, late
    assert wf.clicks == [(100.0, 100.0)]
    _click(panel, (103, 101), at=11.5)  # a click made afterwards is a click
    assert wf.clicks == [(100.0, 100.0), (103.0, 101.0)]


def test_a_first_click_that_came_in_order_leaves_the_next_click_alone():
    panel, wf = _panel()
    _click(panel, (100, 100), at=9.8)
    _click(panel, (100, 100), at=10.0, double=True)
    _click(panel, (101, 100), at=10.5)  # a third click: the operator's, taken
    assert len(wf.clicks) == 3


def test_a_click_elsewhere_or_later_is_taken():
    panel, wf = _panel()
    _click(panel, (100, 100), at=10.0, double=True)
    _click(panel, (160, 100), at=10.5)  # elsewhere
    _click(panel, (100, 100), at=14.0)  # long after
    assert len(wf.clicks) == 3
