"""Clicks snapped to the image in the workflows, on the workcell's rendered video (known truth):
segments to edges (update pose, model object), points to corners (calibrate camera), the raw
click shown beside the snapped one, refusal, the history, and the frame providers of the site."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import CalibrateCamera, ModelObject, Session, Site, UpdatePose, WorkflowError
from app.workflows.snapping import SNAPPED_SEGMENT_SIGMA_PX
from core.transforms import pose_error

T_MOVED = 16.0  # the known box has moved (12 → 15 s) and stays there: the video shows it, the database does not


def line_distance(p_uv: np.ndarray, edge_uv: np.ndarray) -> np.ndarray:
    """Distances (pixels) of points (N, 2) to the line through a projected edge (2, 2)."""
    a, b = edge_uv
    n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
    return np.abs((np.asarray(p_uv).reshape(-1, 2) - a) @ n)


def visible_edges(cam, model, T, min_len_px=40.0):
    """(model edge, projected edge (2, 2)) of the visible straight edges at least min_len_px long."""
    wf = model.wireframe(cam.center, T)
    out = []
    for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind):
        if v and kind == "edge":
            uv = cam.project(model.edge_segments(T)[int(k)])
            if np.linalg.norm(uv[1] - uv[0]) >= min_len_px:
                out.append((int(k), uv))
    return out


def clicks_on(edge_uv, rng, sigma_px, at=(0.25, 0.75)):
    a, b = edge_uv
    return np.array([a + t * (b - a) for t in at]) + rng.normal(0, sigma_px, (2, 2))


def test_update_pose_snaps_clicked_edges_shows_raw_refuses_and_records(video_site, scene, db):
    site = video_site
    site.t["t"] = T_MOVED
    obj = site.object("parallelepiped")
    T_true = scene.body("parallelepiped").pose_at(T_MOVED)
    wf = UpdatePose(site, client="alice", object_name="parallelepiped")
    rng = np.random.default_rng(4)
    edges = visible_edges(site.camera, obj.model, T_true, min_len_px=20.0)
    assert len(edges) >= 5
    raw_err, snap_err = [], []
    for k, uv in edges:
        raw = clicks_on(uv, rng, 2.0)
        wf.add_segment(raw, k)
        snap = wf.seg_snaps[-1]
        assert snap is not None and np.array_equal(snap.raw, raw)
        if snap.applied:
            assert "snapped" in wf.message and np.array_equal(wf.segs[-1], snap.snapped)
            snap_err.append(line_distance(wf.segs[-1], uv).max())
            raw_err.append(line_distance(raw, uv).max())
        else:
            assert "kept as clicked" in wf.message and np.array_equal(wf.segs[-1], raw)
    assert len(snap_err) >= 4
    assert max(snap_err) <= 0.3 < np.mean(raw_err)  # the snapped clicks land on the true edges
    m = wf.marks()
    assert m.raw_segments.shape == (len(snap_err), 2, 2)  # each raw click drawn beside its snapped one
    assert sum("snapped" in text for _, text in m.labels) == len(snap_err)
    # refusal: the last segment goes back to its raw click, the overlay stops drawing it twice
    last = wf.seg_snaps[-1]
    assert last.applied
    wf.refuse_snap()
    assert np.array_equal(wf.segs[-1], last.raw) and last.refused and not last.applied
    assert wf.marks().raw_segments.shape == (len(snap_err) - 1, 2, 2)
    with pytest.raises(WorkflowError, match="already used as clicked"):
        wf.refuse_snap()
    # the history keeps raw and snapped pixels of every segment, and which one was used
    wf.solve()
    refined = wf.refine()
    # refine weighs each click by its precision: snapped ones at the snap's σ, the refused one raw
    applied = np.array([s.applied for s in wf.seg_snaps])
    np.testing.assert_allclose(refined.sigma_px, np.where(applied, SNAPPED_SEGMENT_SIGMA_PX, wf.sigma_px))
    deg, m_err = pose_error(refined.T_world_obj, T_true)
    assert (
        np.degrees(np.sqrt(refined.cov[3:, 3:].trace())) > deg / 3 and np.sqrt(refined.cov[:3, :3].trace()) > m_err / 3
    )
    rec = wf.accept()
    change = db.history("parallelepiped")[-1]
    assert change.method == "p3l+refine" and change.client == "alice" and rec.version == obj.version + 1
    snaps = change.clicks["snaps"]
    assert len(snaps) == len(edges)
    assert [s["snapped"] for s in snaps] == [s.applied for s in wf.seg_snaps]
    assert (
        snaps[-1]["refused"]
        and np.allclose(snaps[-1]["raw_uv"], last.raw)
        and np.allclose(snaps[-1]["snapped_uv"], last.snapped)
    )
    assert np.allclose(change.clicks["segs_uv"], np.array(wf.segs))


def test_snapping_off_and_without_frames_uses_clicks_as_clicked(video_site, site, scene):
    video_site.t["t"] = T_MOVED
    obj = video_site.object("parallelepiped")
    k, uv = visible_edges(video_site.camera, obj.model, scene.body("parallelepiped").pose_at(T_MOVED))[0]
    raw = clicks_on(uv, np.random.default_rng(0), 1.5)
    session = Session(video_site)
    session.select("parallelepiped")
    session.set_snap(False)
    wf = session.start("update_pose")
    assert wf.snap is False
    wf.add_segment(raw, k)
    assert wf.seg_snaps == [None] and np.array_equal(wf.segs[0], raw)
    with pytest.raises(WorkflowError, match="not snapped"):
        wf.refuse_snap()
    session.set_snap(True)  # from now on, in the workflow under way too
    wf.add_segment(
        clicks_on(
            visible_edges(video_site.camera, obj.model, scene.body("parallelepiped").pose_at(T_MOVED))[1][1],
            np.random.default_rng(1),
            1.5,
        ),
        visible_edges(video_site.camera, obj.model, scene.body("parallelepiped").pose_at(T_MOVED))[1][0],
    )
    assert wf.seg_snaps[-1] is not None
    # a site without frames never snaps (nothing to snap to)
    wf2 = UpdatePose(site, object_name="parallelepiped")
    wf2.add_segment(raw, k)
    assert wf2.seg_snaps == [None] and np.array_equal(wf2.segs[0], raw)


def test_calibrate_camera_snaps_corners_and_stores_raw_and_snapped(video_site, scene, db):
    site = video_site
    site.t["t"] = 1.0
    cam = scene.camera
    box = site.object("parallelepiped")
    V = box.vertices_world()
    wf = CalibrateCamera(site, client="alice")
    rng = np.random.default_rng(5)
    wfv = box.model.wireframe(cam.center, box.T_world_obj)
    seen = sorted(
        {
            int(v)
            for k, vis, kind in zip(wfv.edge_index, wfv.visible, wfv.kind)
            if vis and kind == "edge"
            for v in box.model.edges[int(k)]
        }
    )
    raw_err, snap_err = [], []
    for k in seen:
        wf.choose_vertex("parallelepiped", k)
        truth = cam.project(V[k])
        wf.click(truth + rng.normal(0, 1.0, 2))
        s = wf.snaps[-1]
        raw_err.append(np.linalg.norm(s.raw - truth))
        if s.applied:
            assert s.method == "edges" and len(s.lines_uv) >= 2
            snap_err.append(np.linalg.norm(wf.uv[-1] - truth))
    assert len(snap_err) >= len(seen) - 1 and len(seen) >= 6
    assert max(snap_err) < 0.3 < np.mean(raw_err)
    m = wf.marks()
    assert len(m.raw_points) == len(snap_err) and len(m.snap_lines) >= 2 * len(snap_err)
    table = site.object("table")
    for k in np.argsort(table.vertices_world()[:, 2])[-4:]:  # the table's top corners: another plane
        wf.choose_vertex("table", int(k))
        wf.click(cam.project(table.vertices_world()[int(k)]) + rng.normal(0, 1.0, 2))
    wf.refuse_snap()  # the last point, as clicked
    assert np.array_equal(wf.uv[-1], wf.snaps[-1].raw)
    wf.solve()
    wf.accept()
    data = db.latest_calibration("camera").data
    assert len(data["snaps"]) == len(wf.uv)
    assert data["snaps"][-1]["refused"] and data["snaps"][0]["snapped"]
    assert np.allclose(data["uv"][0], data["snaps"][0]["snapped_uv"])


def test_model_object_snaps_sides_and_silhouettes(video_site, scene):
    site = video_site
    site.t["t"] = 1.0
    cam = scene.camera
    body = scene.body("unknown_box")
    T = body.pose_at(1.0)
    wf = ModelObject(site, shape="box")
    edges = visible_edges(cam, body.model, T, min_len_px=25.0)
    rng = np.random.default_rng(6)
    for _, uv in edges[:2]:
        wf.add_segment(clicks_on(uv, rng, 1.5))
    snapped = [(s, uv) for s, (_, uv) in zip(wf.faces[-1]["snaps"], edges[:2]) if s.applied]
    assert snapped and all(line_distance(s.snapped, uv).max() <= 0.3 for s, uv in snapped)
    assert len(wf.marks().raw_segments) == len(snapped)
    wf.refuse_snap()
    assert np.array_equal(wf.faces[-1]["segs"][-1], wf.faces[-1]["snaps"][-1].raw)
    wf.remove_last()
    assert len(wf.faces[-1]["segs"]) == len(wf.faces[-1]["snaps"]) == 1
    # a cylinder's silhouettes: snapped onto the line, the clicked height kept
    cyl = scene.body("unknown_cylinder")
    Tc = cyl.pose_at(1.0)
    sil = cyl.model.solids[0].silhouette((cam.center - Tc[:3, 3]) @ Tc[:3, :3])
    wf2 = ModelObject(site, shape="cylinder")
    for g in sil:
        uv = cam.project(g @ Tc[:3, :3].T + Tc[:3, 3])
        raw = uv + rng.normal(0, 1.0, (2, 2))
        wf2.add_segment(raw)
        s = wf2.silhouette_snaps[-1]
        assert s.applied and line_distance(s.snapped, uv).max() < 0.5  # a shaded cylinder's edge lies a little inside
        along = (s.snapped - raw) @ ((uv[1] - uv[0]) / np.linalg.norm(uv[1] - uv[0]))
        assert np.all(np.abs(along) < 0.2)  # the ends move across the edge, not along it


def test_site_frames_follow_the_scene_clock(video_site, scene, db):
    import cv2

    video_site.t["t"] = 16.02
    k = scene.video.frame_index(16.02)
    cap = cv2.VideoCapture(str(scene.video.path))
    cap.set(cv2.CAP_PROP_POS_FRAMES, k)
    ok, bgr = cap.read()
    assert ok and np.array_equal(video_site.frame_at(), bgr[:, :, ::-1])
    assert not np.array_equal(video_site.frame_at(0.0), video_site.frame_at())
    assert Site(scene, db, frames=None).frame_at() is None
    still = np.full((256, 512), 7, np.uint8)
    s = Site(scene, db, frames=lambda t: still)
    assert s.has_frames and s.frame_at(3.0) is still
    s.set_frames(None)
    assert not s.has_frames
    with pytest.raises(ValueError, match="frames must be"):
        Site(scene, db, frames="video")
    with pytest.raises(ValueError, match="frames must be"):
        s.set_frames(42)


def test_update_pose_point_clicks_snap_to_the_vertex_corner(video_site, scene):
    site = video_site
    site.t["t"] = 2.0  # the box where the database has it
    obj = site.object("parallelepiped")
    wf = UpdatePose(site, object_name="parallelepiped")
    V = obj.vertices_world()
    front = int(np.argmin(site.camera.depth(V)))  # the nearest corner: three visible edges meet there
    truth = scene.camera.project(V[front])
    wf.start_point()
    wf.click(truth + [3.0, -2.0])  # the model vertex, on the overlay (not snapped: it is not an image click)
    assert wf.pending_vertex == front and not wf.point_snaps
    raw = truth + np.random.default_rng(2).normal(0, 1.0, 2)
    wf.click(raw)  # where it is in the video
    s = wf.point_snaps[-1]
    assert s.applied and s.kind == "corner" and s.method == "edges"
    assert np.linalg.norm(wf.points_uv[-1] - truth) < 0.3 < np.linalg.norm(raw - truth)
    assert len(wf.marks().raw_points) == 1 and "Point v" in wf.message
    wf.refuse_snap()
    assert np.array_equal(wf.points_uv[-1], raw) and len(wf.marks().raw_points) == 0


def test_a_snap_is_weak_for_a_poor_fit_where_it_landed_not_for_the_distance_it_moved():
    """A click snapped 2.6 px onto an edge its points fit within 0.05 px is not weak (a new operator's was
    flagged for the distance); one whose edge points scatter 0.6 px is, however little it moved."""
    from app.workflows.snapping import WEAK_EDGE_RMS_PX, ClickSnap, weak_snaps

    seg = np.array([[10.0, 10.0], [60.0, 10.0]])
    far_good = ClickSnap("segment", seg, seg + [0.0, 2.6], 2.6, "edge", fit_px=0.05)
    near_poor = ClickSnap("segment", seg, seg + [0.0, 0.4], 0.4, "edge", fit_px=2 * WEAK_EDGE_RMS_PX)
    corner = ClickSnap("corner", seg[0], seg[0] + 3.0, 4.2, "edges", fit_px=0.1)
    assert far_good.weak() == "" and corner.weak() == ""
    assert "scatter 0.60 px there (more than 0.3 px)" in near_poor.weak()
    assert weak_snaps([("edge 1", far_good), ("edge 2", near_poor), ("edge 3", None)]) == [
        f"edge 2's snap: {near_poor.weak()}"
    ]
    near_poor.refused = True  # the raw click in use: nothing to judge
    assert near_poor.weak() == ""
