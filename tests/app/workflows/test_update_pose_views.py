"""Update pose with clicks in two cameras (the workcell's front and side): each click belongs to the
camera it was made in, drawn there; Refine fits all of them at once; other workflows refuse a click in
another camera; clicks in a camera whose frame was not shown at the frozen frame's moment are refused."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import CalibrateCamera, UpdatePose, WorkflowError
from app.workflows.base import FrameRef
from core.transforms import pose_error
from tests.app.workflows.test_update_pose import _moved, _visible_edges


def _side_edges(site, model, T):
    """Edges the side camera sees well, a triple of three directions with no common vertex first."""
    import itertools

    cam = site.camera_of("side")
    wf = model.wireframe(cam.center, T)
    uv = cam.project(model.edge_segments(T).reshape(-1, 3)).reshape(-1, 2, 2)
    vis = [
        int(k)
        for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind)
        if v and kind == "edge" and np.linalg.norm(uv[k][1] - uv[k][0]) > 30
    ]
    d = {k: np.abs(np.diff(model.vertices[model.edges[k]], axis=0)[0]).argmax() for k in vis}
    for a, b, c in itertools.combinations(vis, 3):
        if len({d[a], d[b], d[c]}) == 3 and not set(model.edges[a]) & set(model.edges[b]) & set(model.edges[c]):
            return [a, b, c]
    return vis


def _click_edge_in(wf, view, camera, model, T_true, k, rng, sigma_px=0.5):
    a, b = camera.project(model.edge_segments(T_true)[k])
    for t in (0.3, 0.7):
        wf.click_in(view, a + t * (b - a) + rng.normal(0, sigma_px, 2))
    drawn = camera.project(model.edge_segments(wf.T_current)[k])
    wf.click_in(view, drawn.mean(axis=0))  # "this is model edge k", on the wireframe in that camera
    assert wf.edge_ids[-1] == k


def test_edges_clicked_in_both_cameras_are_refined_together(site):
    rng = np.random.default_rng(3)
    obj = site.object("parallelepiped")
    T_true = _moved(obj.T_world_obj, 4.0, 0.02, -0.01)
    wf = UpdatePose(site, object_name="parallelepiped", snap=False)
    front, side = site.camera_of("front"), site.camera_of("side")
    edges = _visible_edges(site, obj.model, T_true)[:3]
    for k in edges:
        _click_edge_in(wf, "front", front, obj.model, T_true, k, rng)
    side_edges = _side_edges(site, obj.model, T_true)  # a model edge may be clicked in both cameras
    for k in side_edges:
        _click_edge_in(wf, "side", side, obj.model, T_true, k, rng)
    assert wf.seg_views == ["front"] * 3 + ["side"] * 3
    # each camera's image shows the clicks made in it
    assert len(wf.marks_in("front").segments) == 3 and len(wf.marks_in("side").segments) == 3
    both = wf.refine()
    assert both.views == (0, 0, 0, 1, 1, 1) and "in cameras front, side" in wf.message
    # against the front camera's clicks alone (the side's removed), along its line of sight
    one = UpdatePose(site, object_name="parallelepiped", snap=False)
    for seg, k in zip(wf.segs[:3], edges):
        one.add_segment(seg, k)
    alone = one.refine()
    d = T_true[:3, 3] - front.center
    d /= np.linalg.norm(d)
    sd_one, sd_both = (float(np.sqrt(d @ r.cov[:3, :3] @ d)) for r in (alone, both))
    assert sd_both < sd_one / 3  # the second camera fixes the depth one camera sees worst
    deg, m = pose_error(both.T_world_obj, T_true)  # within the stated σ (3 edges a camera: the turn is weak)
    assert deg < 3 * float(np.max(both.std_r_deg)) and m < 3 * float(np.max(both.std_t_m))
    wf.accept()
    assert site.db.history("parallelepiped")[-1].clicks["views"] == ["front"] * 3 + ["side"] * 3


def test_other_workflows_take_clicks_in_their_own_camera_only(site):
    wf = CalibrateCamera(site, view="side")
    with pytest.raises(WorkflowError, match="works in camera side: show it"):
        wf.click_in("front", (100.0, 100.0))
    with pytest.raises(WorkflowError, match="no camera named 'top'"):
        CalibrateCamera(site, view="top")


def test_a_camera_whose_frame_is_not_of_the_frozen_moment_is_refused(site):
    image = np.zeros((256, 512, 3), np.uint8)
    late = FrameRef(image, 16.0, 5, "live", view="side", gap_s=2.4)
    wf = UpdatePose(site, object_name="parallelepiped", snap=False)
    wf.use_frame(FrameRef(image, 16.0, 3, "live", view="front", others={"side": late}))
    with pytest.raises(WorkflowError, match=r"camera side's frame nearest the frozen one arrived 2.4 s after it"):
        wf.click_in("side", (200.0, 100.0))
    assert not wf.segs and wf.pending is None  # nothing taken
