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
