"""Which clicks are one gesture (app.ui.clicks.ClickTimer): a double click told by the page whose first
click reaches the server after it (the two travel as different messages; on a loaded machine they
swapped) is one gesture, the late first click dropped (as an edge's first point it hid the found poses'
Accept); and what the session makes of a double click (app.workflows.Session.double_click)."""

import numpy as np
import pytest

from app.ui.clicks import ClickTimer
from app.workflows import WorkflowError


def _taken(timer, uv, at, double=False):
    """The gesture a click makes, as (double, uv) rounded, or None when it is dropped."""
    g = timer.arrive(np.array(uv, float), at, double, "box_1", None)
    return None if g is None else (g.double, tuple(np.round(g.uv, 1)))


def test_the_first_click_arriving_after_its_double_is_dropped():
    timer = ClickTimer()
    assert _taken(timer, (100, 100), 10.0, double=True) == (True, (100.0, 100.0))  # the double, told by the page
    assert _taken(timer, (103, 101), 10.9) is None  # its first click, late
    assert _taken(timer, (103, 101), 11.5) == (False, (103.0, 101.0))  # a click made afterwards is a click


def test_a_first_click_that_came_in_order_leaves_the_next_click_alone():
    timer = ClickTimer()
    assert _taken(timer, (100, 100), 9.8) == (False, (100.0, 100.0))
    assert _taken(timer, (100, 100), 10.0, double=True)[0] is True
    assert _taken(timer, (101, 100), 10.5) == (False, (101.0, 100.0))  # a third click: the operator's, taken


def test_a_told_double_is_placed_at_its_first_click_which_the_page_placed_itself():
    """The first click comes as the page's own ray; the told double as a point of the canvas the server maps
    through the camera it holds, which can be a fit the page does not show yet (a loaded CI run searched from
    there and found no pose)."""
    timer = ClickTimer()
    assert _taken(timer, (100, 100), 9.8) == (False, (100.0, 100.0))
    assert _taken(timer, (108, 95), 10.0, double=True) == (True, (100.0, 100.0))
    timer = ClickTimer()
    _taken(timer, (100, 100), 5.0)  # long before: the double is placed where it was told
    assert _taken(timer, (108, 95), 10.0, double=True) == (True, (108.0, 95.0))


def test_a_click_elsewhere_or_later_is_taken():
    timer = ClickTimer()
    _taken(timer, (100, 100), 10.0, double=True)
    assert _taken(timer, (160, 100), 10.5) is not None  # elsewhere
    assert _taken(timer, (100, 100), 14.0) is not None  # long after


def test_two_clicks_close_at_the_server_are_a_double_carrying_the_first_clicks_selection_and_frame():
    timer = ClickTimer()
    first = timer.arrive(np.array([50.0, 60.0]), 1.0, None, "box_1", "frame A")
    second = timer.arrive(np.array([51.0, 60.0]), 1.3, None, "table", "frame B")
    assert not first.double and second.double
    assert (second.before, second.frame) == ("box_1", "frame A")  # what was selected and shown at its first click
    third = timer.arrive(np.array([51.0, 60.0]), 1.5, None, "box_1", "frame C")
    assert not third.double  # a third click is a click of its own, not a second double
    late = timer.arrive(np.array([51.0, 60.0]), 3.0, None, "box_1", "frame D")
    assert not late.double


class _Workflow:
    """A workflow under way that takes clicks, as the session sees one."""

    title, finished, actions, message, view = "Update pose", False, ("click", "find"), "", "front"

    def __init__(self, press):
        self.clicks, self.press = [], press

    def current_step(self):
        from app.workflows.base import Step

        return Step("edges", "click", frozenset({"cancel"}))

    def click_in(self, view, uv):
        self.clicks.append((view, tuple(uv)))

    def on_double_click(self, view, uv):
        return self.press

    def follows_live(self):
        return ""


def _session(wf):
    from app.workflows.session import Session

    s = Session.__new__(Session)
    s._workflow, s.waiting, s.selected, s.on_start = wf, None, None, None
    return s


def test_the_workflow_decides_what_a_double_click_presses_and_a_click_is_its_own():
    from app.workflows.base import AS_CLICK

    s = _session(_Workflow("find"))
    assert s.double_click("front", np.array([1.0, 2.0]), before=None, on=None) == "find"
    assert s.workflow.clicks == []
    s = _session(_Workflow(AS_CLICK))  # one more click
    assert s.double_click("front", np.array([1.0, 2.0]), before=None, on=None) is None
    assert s.workflow.clicks == [("front", (1.0, 2.0))]
    s = _session(_Workflow(None))  # dropped
    assert s.double_click("front", np.array([1.0, 2.0]), before=None, on=None) is None and s.workflow.clicks == []


def test_a_click_over_a_frozen_frame_with_the_live_video_shown_is_refused():
    s = _session(_Workflow("find"))
    with pytest.raises(WorkflowError, match="live video"):
        s.click("front", np.array([1.0, 2.0]), live_shown=True)
    assert s.workflow.clicks == []
