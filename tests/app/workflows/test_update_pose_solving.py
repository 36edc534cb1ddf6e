"""Update pose solves outside the workflow's lock (snapshot, compute, commit): the overlay can draw
while P3L, refinement or matching runs, and a result whose clicks changed meanwhile is not kept."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import app.vision.matching as matching
import app.workflows.update_pose as update_pose
from app.workflows import UpdatePose, WorkflowError
from tests.app.workflows.test_update_pose import _moved, _true_segments, _visible_edges


def _lock_is_free(wf) -> bool:
    """True when another thread can take the workflow's lock now (marks() would not wait)."""
    got = []

    def probe():
        ok = wf.lock.acquire(blocking=False)
        got.append(ok)
        if ok:
            wf.lock.release()

    t = threading.Thread(target=probe)
    t.start()
    t.join()
    return got[0]


def _workflow(site, assign=True):
    obj = site.object("parallelepiped")
    T_true = _moved(obj.T_world_obj, 3.0, 0.01, -0.005)
    edges = _visible_edges(site, obj.model, T_true)[:5]
    wf = UpdatePose(site, object_name="parallelepiped", snap=False)
    for seg, k in zip(_true_segments(site, obj.model, T_true, edges, np.random.default_rng(4), 0.3), edges):
        wf.add_segment(seg, k if assign else None)
    return wf


@pytest.mark.parametrize(
    "action, solver_module, solver",
    [("refine", update_pose, "refine_starts"), ("solve", update_pose, "p3l_candidates")],
)
def test_a_solve_runs_outside_the_lock_and_is_dropped_when_the_clicks_changed(
    site, monkeypatch, action, solver_module, solver
):
    wf = _workflow(site)
    real, seen = getattr(solver_module, solver), {"free": [], "calls": 0}

    def meddling(*args, **kwargs):
        seen["free"].append(_lock_is_free(wf))
        seen["calls"] += 1
        if seen["calls"] == 1:
            wf.remove_last()  # the operator removes a click while the solver runs
        return real(*args, **kwargs)

    monkeypatch.setattr(solver_module, solver, meddling)
    with pytest.raises(WorkflowError, match="the clicks changed while solving"):
        getattr(wf, action)()
    assert seen["free"] and all(seen["free"])
    assert wf.refined is None and wf.candidates == []  # nothing kept from the stale solve
    getattr(wf, action)()  # the clicks unchanged this time: kept
    assert (wf.refined is not None) if action == "refine" else (len(wf.candidates) >= 1 and wf.chosen == 0)


def test_auto_match_runs_outside_the_lock_and_is_dropped_when_the_clicks_changed(site, monkeypatch):
    wf = _workflow(site, assign=False)
    real, seen = matching.match_edges, {"free": [], "calls": 0}

    def meddling(*args, **kwargs):
        seen["free"].append(_lock_is_free(wf))
        seen["calls"] += 1
        if seen["calls"] == 1:
            wf.remove_last()
        return real(*args, **kwargs)

    monkeypatch.setattr(matching, "match_edges", meddling)
    with pytest.raises(WorkflowError, match="the clicks changed while solving: Auto match again"):
        wf.auto_match()
    assert seen["free"] == [True] and wf.matches is None and len(wf.segs) == 4
    assert wf.auto_match() and wf.state == "match"


def test_accept_refines_outside_the_lock(site, monkeypatch, db):
    wf = _workflow(site)
    real, free = update_pose.refine_starts, []
    monkeypatch.setattr(
        update_pose, "refine_starts", lambda *a, **k: (free.append(_lock_is_free(wf)), real(*a, **k))[1]
    )
    rec = wf.accept()
    assert free and all(free) and rec.version == db.get("parallelepiped").version and wf.accepted
