"""core.pose.PoseClicks: the operator's clicks per view and their assignment, as the click flow reads
them; the pipeline's view of them (in the clicks' order, whatever the view)."""

import numpy as np
import pytest

from core.brep import BRep
from core.pose import PoseClicks, Refused, refine, refine_views
from core.pose.synthetic import PAPER_BOX_M, paper_box_pose, paper_camera, side_camera

BOX = BRep.box(*PAPER_BOX_M)


def _setup(seed=0):
    rng = np.random.default_rng(seed)
    while True:
        T = paper_box_pose(rng)
        front, side = paper_camera(), side_camera()
        vis = [
            set(int(k) for k in wf.edge_index[wf.visible & (wf.edge_index >= 0)])
            for wf in (BOX.wireframe(front.center, T), BOX.wireframe(side.center, T))
        ]
        if len(vis[0] & vis[1]) >= 3:
            return T, front, side, sorted(vis[0]), sorted(vis[1])


def _on_edge(camera, T, k, f=(0.3, 0.7)):
    a, b = camera.project_obj(T, BOX.edge_segments()[k])
    return np.array([a + f[0] * (b - a), a + f[1] * (b - a)])


def _corner(edges) -> tuple[int, int, int]:
    """Three of ``edges`` (model edge indices) through one corner of the box."""
    return next(
        (i, j, k)
        for i in edges
        for j in edges
        for k in edges
        if len({i, j, k}) == 3 and set(BOX.edges[i]) & set(BOX.edges[j]) & set(BOX.edges[k])
    )


def test_the_click_flow_segment_then_its_model_edge_picked_on_the_projection():
    T, front, _, vis, _ = _setup()
    c = PoseClicks(BOX.edges, BOX.vertices, "the box")
    k = vis[0]
    seg = _on_edge(front, T, k)
    assert c.click(seg[0], "front", front, T, 25.0) == ("pending", None)
    kind, pair = c.click(seg[1], "front", front, T, 25.0)
    assert kind == "segment" and np.allclose(pair, seg) and c.pending is not None  # the caller adds it
    c.add_segment(pair, "front", 0.15)
    assert c.pending is None and c.waiting_for_edge() and c.edge_ids == [None]
    with pytest.raises(Refused, match="no edge of the box within 25 px"):
        c.click(np.array([-500.0, -500.0]), "front", front, T, 25.0)
    assert c.click(front.project_obj(T, BOX.edge_segments()[k]).mean(axis=0), "front", front, T, 25.0) == ("assign", k)
    assert c.edge_ids == [k] and not c.waiting_for_edge()
    c.add_segment(seg, "front", 1.0)
    with pytest.raises(Refused, match=f"model edge {k} is already assigned to segment 1"):
        c.assign(k)
    c.remove_last()  # the second segment
    assert c.edge_ids == [k] and len(c.segs) == 1
    c.mode = "point"
    v = int(BOX.edges[k][0])
    kind, vertex = c.click(front.project_obj(T, BOX.vertices[[v]])[0], "front", front, T, 25.0)
    assert (kind, vertex) == ("vertex", v) and c.click(np.zeros(2), "front", front, T, 25.0) == ("point", v)
    c.add_point(np.zeros(2), v, "front", 0.15)
    with pytest.raises(Refused, match=f"vertex {v} already has a clicked point"):
        c.check_vertex(v)
    assert c.rows() == [("segment", 0), ("point", 0)] and c.remove(0) == "Edge 1" and c.rows() == [("point", 0)]
    assert c.remove_last() == "point" and c.empty


def test_a_model_edge_clicked_in_two_views_is_two_measurements_and_a_split_click_is_refused():
    T, front, side, vis_f, vis_s = _setup(1)
    c = PoseClicks(BOX.edges, BOX.vertices)
    k = sorted(set(vis_f) & set(vis_s))[0]
    c.add_segment(_on_edge(front, T, k), "front", 1.0)
    c.assign(k)
    c.add_segment(_on_edge(side, T, k), "side", 1.0)
    c.assign(k)  # the same edge in another camera
    assert c.edge_ids == [k, k] and c.click_views() == (["front", "side"], [])
    c.pending, c.pending_view = np.zeros(2), "front"
    with pytest.raises(Refused, match="started in camera front"):
        c.check_view("side")


def test_view_clicks_give_the_pipeline_every_camera_in_the_clicks_order():
    """Edges clicked alternately in two cameras: refine_views' per-click arrays follow the click order,
    and the pose is the one refine finds from all of them."""
    T, front, side, vis_f, vis_s = _setup(2)
    c = PoseClicks(BOX.edges, BOX.vertices)
    for kf, ks in zip(vis_f[:3], vis_s[:3]):
        for cam, view, k in ((front, "front", kf), (side, "side", ks)):
            c.add_segment(_on_edge(cam, T, k), view, 0.5 if view == "front" else 1.0)
            c.assign(k)
    views, per_view = c.views_clicks({"front": front, "side": side}.__getitem__, "front")
    assert views == ["front", "side"] and [v.seg_index for v in per_view] == [[0, 2, 4], [1, 3, 5]]
    res = refine_views(per_view, T)
    assert res.views == (0, 1, 0, 1, 0, 1) and np.allclose(res.sigma_px, [0.5, 1.0] * 3)
    assert np.max(res.click_residuals_px) < 1e-6
    one = refine(front, T, **{k: v for k, v in c.refine_args().items()})  # every click through one camera: wrong
    assert one.rms_px > 1.0


def test_solve_clicks_need_three_edges_in_one_camera_and_one_corner_is_said():
    T, front, _, vis, _ = _setup(3)
    c = PoseClicks(BOX.edges, BOX.vertices)
    with pytest.raises(Refused, match="0 edges assigned; the three-line solver needs 3"):
        c.solve_clicks("front")
    ends = [set(BOX.edges[k].tolist()) for k in vis]
    corner = _corner(vis)
    assert ends
    for k in corner:
        c.add_segment(_on_edge(front, T, k), "front", 1.0)
        c.assign(k)
    assert c.one_corner() == [0, 1, 2]
    view, (segs, edges, pts, pobj) = c.solve_clicks("front")
    assert view == "front" and segs.shape == (3, 2, 2) and edges.shape == (3, 2, 3) and pts is None


def test_three_edges_at_one_corner_in_two_cameras_are_not_said_to_leave_the_distance_open():
    """Seen from two cameras the corner is triangulated: its distance is fixed (the panel had told a new
    operator the edges "meet at one corner" when the clicks were split between the cameras)."""
    T, front, side, vis, _ = _setup(3)
    corner = _corner(vis)
    c = PoseClicks(BOX.edges, BOX.vertices)
    for k, (view, cam) in zip(corner, (("front", front), ("front", front), ("side", side))):
        c.add_segment(_on_edge(cam, T, k), view, 1.0)
        c.assign(k)
    assert c.one_corner() is None
