"""Calibrate camera: pick model corners in the overlay, click them in the video, DLT, accept."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import CalibrateCamera, Site, WorkflowError
from core.camera import Camera


def _wrong_camera(true_cam: Camera) -> Camera:
    """The true C shifted by a few pixels and slightly rescaled: what a stale calibration looks like."""
    H = np.array([[1.01, 0.0, 6.0], [0.0, 0.99, -4.0], [0.0, 0.0, 1.0]])
    return Camera(H @ true_cam.C, true_cam.width, true_cam.height)


def _visible_vertices(site, name):
    """Vertices of ``name`` on an edge the camera sees (convex hidden-line removal)."""
    obj = site.object(name)
    wf = obj.model.wireframe(site.camera.center, obj.T_world_obj)
    E = np.asarray(obj.model.edges)
    vis = [int(k) for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind) if v and kind == "edge"]
    return sorted({int(v) for v in E[vis].ravel()})


def _calibration_targets(site):
    """(object name, vertex index) pairs spread in 3D: the box's visible corners and the table's top corners."""
    table = site.object("table")
    top = np.argsort(table.vertices_world()[:, 2])[-4:]
    return [("parallelepiped", k) for k in _visible_vertices(site, "parallelepiped")] + [("table", int(k)) for k in top]


def test_a_click_picks_only_a_visible_corner(site):
    """A click nearer a hidden corner than a visible one picks the visible one (the hidden one cannot be seen)."""
    box = site.object("parallelepiped")
    V = box.vertices_world()
    visible = set(_visible_vertices(site, "parallelepiped"))
    hidden = [k for k in range(len(V)) if k not in visible]
    assert hidden
    cam = site.camera
    uv = cam.project(V)
    h, near = min(((h, k) for h in hidden for k in visible), key=lambda hk: np.linalg.norm(uv[hk[1]] - uv[hk[0]]))
    gap = np.linalg.norm(uv[near] - uv[h])
    assert gap < 40
    click = uv[h] + 0.4 * (uv[near] - uv[h])  # nearer the hidden corner than the visible one
    wf = CalibrateCamera(site, client="alice")
    wf.click_px_per_screen_px = gap / 10.0  # zoomed out: both corners within the pick's 12 screen pixels
    wf.click(click)
    assert wf.pending_vertex == ("parallelepiped", near)
    assert "circled" in wf.next_step


def test_click_pairs_solve_accept_updates_every_reader(site, scene, db):
    true_cam = scene.camera
    site.set_camera(_wrong_camera(true_cam), rms_px=0.0, residuals_px=np.zeros((0, 2)), points={}, client="test")
    wf = CalibrateCamera(site, client="alice")
    rng = np.random.default_rng(0)
    n_cal = len(db.calibrations("camera"))
    for name, k in _calibration_targets(site):
        X = site.object(name).vertices_world()[k]
        wf.click(site.camera.project(X) + rng.normal(0, 0.5, 2))  # the corner as drawn (wrong C)
        assert wf.state == "click_image" and name in wf.next_step
        wf.click(true_cam.project(X) + rng.normal(0, 0.5, 2))  # where it really is
    n = len(_calibration_targets(site))
    assert wf.summary()["pairs"] == n
    result = wf.solve()
    assert result.rms_px < 1.0
    assert len(wf.summary()["points"]) == n
    # the Point chooser lists the farthest off first after a Solve: Delete point's default (it deleted the best)
    listed = [i for _, i in wf.choices("pair")]
    assert sorted(listed) == list(range(n)) and listed[0] == int(np.argmax(result.errors_px))
    assert list(result.errors_px[listed]) == sorted(result.errors_px, reverse=True)
    assert len(db.calibrations("camera")) == n_cal  # nothing written before accept
    wf.accept()
    assert wf.accepted and len(db.calibrations("camera")) == n_cal + 1
    X = site.object("parallelepiped").vertices_world()
    assert np.max(np.linalg.norm(site.camera.project(X) - true_cam.project(X), axis=1)) < 1.5
    # another server on the same database starts with the new calibration
    other = Site(scene, db)
    assert np.allclose(other.camera.C, site.camera.C)


def test_too_few_or_coplanar_points_refuse_and_write_nothing(site, db):
    wf = CalibrateCamera(site)
    n_cal = len(db.calibrations())
    box = site.object("parallelepiped").vertices_world()
    for k in range(4):  # the bottom face: coplanar
        wf.choose_vertex("parallelepiped", k)
        wf.click(site.camera.project(box[k]))
    with pytest.raises(WorkflowError, match="at least 6"):
        wf.solve()
    table = site.object("table").vertices_world()
    for k in range(4):  # the table's bottom face: on z = -0.05, still two parallel planes... plus one more plane below
        wf.choose_point(table[k] * [1, 1, 0])  # z = 0: coplanar with the box's bottom
        wf.click(site.camera.project(table[k] * [1, 1, 0]))
    with pytest.raises(WorkflowError, match="coplanar"):
        wf.solve()
    with pytest.raises(WorkflowError, match="solve first"):
        wf.accept()
    assert len(db.calibrations()) == n_cal


def test_a_click_far_from_every_corner_is_refused(site):
    wf = CalibrateCamera(site)
    with pytest.raises(WorkflowError, match="No visible model corner within"):
        wf.click([2.0, 250.0])
    assert wf.state == "pick_model" and wf.pending_X is None
    with pytest.raises(WorkflowError, match="finite"):
        wf.click([np.nan, 3.0])


def test_remove_last_redo_and_marks(site):
    wf = CalibrateCamera(site)
    box = site.object("parallelepiped").vertices_world()
    wf.choose_vertex("parallelepiped", 0)
    assert wf.marks().pending.shape == (1, 2)
    wf.click([100.0, 100.0])
    wf.choose_vertex("parallelepiped", 1)
    wf.remove_last()  # drops the pending point
    assert wf.pending_X is None and len(wf.uv) == 1
    wf.remove_last()  # drops the pair
    assert len(wf.uv) == 0
    for k in range(7):
        wf.choose_vertex("parallelepiped", k if k < 6 else 6)
        wf.click(site.camera.project(box[k]))
    wf.solve()
    m = wf.marks()
    assert m.points.shape == (7, 2) and m.residuals.shape == (7, 2, 2) and len(m.labels) == 7
    wf.redo()
    assert wf.result is None and not wf.uv and wf.state == "pick_model"
    with pytest.raises(WorkflowError, match="vertices 0..7"):
        wf.choose_vertex("parallelepiped", 8)
    wf.cancel()
    with pytest.raises(WorkflowError, match="cancelled"):
        wf.click([1.0, 1.0])


def test_a_corner_is_picked_within_a_screen_pixel_radius(site):
    """A click 20 video px from the nearest visible corner picks no corner at the fitted view (1 video px per
    screen px here) or zoomed in, and picks it zoomed out (2.5 video px per screen px: 8 screen px away)."""
    from app.workflows import WorkflowError

    k = _visible_vertices(site, "parallelepiped")[0]
    uv = site.camera.project(site.object("parallelepiped").vertices_world()[k : k + 1])[0]
    for scale, picked in ((1.0, False), (0.5, False), (2.5, True)):
        wf = CalibrateCamera(site, client="alice")
        wf.click_px_per_screen_px = scale
        others = site.camera.project(np.vstack([o.vertices_world() for o in site.objects()]))
        for ang in np.linspace(0, 2 * np.pi, 36, endpoint=False):  # 20 px off, farther from every other corner
            p = uv + 20.0 * np.array([np.cos(ang), np.sin(ang)])
            if np.sort(np.linalg.norm(others - p, axis=1))[0] > 19.5:
                break
        if picked:
            wf.click(p)
            assert wf.pending_vertex == ("parallelepiped", k)
        else:
            with pytest.raises(WorkflowError, match="No visible model corner within"):
                wf.click(p)
