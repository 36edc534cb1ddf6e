"""Which clicks on the video are one gesture: a click, a double click, or the late half of one.

A double click reaches the server as two messages, its first click and the page's double (static/wheel.js
times the presses with the browser's own clock and tells the double); on a loaded machine they can
arrive seconds apart and in either order. ``ClickTimer`` pairs them: a click soon after a told double and
near it is that double's own first click, arriving late, and is dropped; two plain clicks close in time
and place at the server are a double click too (a page whose script did not run). What a click or a
double click means is the session's to decide (``app.workflows.Session.click`` / ``double_click``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["ClickTimer", "Gesture", "DOUBLE_CLICK_S", "DOUBLE_CLICK_PX"]

DOUBLE_CLICK_S = 0.6  # two clicks this close in time and place at the server are a double click
DOUBLE_CLICK_PX = 4.0
LATE_FIRST_CLICK_S = 3.0  # a click by a page-told double click soon after it is its first click, arriving late
LATE_FIRST_CLICK_PX = 12.0  # the page tells a double within 5 screen px: more image px when the view is zoomed out


@dataclass(frozen=True)
class Gesture:
    """A click or the second click of a double click at pixel ``uv``. ``before``: the object selected
    before the gesture's first click; ``frame``: the frame shown at it (a double click with no workflow
    under way works on that frame)."""

    uv: np.ndarray
    double: bool
    before: str | None = None
    frame: Any = None


class ClickTimer:
    """Pairs the clicks of one page (see the module docstring)."""

    def __init__(self) -> None:
        self.last: tuple | None = None  # (arrival, uv, selected then, frame shown then) of the last click
        self.told: tuple | None = None  # (arrival, uv) of a told double click whose first click is awaited

    def arrive(
        self, uv: np.ndarray, at: float, double: bool | None, selected: str | None, frame: Any
    ) -> Gesture | None:
        """A click at pixel uv arrived at ``at`` (monotonic seconds). ``double``: the page told it is a double
        click's second click (True), or not (False); None: a double if it follows the last click closely.
        ``selected`` and ``frame``: the selection and the frame shown now. None: the click is a told double's
        own first click, arriving after it, and is dropped."""
        uv = np.asarray(uv, float).copy()
        last, told = self.last, self.told
        if not double and told is not None and 0 <= at - told[0] <= LATE_FIRST_CLICK_S:
            if np.linalg.norm(uv - told[1]) <= LATE_FIRST_CLICK_PX:
                self.told = None
                return None
        # the last click can be this double click's first (a told double is placed where it was)
        first_seen = (
            last is not None
            and at - last[0] <= LATE_FIRST_CLICK_S
            and np.linalg.norm(uv - last[1]) <= LATE_FIRST_CLICK_PX
        )
        if double:  # its first click is still awaited when none came before it at that point
            self.told = None if first_seen else (at, uv)
        if double is None:
            double = (
                last is not None and at - last[0] <= DOUBLE_CLICK_S and np.linalg.norm(uv - last[1]) <= DOUBLE_CLICK_PX
            )
        if not double:
            self.last = (at, uv, selected, frame)
            return Gesture(uv, False, selected, frame)
        self.last = None  # a third click is a click of its own
        if first_seen:
            # at its first click: placed by the page's own ray, where a told double's point goes through the camera
            # the server holds, which lags the page's or leads it (a fit sent and not yet shown)
            return Gesture(last[1], True, last[2], last[3])
        first = last if last is not None else (at, uv, selected, frame)  # its first click unseen: as if made here
        return Gesture(uv, True, first[2], first[3])
