"""The recent frames kept for the frozen frame's scrubber: bounded, by arrival time, looping videos."""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.ui.recent import RecentFrames
from app.video import Frame


class _Grabber:
    def __init__(self):
        self.listeners = []

    def add_listener(self, fn):
        self.listeners.append(fn)

    def latest(self):
        return None

    def push(self, frame):
        for fn in self.listeners:
            fn(frame)


def test_frames_kept_bounded_and_found_by_seconds_back():
    g = _Grabber()
    r = RecentFrames(g, seconds=0.5, max_frames=10)
    img = np.zeros((2, 2, 3), np.uint8)
    for i in range(40):
        g.push(Frame(img, i, (i % 7) * 0.1))  # a looping recording: its time restarts
        time.sleep(0.02)
    assert 1 < len(r) <= 10
    newest = r.back(0)
    assert newest.index == r.frames()[-1].index
    older = r.seconds_back(0.2)
    assert older.index < newest.index
    assert r.seconds_back(100.0).index == r.frames()[0].index  # clamped to the oldest kept
    with pytest.raises(ValueError):
        RecentFrames(g, seconds=0.0)


def test_the_frame_shown_before_a_frozen_one():
    """``before``: the kept frame that arrived about that long before the given one (whose motion the
    frozen frame is checked for), None for the first kept or a frame not kept."""
    g = _Grabber()
    r = RecentFrames(g, seconds=5.0, max_frames=100)
    img = np.zeros((2, 2, 3), np.uint8)
    frames = []
    for i in range(12):
        frames.append(Frame(img, i, i * 0.05))
        g.push(frames[-1])
        time.sleep(0.06)
    got = r.before(frames[-1], 0.3)
    assert got is not None and 1 <= frames[-1].index - got.index <= 7  # about 0.3 s: 5 frames at one per 0.06 s
    assert r.before(frames[0], 0.3) is None  # nothing older
    assert r.before(Frame(img, 99, 9.9), 0.3) is None  # not kept


def test_seconds_back_from_a_frame_on_screen_and_how_far_it_reached():
    """``back_from``: counted from when the frame on screen arrived, not from the newest; beyond the kept
    frames the oldest, with how far back it really is (less than asked: the panel says it was clamped)."""
    g = _Grabber()
    r = RecentFrames(g, seconds=5.0, max_frames=100)
    img = np.zeros((2, 2, 3), np.uint8)
    for i in range(16):
        g.push(Frame(img, i, i * 0.05))
        time.sleep(0.06)
    kept = r.frames()
    on_screen = kept[10]
    at = r.arrival(on_screen)
    frame, back_s = r.back_from(at, 0.3)
    assert 0.2 <= back_s <= 0.4 and 3 <= on_screen.index - frame.index <= 7
    assert frame.index < r.seconds_back(0.3).index  # the newest's 0.3 s back is a later frame
    oldest, reached = r.back_from(at, 30.0)
    assert oldest.index == kept[0].index and reached < 1.0  # clamped: far less than asked


def test_seconds_back_past_the_kept_frames_is_said_never_as_a_negative_time():
    from app.ui.frozen import past_kept

    assert past_kept(4.0, 3.9, 12.0) == ""  # the frame asked for (the scrubber's step is 0.5 s)
    said = past_kept(12.0, 9.5, 12.0)
    assert "reaches past the frames kept" in said and "9.5 s before the frame you scrubbed from" in said
    # frozen a minute before, its frame has left the kept 12 s: the oldest kept is 50.5 s after it (a new operator
    # read "the oldest kept, -50.5 s before the frame you scrubbed from")
    said = past_kept(10.0, -50.5, 12.0)
    assert "-" not in said.replace("Seconds back", "") and "50.5 s after it" in said and "last 12 s" in said
