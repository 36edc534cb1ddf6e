"""The interface's track feeder: a Track workflow fed the grabber's frames on its own thread; the
operator is notified once when the track is lost; the feeder ends with the workflow. The frame
provider the server installs is the grabber's latest frame."""

from __future__ import annotations

import threading
import time

import numpy as np

from app.ui.tracking import TrackFeeder
from app.video import FrameGrabber, StillSource
from app.workflows import TrackObject
from app.workflows.frames import GrabberFrames


class _Panel:
    """What the feeder uses of a client panel: notify, dirty, app.wake."""

    def __init__(self):
        self.notes: list[tuple[str, str, str]] = []
        self.dirty = False
        self.wakes = 0
        self.app = self

    def notify(self, title, body, color="yellow", stays=False):
        self.notes.append((title, body, color))

    def wake(self):
        self.wakes += 1


def _wait(predicate, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def test_feeder_tracks_live_frames_then_notifies_once_when_lost_and_stops_with_the_workflow(video_site):
    site = video_site
    site.t["t"] = 2.0
    frame = site.frame_at()  # the box where the database has it
    grabber = FrameGrabber(StillSource(np.ascontiguousarray(frame), fps=50)).start()
    try:
        assert _wait(lambda: grabber.latest() is not None)
        assert np.array_equal(GrabberFrames(grabber)(123.0), grabber.latest().image)  # the latest, whatever the time
        wf = TrackObject(site, object_name="parallelepiped")
        panel = _Panel()
        feeder = TrackFeeder(panel, wf, grabber)
        assert _wait(lambda: wf.frames >= 5) and not wf.lost and panel.wakes >= 5 and panel.dirty
        assert feeder.steps == wf.frames and not panel.notes
        assert threading.current_thread() is not feeder.thread
        # the video goes blank: lost, one notification, no more steps
        blank = FrameGrabber(StillSource(np.zeros_like(frame), fps=50)).start()
        feeder.stop()
        assert _wait(lambda: not feeder.alive)
        feeder = TrackFeeder(panel, wf, blank)
        assert _wait(lambda: wf.lost)
        time.sleep(0.2)
        assert [n[0] for n in panel.notes] == ["Tracking lost"] and "Re-initialise" in panel.notes[0][1]
        # the frame it was lost on is the one the panel freezes ("Lost at t = 17.20 s" froze 17.60 s: the newest)
        assert wf.stepped_on.t_s == wf.t_lost and wf.stepped_on.index <= blank.latest().index
        steps = wf.frames
        time.sleep(0.2)
        assert wf.frames == steps  # a lost track is not fed
        wf.cancel()
        assert _wait(lambda: not feeder.alive)
        assert feeder._on_frame not in blank._listeners  # it let go of the grabber
        blank.stop()
    finally:
        grabber.stop()


def test_track_started_on_a_frozen_frame_follows_the_frames_kept_since_it(video_site):
    """The operator froze the frame where the database's pose is right (t = 12.0 s) and pressed Track once the video had
    moved on (13.0 s, the box turned 18° and 9 cm off): the track starts on the frozen frame and follows the frames
    kept since it, in order, to the newest. From the newest (as before: a new operator's track on a recording was lost
    at its first frame) it is lost."""
    from types import SimpleNamespace

    from app.video import Frame
    from core.transforms import pose_error

    site = video_site
    body = site.scene.body("parallelepiped")
    kept = [
        Frame(np.ascontiguousarray(site.frame_at(t)), 10_000 + k, float(t))
        for k, t in enumerate(np.round(np.arange(12.0, 13.01, 0.1), 2))
    ]
    recent = SimpleNamespace(frames=lambda: list(kept))
    grabber = FrameGrabber(StillSource(kept[-1].image, fps=50)).start()  # the live video: at 13.0 s
    try:
        assert _wait(lambda: grabber.latest() is not None)
        runs = {}
        for start in (kept[0], None):
            wf = TrackObject(site, object_name="parallelepiped")
            feeder = TrackFeeder(_Panel(), wf, grabber, recent, start=start)
            assert _wait(lambda wf=wf: wf.lost or wf.frames >= len(kept) + 15, timeout_s=60)
            runs[start is None] = (wf.lost, pose_error(wf.T_world_obj, body.pose_at(13.0)))
            wf.cancel()
            assert _wait(lambda feeder=feeder: not feeder.alive)
        lost, (deg, m) = runs[False]
        # (started at the true pose, the tracker settles 0.98° and 11 mm off on this frame: the box moving, blurred;
        # its σ up to 9.5 mm)
        assert not lost and deg < 2.0 and m < 0.02, runs
        assert runs[True][0], runs  # from the newest: lost at once
    finally:
        grabber.stop()


def test_a_track_slower_than_the_frames_kept_goes_on_from_the_newest():
    """Catching up, a tracker slower than the video falls off the frames kept (the oldest dropped before it reached
    them): it goes on from the newest, never tracking further and further behind the live video."""
    from types import SimpleNamespace

    from app.video import Frame

    img = np.zeros((4, 4, 3), np.uint8)
    kept = [Frame(img, i, 0.1 * i) for i in range(10)]
    newest = Frame(img, 99, 9.9)
    grabber = SimpleNamespace(latest=lambda: newest)
    feeder = TrackFeeder.__new__(TrackFeeder)  # its choice of frames alone (no thread)
    feeder.recent, feeder.grabber = SimpleNamespace(frames=lambda: list(kept)), grabber
    feeder._first, feeder._catch_up, feeder._from_kept = kept[0], None, False
    assert [feeder._next().index for _ in range(3)] == [0, 1, 2]  # the start, then the frames kept after it
    del kept[:5]  # the ring dropped frames 0-4 (the last tracked, 2, among them) before the tracker came back
    assert feeder._next() is newest and feeder._next() is newest
