"""Track on a recording that restarts: the loss says the video jumped back in time (the workcell's
video loops; at its restart the tracked box is back where it started)."""

from __future__ import annotations

from app.workflows import Session


def test_a_loss_where_the_video_jumped_back_says_so(video_site):
    site = video_site
    site.t["t"] = 11.5  # the box still, at the database's pose
    session = Session(site, client="alice")
    session.select("parallelepiped")
    wf = session.start("track")
    for t in (11.5, 11.6, 11.7):
        site.t["t"] = t
        assert not wf.step()[2]
    site.t["t"] = 11.6  # a small step back (a late frame) is no jump: still tracked
    assert not wf.step()[2]
    site.t["t"] = 16.0  # forward, the box 55° away: lost, no jump
    assert wf.step()[2] and "jumped back" not in wf.reason
    wf.restart()
    wf.tracker.reset(site.object("parallelepiped").T_world_obj)
    wf.t_last = 20.0  # the last frame was at 20 s; the video restarts at 16 s
    assert wf.step()[2] and "the video jumped back in time" in wf.reason and "jumped back" in wf.next_step
