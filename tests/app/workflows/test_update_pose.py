"""Update pose: click image edges, assign model edges in the overlay, P3L, refine, accept."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from app.workflows import Session, UpdatePose, WorkflowError
from core.transforms import make_T, pose_error, rot_z


def _moved(T: np.ndarray, deg: float, dx_m: float, dy_m: float) -> np.ndarray:
    """T turned about its own vertical axis and shifted on the table."""
    return make_T(T[:3, :3] @ rot_z(np.radians(deg)), T[:3, 3] + [dx_m, dy_m, 0.0])


def _visible_edges(site, model, T):
    """Visible model edges, a well-conditioned P3L triple first: three directions, no common vertex."""
    wf = model.wireframe(site.camera.center, T)
    vis = [int(k) for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind) if v and kind == "edge"]
    d = {k: np.abs(np.diff(model.vertices[model.edges[k]], axis=0)[0]).argmax() for k in vis}
    for a, b, c in itertools.combinations(vis, 3):
        if len({d[a], d[b], d[c]}) == 3 and not set(model.edges[a]) & set(model.edges[b]) & set(model.edges[c]):
            return [a, b, c] + [k for k in vis if k not in (a, b, c)]
    return vis


def _operator_clicks(wf, site, T_true, edges, rng, sigma_px=0.5):
    """What an operator does: two clicks along each true image edge, then a click on that edge's
    drawing in the overlay (the object at its estimate in the workflow)."""
    model = wf.obj.model
    for k in edges:
        E = model.vertices[model.edges[k]]
        a, b = np.random.default_rng(k).uniform([0.15, 0.6], [0.4, 0.85])
        P = T_true[:3, :3] @ np.array([E[0] + a * (E[1] - E[0]), E[0] + b * (E[1] - E[0])]).T
        uv = site.camera.project(P.T + T_true[:3, 3])
        wf.click(uv[0] + rng.normal(0, sigma_px, 2))
        wf.click(uv[1] + rng.normal(0, sigma_px, 2))
        drawn = site.camera.project(wf.obj.model.edge_segments(wf.T_current)[k])
        wf.click(drawn.mean(axis=0))
        assert wf.edge_ids[-1] == k


def test_large_motion_p3l_candidates_refine_accept(site, db):
    obj = site.object("parallelepiped")
    T_true = _moved(obj.T_world_obj, 25.0, -0.06, 0.04)
    wf = UpdatePose(site, client="alice", object_name="parallelepiped")
    rng = np.random.default_rng(1)
    edges = _visible_edges(site, obj.model, T_true)
    assert len(edges) >= 6
    _operator_clicks(wf, site, T_true, edges[:3], rng)
    cands = wf.solve()
    assert 1 <= len(cands) <= 8 and wf.chosen == 0
    assert len(wf.marks().ghosts) == len(cands)
    best = min(range(len(cands)), key=lambda i: pose_error(cands[i], T_true)[0])
    assert pose_error(cands[best], T_true)[0] < 10.0  # P3L uses 3 noisy edges: a first estimate
    wf.choose_candidate(best)
    _operator_clicks(wf, site, T_true, edges[3:6], rng)  # assigned on the chosen ghost
    r = wf.refine()
    deg, m = pose_error(r.T_world_obj, T_true)
    # within 4 standard deviations of the pose the refinement reports (σ = 0.5 px clicks)
    assert deg < 4 * np.linalg.norm(r.std_r_deg) * 0.5 and m < 4 * np.linalg.norm(r.std_t_m) * 0.5
    assert r.rms_px < 1.5 and len(wf.summary()["clicks"]) == 6
    assert all(s > 0 for s in wf.summary()["std_t_mm"])
    assert db.get("parallelepiped").version == obj.version  # nothing written before accept
    rec = wf.accept()
    assert rec.version == obj.version + 1
    assert np.allclose(db.get("parallelepiped").T_world_obj, r.T_world_obj)
    last = db.history("parallelepiped")[-1]
    assert last.method == "p3l+refine" and last.client == "alice"
    assert len(last.clicks["segs_uv"]) == 6
    assert site.object("parallelepiped").version == rec.version  # every client's overlay redraws from it


def test_small_motion_refines_from_the_database_pose(site, db):
    obj = site.object("parallelepiped")
    T_true = _moved(obj.T_world_obj, 3.0, 0.01, -0.005)
    wf = UpdatePose(site, object_name="parallelepiped")
    edges = _visible_edges(site, obj.model, T_true)
    _operator_clicks(wf, site, T_true, edges[:5], np.random.default_rng(2))
    r = wf.refine()
    deg, m = pose_error(r.T_world_obj, T_true)
    assert deg < 4 * np.linalg.norm(r.std_r_deg) * 0.5 and m < 4 * np.linalg.norm(r.std_t_m) * 0.5
    assert deg < 3.0 and m < 0.03
    wf.accept()
    assert db.history("parallelepiped")[-1].method == "refine"


def test_conflict_writes_nothing_and_says_what_to_do(site, db):
    obj = site.object("parallelepiped")
    T_true = _moved(obj.T_world_obj, 3.0, 0.01, 0.0)
    wf = UpdatePose(site, object_name="parallelepiped")
    _operator_clicks(wf, site, T_true, _visible_edges(site, obj.model, T_true)[:5], np.random.default_rng(3))
    wf.refine()
    other = db.update_pose(obj.id, T_true, None, expected_version=obj.version, method="other", client="bob")
    with pytest.raises(WorkflowError, match="changed since you read it"):
        wf.accept()
    assert db.get("parallelepiped").version == other.version
    assert np.allclose(db.get("parallelepiped").T_world_obj, T_true)
    assert not wf.accepted


def test_degenerate_clicks_are_refused(site):
    obj = site.object("parallelepiped")
    wf = UpdatePose(site, object_name="parallelepiped")
    wf.click([100.0, 100.0])
    with pytest.raises(WorkflowError, match="apart"):
        wf.click([101.0, 100.5])
    wf.remove_last()
    # three model edges all parallel to x: no rotation can come from them
    E = obj.model.edges
    V = obj.model.vertices
    parallel_x = [k for k in range(len(E)) if abs(abs((V[E[k][1]] - V[E[k][0]])[0]) - 0.35) < 1e-9][:3]
    for i, k in enumerate(parallel_x):
        wf.add_segment([[50.0 + 30 * i, 60.0], [150.0 + 30 * i, 80.0 + 5 * i]], k)
    with pytest.raises(WorkflowError, match="no pose fits"):
        wf.solve()
    with pytest.raises(WorkflowError, match="already assigned"):
        wf.add_segment([[10.0, 10.0], [40.0, 12.0]], parallel_x[0])
    wf.remove_last()  # the unassigned segment of the refused add
    wf.remove_last()  # the third edge's assignment
    assert wf.edge_ids[-1] is None and wf.state == "assign_edge"
    with pytest.raises(WorkflowError, match="has edges 0..11"):
        wf.assign_edge(12)


def test_session_needs_a_selection_and_replays_script_actions(site):
    session = Session(site, client="script")
    with pytest.raises(WorkflowError, match="select an object first"):
        session.start("update_pose")
    session.select("parallelepiped")
    wf = session.start("update_pose")
    assert wf.object_name == "parallelepiped"
    session.run_action({"t": 1.0, "workflow": "update_pose", "action": "click", "uv": [120.0, 90.0]})
    assert wf.pending is not None
    with pytest.raises(WorkflowError, match="no action"):
        session.run_action({"workflow": "update_pose", "action": "explode"})
    with pytest.raises(WorkflowError, match="no workflow 'nope'"):
        session.start("nope")
    with pytest.raises(WorkflowError, match="no object named"):
        session.select("ghost")
