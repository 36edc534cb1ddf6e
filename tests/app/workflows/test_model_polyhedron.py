"""Model polyhedron: a wedge and a pyramid on the workcell's table, from clicked sides and the emulated
range finder/turret (their real serial protocols), against the scene's truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from app.db import Database, seed_from_scene
from app.scene import Appearance, Body
from app.workflows import ModelPolyhedron, Site, WorkflowError
from app.workflows.model_polyhedron import POLY_SHAPES
from core.brep import BRep
from core.transforms import make_T, rot_z

from .conftest import FAST_DEVICES
from .test_steps import Walk

WEDGE = (0.18, 0.13, 0.09)  # length (x), depth (y), height (m)


def wedge_brep(L, W, H) -> BRep:
    """The workflow's wedge topology at these dimensions (frame at the bottom's centre)."""
    V = np.array([[0, 0, 0], [L, 0, 0], [L, W, 0], [0, W, 0], [L, W, H], [0, W, H]], float) - [L / 2, W / 2, 0]
    return BRep.from_faces(V, POLY_SHAPES["wedge"].faces)


def pyramid_brep(a, h) -> BRep:
    return BRep.pyramid(np.array([[-a, -a], [a, -a], [a, a], [-a, a]]), np.array([0.0, 0.0, h]))


def _variant(fast_scene, name, model, xy, yaw_deg):
    body = Body(
        name,
        "polyhedron",
        "unknown",
        model,
        make_T(rot_z(np.radians(yaw_deg)), [xy[0], xy[1], 0.0]),
        (),
        Appearance(albedo=0.7, texture=0.02, texture_scale_m=0.03),
    )
    return dataclasses.replace(fast_scene, bodies=fast_scene.bodies + (body,))


@pytest.fixture
def poly_site(request, fast_scene, tmp_path):
    """A device site on the workcell with one extra unknown polyhedron (request.param: (name, model, xy, yaw))."""
    from app.devices import open_devices

    scene = _variant(fast_scene, *request.param)
    db = Database.open(tmp_path / "site.sqlite")
    seed_from_scene(db, scene)
    devs = open_devices(scene, clock=lambda: 0.0, site_options=FAST_DEVICES)
    site = Site(scene, db, devices=devs, clock=lambda: 0.0, frames=None)
    site.body = scene.body(request.param[0])
    yield site
    devs.close()
    db.close()


def _facing(cam, model, T):
    normals, cents = model.face_normals(), model.face_centroids()
    c_obj = (cam.center - T[:3, 3]) @ T[:3, :3]
    return [
        k for k in range(len(model.faces)) if normals[k] @ (c_obj - cents[k]) > 1e-3 * np.linalg.norm(c_obj - cents[k])
    ]


def _click_sides(wf, cam, model, T, k, rng, order=None, walk=None):
    f = model.faces[k]
    sides = list(zip(f, f[1:] + f[:1]))
    for i in order if order is not None else range(len(sides)):
        a, b = sides[i]
        uv = cam.project(model.vertices[[a, b]] @ T[:3, :3].T + T[:3, 3])
        wf.click(uv[0] + 0.2 * (uv[1] - uv[0]) + rng.normal(0, 0.5, 2))
        if walk is not None:
            walk.check(wf)
        wf.click(uv[0] + 0.8 * (uv[1] - uv[0]) + rng.normal(0, 0.5, 2))
        if walk is not None:
            walk.check(wf)


def _check(r, model, named, tol_m=0.006, sigma_max_m=0.01):
    for name, (i, j) in named.items():
        true = float(np.linalg.norm(model.vertices[i] - model.vertices[j]))
        assert abs(r.dimensions[name] - true) < max(tol_m, 3 * r.sigmas[name]), (name, r.dimensions[name], true)
        assert 0 < r.sigmas[name] < sigma_max_m
    H = model.vertices[:, 2].max()
    assert abs(r.dimensions["height"] - H) < max(tol_m, 3 * r.sigmas["height"])


WEDGE_CASE = ("ramp", wedge_brep(*WEDGE), (-0.03, -0.2), 35.0)


@pytest.mark.parametrize("poly_site", [WEDGE_CASE], indirect=True)
def test_wedge_from_its_visible_faces_is_added(poly_site):
    site = poly_site
    body = site.body
    T = body.pose_at(0.0)
    cam = site.camera
    wf = ModelPolyhedron(site, client="alice", shape="wedge")
    assert wf.object_name == "wedge_1"
    walk = Walk()  # every state's instruction names only enabled, existing controls
    st = walk.check(wf)
    assert st.name == "click_sides" and "solve" not in st.enabled
    with pytest.raises(WorkflowError, match="measure at least one face"):
        wf.solve()
    faces = _facing(cam, body.model, T)
    assert sorted(faces) == [1, 3]  # the slope and the left end face the camera
    rng = np.random.default_rng(0)
    # Sides in scrambled orders: the workflow finds which edge each is.
    for k, order in zip(faces, ([2, 0, 3, 1], [1, 2, 0])):
        _click_sides(wf, cam, body.model, T, k, rng, order, walk)
        assert walk.check(wf).name == "sides_clicked"
        wf.measure()
        assert wf.faces[-1]["points"].shape[0] >= 10
        assert walk.check(wf).name == "face_measured"
    r = wf.solve()
    assert walk.check(wf).name == "review"
    assert r.kind == "polyhedron"
    assert [a["face"] for a in wf.assignment] == faces
    true_edges = [[tuple(sorted(s)) for s in zip(f, f[1:] + f[:1])] for f in (body.model.faces[k] for k in faces)]
    assert [a["edges"] for a in wf.assignment] == [
        [e[i] for i in o] for e, o in zip(true_edges, ([2, 0, 3, 1], [1, 2, 0]))
    ]
    _check(r, body.model, POLY_SHAPES["wedge"].named)
    assert np.abs(r.vertices_world - body.model.transformed(T).vertices).max() < 0.01
    assert "length" in wf.next_step and "±" in wf.next_step and len(wf.marks().ghosts) == 1
    assert "wedge_1" not in [o.name for o in site.db.objects()]  # nothing written before Accept
    rec = wf.accept()
    walk.check(wf)
    assert walk.seen["model_polyhedron"] == {
        "click_sides",
        "click_end",
        "sides_clicked",
        "face_measured",
        "review",
        "accepted",
    }
    assert rec.status == "modelled" and rec.kind == "polyhedron"
    got = site.db.get("wedge_1")
    assert got.dims["length"] == pytest.approx(r.dimensions["length"]) and got.sigmas["height"] > 0
    h = site.db.history("wedge_1")[-1]
    assert h.clicks["shape"] == "wedge" and len(h.clicks["assignment"]) == 2 and len(h.measurements["faces"]) == 2
    print(f"\nwedge: {wf._dimension_text(r)}")


@pytest.mark.parametrize("poly_site", [WEDGE_CASE], indirect=True)
def test_wedge_from_the_slope_alone_is_completed_by_its_hints_and_weak(poly_site):
    site = poly_site
    body = site.body
    T = body.pose_at(0.0)
    wf = ModelPolyhedron(site, shape="wedge")
    _click_sides(wf, site.camera, body.model, T, 1, np.random.default_rng(1))
    wf.measure()
    r = wf.solve()
    _check(r, body.model, POLY_SHAPES["wedge"].named, tol_m=0.01)
    assert any("one face measured" in w for w in wf.weaknesses())


@pytest.mark.parametrize("poly_site", [("spire", pyramid_brep(0.07, 0.08), (-0.03, -0.2), 10.0)], indirect=True)
def test_pyramid_from_its_visible_faces(poly_site):
    site = poly_site
    body = site.body
    T = body.pose_at(0.0)
    cam = site.camera
    wf = ModelPolyhedron(site, shape="pyramid")
    faces = _facing(cam, body.model, T)
    assert 0 not in faces and len(faces) == 3
    rng = np.random.default_rng(2)
    for k in faces:
        _click_sides(wf, cam, body.model, T, k, rng)
        wf.measure()
    r = wf.solve()
    # The square pyramid's quarter turns give the same model: compare what does not depend on the numbering.
    # Its sides are seen obliquely here (the faces' planes cross at grazing angles): σ up to 1.5 cm.
    _check(r, body.model, POLY_SHAPES["pyramid"].named, sigma_max_m=0.02)
    Xt = body.model.transformed(T).vertices
    assert max(np.min(np.linalg.norm(Xt - x, axis=1)) for x in r.vertices_world) < 0.01
    wf.accept()
    assert site.db.get("pyramid_1").kind == "polyhedron"


@pytest.mark.parametrize("poly_site", [("spire", pyramid_brep(0.07, 0.08), (-0.03, -0.2), 45.0)], indirect=True)
def test_pyramid_showing_two_faces_says_its_back_corner_is_not_fixed(poly_site):
    site = poly_site
    body = site.body
    T = body.pose_at(0.0)
    wf = ModelPolyhedron(site, shape="pyramid")
    faces = _facing(site.camera, body.model, T)
    assert len(faces) == 2
    for k in faces:
        _click_sides(wf, site.camera, body.model, T, k, np.random.default_rng(6))
        wf.measure()
    with pytest.raises(WorkflowError, match="do not fix every corner of the pyramid"):
        wf.solve()
    assert wf.result is None and wf.current_step().name == "face_measured"


@pytest.mark.parametrize("poly_site", [WEDGE_CASE], indirect=True)
def test_error_paths_write_nothing(poly_site):
    site = poly_site
    body = site.body
    T = body.pose_at(0.0)
    cam = site.camera
    with pytest.raises(WorkflowError, match="one of wedge, pyramid"):
        ModelPolyhedron(site, shape="prism")
    with pytest.raises(WorkflowError, match="Lies on the table"):
        ModelPolyhedron(site, shape="wedge", on_table=False)
    wf = ModelPolyhedron(site, shape="wedge")
    with pytest.raises(WorkflowError, match="at least 2 sides"):
        wf.measure()
    # The slope measured as a pyramid's side: the shape does not fit what the faces show.
    pyr = ModelPolyhedron(site, shape="pyramid")
    _click_sides(pyr, cam, body.model, T, 3, np.random.default_rng(3))  # the wedge's vertical end
    pyr.measure()
    with pytest.raises(WorkflowError, match="do not fit a pyramid"):
        pyr.solve()
    # A side clicked far from every edge of its face.
    rng = np.random.default_rng(4)
    _click_sides(wf, cam, body.model, T, 1, rng)
    wf.measure()
    wf.remove_last()  # the measurement goes, the sides stay
    assert wf.faces[-1]["points"] is None and len(wf.faces[-1]["segs"]) == 4
    wf.remove_last()
    c = cam.project(body.model.transformed(T).face_centroids()[1:2])[0]
    wf.click(c + [-8, 0])
    wf.click(c + [8, 0])  # across the middle of the slope
    wf.measure()
    with pytest.raises(WorkflowError, match="px from every side"):
        wf.solve()
    assert wf.result is None and site.db.objects() and "wedge_1" not in [o.name for o in site.db.objects()]
    with pytest.raises(WorkflowError, match="Solve first"):
        wf.accept()
