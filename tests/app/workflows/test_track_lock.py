"""Track's step computes outside the workflow's lock (the overlay's marks() never waits for it) and
drops its result when the tracker was reset meanwhile."""

from __future__ import annotations

import threading

from app.workflows import Session


def _slowed(wf):
    """Make the workflow's tracker block inside track() until released."""
    entered, release = threading.Event(), threading.Event()

    class SlowTracker(type(wf.tracker)):
        def track(self, frame):
            entered.set()
            release.wait(30)
            return super().track(frame)

    wf.tracker.__class__ = SlowTracker
    return entered, release


def _start(video_site):
    video_site.t["t"] = 11.5
    session = Session(video_site, client="alice")
    session.select("parallelepiped")
    return session.start("track")


def test_marks_are_served_while_a_slow_step_tracks(video_site):
    wf = _start(video_site)
    entered, release = _slowed(wf)
    results = []
    worker = threading.Thread(target=lambda: results.append(wf.step()), daemon=True)
    worker.start()
    assert entered.wait(30)
    free = wf.lock.acquire(blocking=False)  # the step holds no lock while it tracks
    if free:
        wf.lock.release()
    marks = wf.marks()
    release.set()
    worker.join(30)
    assert free and len(marks.tracked) == 1
    assert results and not results[0].lost and wf.frames == 1  # then its result is committed


def test_a_step_overtaken_by_a_restart_is_dropped(video_site):
    wf = _start(video_site)
    entered, release = _slowed(wf)
    T0 = wf.T_world_obj.copy()
    worker = threading.Thread(target=wf.step, daemon=True)
    worker.start()
    assert entered.wait(30)
    wf.restart()  # resets the tracker while the step computes
    release.set()
    worker.join(30)
    assert wf.frames == 0 and (wf.T_world_obj == T0).all() and wf.diagnostics is None
