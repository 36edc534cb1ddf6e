"""The recent video frames, for freezing one and scrubbing back (the operator's frozen frame).

``RecentFrames`` listens to the grabber and keeps the frames of the last ``seconds`` (at most one
every ``seconds / max_frames``, so memory stays bounded: 120 frames of 640×480 RGB are 110 MB at
most, of the workcell's 512×256 video 47 MB). Frames are shared read-only arrays: nothing is copied.
"""

from __future__ import annotations

import collections
import threading
import time
from typing import Any

__all__ = ["RecentFrames"]


class RecentFrames:
    """A bounded ring of the grabber's recent frames (``app.video.Frame``: image, index, t_s).

    seconds : how far back the scrubber reaches. max_frames : the most frames kept.
    """

    def __init__(self, grabber: Any, seconds: float = 12.0, max_frames: int = 120):
        if not (seconds > 0 and max_frames > 1):
            raise ValueError(f"seconds must be > 0 and max_frames > 1, got {seconds}, {max_frames}")
        self.seconds = float(seconds)
        self.min_gap_s = self.seconds / max_frames
        self._frames: collections.deque = collections.deque(maxlen=int(max_frames))
        self._lock = threading.Lock()
        grabber.add_listener(self._on_frame)
        first = grabber.latest()
        if first is not None:
            self._on_frame(first)

    def _on_frame(self, frame: Any) -> None:
        now = time.monotonic()
        with self._lock:
            if self._frames:
                last, at = self._frames[-1]
                if frame.index == last.index or now - at < self.min_gap_s:
                    return
            self._frames.append((frame, now))

    def frames(self) -> list:
        """The kept frames, oldest first."""
        with self._lock:
            return [f for f, _ in self._frames]

    def seconds_back(self, seconds: float) -> Any:
        """The kept frame shown ``seconds`` before the newest one (by when they arrived: a looped
        recording's time restarts), the oldest kept if it goes further back; None when empty."""
        with self._lock:
            if not self._frames:
                return None
            newest = self._frames[-1][1]
        hit = self.back_from(newest, seconds)
        return None if hit is None else hit[0]

    def back_from(self, at: float, seconds: float) -> tuple[Any, float] | None:
        """(the kept frame that arrived nearest ``seconds`` before ``at`` (time.monotonic: when the frame on
        screen arrived), how long before ``at`` it arrived); the oldest kept when that reaches further back
        (the caller says so: the second value is then less than ``seconds``). None when empty."""
        with self._lock:
            if not self._frames:
                return None
            want = float(at) - float(seconds)
            frame, arrived = min(self._frames, key=lambda fa: abs(want - fa[1]))
            return frame, float(at) - arrived

    def before(self, frame: Any, seconds: float) -> Any:
        """The kept frame that arrived about ``seconds`` before ``frame`` (at least half that), or None
        (``frame`` not kept, or nothing that much older)."""
        with self._lock:
            at = next((a for f, a in self._frames if f.index == frame.index), None)
            if at is None:
                return None
            older = [(f, a) for f, a in self._frames if a <= at - 0.5 * float(seconds) and f.index != frame.index]
            return min(older, key=lambda fa: abs(at - float(seconds) - fa[1]))[0] if older else None

    def arrival(self, frame: Any) -> float | None:
        """When ``frame`` arrived (time.monotonic), None when it is not kept."""
        with self._lock:
            return next((a for f, a in self._frames if f.index == frame.index), None)

    def nearest(self, arrival: float) -> tuple[Any, float] | None:
        """(the kept frame that arrived nearest to ``arrival`` (time.monotonic), when it arrived); None when
        empty: another camera's frame shown at the moment one camera's was frozen."""
        with self._lock:
            if not self._frames:
                return None
            return min(self._frames, key=lambda fa: abs(fa[1] - float(arrival)))

    def __len__(self) -> int:
        with self._lock:
            return len(self._frames)

    def back(self, k: int) -> Any:
        """The frame ``k`` steps before the newest (0: the newest), clamped; None when empty."""
        with self._lock:
            if not self._frames:
                return None
            k = min(max(int(k), 0), len(self._frames) - 1)
            return self._frames[-1 - k][0]
