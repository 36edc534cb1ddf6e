"""Update pose from one click (issue 17): click once on the moved box, Find, Accept; the click on
nothing refused with nothing written; Remove last; clicked edges refine from the found pose."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import Session, WorkflowError
from core.transforms import pose_error

from .test_update_pose import T_MOVED, _true_segments, _visible_edges

BOX = "parallelepiped"


def _start(site):
    session = Session(site, client="alice")
    session.select(BOX)
    return session.start("update_pose")


def _on_box(site, scene):
    T = scene.body(BOX).pose_at(T_MOVED)
    return site.camera.project_obj(T, scene.body(BOX).model.vertices).mean(axis=0) + [4.0, 2.0], T


def test_one_click_find_accept_writes_the_true_pose_with_the_click(video_site, scene, db):
    site = video_site
    site.t["t"] = T_MOVED
    wf = _start(site)
    assert wf.next_step.startswith(f"Double-click {BOX} where it is now")
    uv, T_true = _on_box(site, scene)
    version = db.get(BOX).version
    wf.click(uv)
    st = wf.current_step()
    assert st.name == "click_edge_end" and "find" in st.enabled and wf.next_step.startswith("Find the pose")
    found = wf.find()
    st = wf.current_step()
    assert st.name == "found" and {"accept", "remove_last", "cancel"} <= st.enabled and wf.pending is None
    assert len(wf.marks().ghosts) == len(found) and wf.marks().circles.shape == (1, 2)
    deg, m = pose_error(found[0].T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005, (deg, m)
    assert wf.weaknesses() == []  # σ well under the thresholds
    assert wf.summary()["found"]["candidates"] == len(found)
    wf.accept()
    rec = db.get(BOX)
    assert rec.version == version + 1
    deg, m = pose_error(rec.T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005
    last = db.history(BOX)[-1]
    assert last.method == "search" and last.client == "alice"
    assert np.allclose(last.clicks["click_uv"], uv) and last.clicks["mode"] == "table"
    assert last.clicks["frame"] is None or "t_s" in last.clicks["frame"]


def test_a_click_on_the_table_finds_nothing_and_writes_nothing(video_site, scene, db):
    site = video_site
    site.t["t"] = T_MOVED
    wf = _start(site)
    n = len(db.history(BOX))
    wf.click(site.camera.project(np.array([[0.3, -0.3, 0.0]]))[0])
    with pytest.raises(WorkflowError, match=f"no pose of the {BOX} fits the image near your click"):
        wf.find()
    assert wf.current_step().name == "click_edge_end" and wf.found is None and wf.pending is not None  # state intact
    assert len(db.history(BOX)) == n
    with pytest.raises(WorkflowError, match="Find uses one click"):
        wf.find([10.0, 10.0])  # a click under way already


def test_remove_last_drops_the_found_poses_and_edges_refine_from_the_found_pose(video_site, scene, db):
    site = video_site
    site.t["t"] = T_MOVED
    wf = _start(site)
    uv, T_true = _on_box(site, scene)
    wf.click(uv)
    wf.find()
    wf.remove_last()  # the found poses go; the click stays, to Find again or go on with an edge
    assert wf.found is None and wf.current_step().name == "click_edge_end" and np.allclose(wf.pending, uv)
    wf.find()
    T_found = wf.candidates[0]
    obj = wf.obj
    edges = [k for k in _visible_edges(site, obj.model, T_true)
             if np.linalg.norm(np.diff(site.camera.project(obj.model.edge_segments(T_true)[k]), axis=0)) > 20][:3]
    for seg, k in zip(_true_segments(site, obj.model, T_true, edges, np.random.default_rng(2), 0.5), edges):
        wf.click(seg[0])
        wf.click(seg[1])
        # which model edge: its drawing at the found pose (the estimate the overlay assigns on)
        wf.click(site.camera.project(obj.model.edge_segments(T_found)[k]).mean(axis=0))
    assert wf.edge_ids == edges
    r = wf.refine()
    assert pose_error(r.T_world_obj, T_true)[0] < 1.0
    wf.accept()
    last = db.history(BOX)[-1]
    assert last.method == "search+refine" and last.clicks["search"]["mode"] == "table"
