"""Prerecorded videos are played on a clock: frame k is shown at start + k / fps, and frames due while a
slow frame held the thread go unseen, so two cameras' recordings given one start show one moment (the
side camera's video ran 1.5 s behind the front one's, its frames handled slower under load)."""

import time

import numpy as np

from app.video import FrameGrabber, VideoSource


class _Numbered(VideoSource):
    """Frames that carry their number."""

    def __init__(self, fps: float):
        super().__init__()
        self.width, self.height, self.fps, self.frame_count = 8, 8, fps, 10_000
        self.description = "numbered frames"

    def _read(self):
        return np.full((8, 8, 3), (self._position + 1) % 256, np.uint8)


def test_a_slow_recording_keeps_the_clock_of_a_fast_one():
    fps, start = 20.0, time.monotonic() + 0.05
    fast = FrameGrabber(_Numbered(fps), start_at=start).start()
    # each of its frames handled in 0.12 s (sent to the pages, on a loaded machine): 0.05 s is due
    slow = FrameGrabber(_Numbered(fps), on_frame=lambda _f: time.sleep(0.12), start_at=start).start()
    try:
        time.sleep(2.0)
        a, b = fast.latest(), slow.latest()
        now_index = (time.monotonic() - start) * fps
        assert abs(a.index - now_index) <= 6, (a.index, now_index)
        assert abs(b.index - a.index) <= 6, (b.index, a.index)  # without the clock: about 23 frames behind
        assert abs(b.t_s - a.t_s) <= 6 / fps
    finally:
        fast.stop()
        slow.stop()


def test_a_corner_stamp_marks_the_bottom_left_and_leaves_the_rest():
    """The frozen frame is marked on the video ("FROZEN t = …"), as a replay is ("REPLAY …")."""
    from app.video import stamp_corner

    image = np.full((256, 512, 3), 128, np.uint8)
    out = stamp_corner(image, "FROZEN t = 12.30 s")
    changed = np.argwhere(np.any(out != image, axis=2))
    assert len(changed) and changed[:, 0].min() > 200 and changed[:, 1].max() < 256  # the bottom-left corner only
    assert np.array_equal(image, np.full((256, 512, 3), 128, np.uint8))  # a copy: the clicked frame untouched
