"""Curved meshes drawn truthfully (issue 15, item 5): the overlay draws a mesh's silhouettes at the
current pose, the database overlay redraws them when the object moves, an import with nothing to
draw warns, and a mesh's .cao keeps its faces and reads back."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from app.models_io import MeshWarning, cao_text, read_cao, read_mesh
from app.overlay import PixelWorld, project_wireframe
from app.ui.db_overlay import DatabaseOverlay
from core.brep import BRep, Revolution
from core.mesh_features import brep_from_mesh
from core.transforms import make_T, rot_x, rot_z
from tests.app.workflows.conftest import db, scene, site  # noqa: F401

from .ui.test_db_overlay import FakeScene


def _mesh(m) -> BRep:
    return brep_from_mesh(m.vertices, m.faces)


def _line_distance(P, seg):
    """Distance (N,) from points (N, 2) to the infinite line through seg (2, 2)."""
    d = seg[1] - seg[0]
    n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
    return np.abs((P - seg[0]) @ n)


def _in_view(camera, depth=1.2):
    """A pose that puts an object's origin on the optical axis, ``depth`` metres in front."""
    return make_T(rot_z(0.4) @ rot_x(0.3), camera.center + depth * camera.optical_axis)


def _sphere_outline_uv(camera, centre_world, radius, n=2000):
    """The analytic outline of a sphere through the camera, as a closed polyline (n + 1, 2)."""
    q = camera.center - centre_world
    d = np.linalg.norm(q)
    u = q / d
    ctr = centre_world + radius**2 / d * u
    rad = radius * np.sqrt(1.0 - radius**2 / d**2)
    e1 = np.cross(u, [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    th = np.linspace(0.0, 2.0 * np.pi, n + 1)
    return camera.project(ctr + rad * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2))


def _to_polyline(P, Q):
    """Distance (N,) from points (N, 2) to the polyline Q (M, 2)."""
    a, d = Q[:-1][None], (Q[1:] - Q[:-1])[None]
    p = P[:, None]
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(a + t[..., None] * d - p, axis=-1).min(axis=1)


def test_the_overlay_draws_a_mesh_cylinders_side_lines_on_the_analytic_ones(site):
    cam = site.camera
    T = _in_view(cam)
    mesh = _mesh(trimesh.creation.cylinder(0.05, 0.2, sections=500))  # 2,000 triangles
    pw = project_wireframe(cam, mesh, T)
    sil = pw.seg_uv[pw.kind == "silhouette"]
    assert (
        len(sil) == 2
        and np.all(pw.visible[pw.kind == "silhouette"])
        and np.all(pw.edge_index[pw.kind == "silhouette"] == -1)
    )
    assert (pw.kind == "edge").sum() >= 900  # the rims (1,000 sides, a few hidden ones clipped or not)
    true = project_wireframe(
        cam, BRep(np.zeros((0, 3)), np.zeros((0, 2), int), (), (Revolution([0, 0, -0.1], [0, 0, 0.1], 0.05, 0.05),)), T
    )
    lines = true.seg_uv[true.kind == "silhouette"]
    assert len(lines) == 2
    for s in sil:
        assert min(_line_distance(s, t).max() for t in lines) <= 0.5


def test_the_database_overlay_draws_a_mesh_spheres_outline_and_follows_it_when_it_moves(site, db):
    cam = site.camera
    r = 0.08
    T = _in_view(cam)
    rec = db.add_object("ball", "mesh", _mesh(trimesh.creation.icosphere(4, r)), T, status="known", method="test")
    scene = FakeScene()
    overlay = DatabaseOverlay(scene, PixelWorld(cam.width, cam.height), z=-0.001, line_px=2.0)
    overlay.sync(cam, site.objects())
    lines, label = overlay.handles(rec.id)
    assert lines is not None and label is not None  # before: a sphere mesh drew nothing at all
    drawn = overlay._drawn[rec.id].seg_uv
    outline = _sphere_outline_uv(cam, T[:3, 3], r)
    assert len(drawn) > 50 and _to_polyline(drawn.reshape(-1, 2), outline).max() <= 0.5
    assert _to_polyline(outline, np.concatenate(list(drawn))).max() <= 0.5  # the whole outline, no gap
    # what viser receives is those segments in the pixel world
    pts = overlay.points_sent(rec.id).astype(float)
    assert np.allclose(pts[..., :2] / overlay.pixel_world.k, drawn, atol=1e-3)
    # a click on the outline selects the ball
    assert overlay.object_at(outline[100], radius_px=3.0) == "ball"
    # moved: only the ball is redrawn, and its outline is at the new pose
    obj = site.object("ball")
    T2 = obj.T_world_obj @ make_T(np.eye(3), [0.05, 0.02, 0.0])
    site.update_pose(obj, T2, None, method="test", client="test")
    scene.take()
    assert overlay.sync(cam, site.objects()) == 1 and overlay.redrawn == [rec.id]
    assert ("add", overlay.node_of(rec.id), "lines") in scene.take()
    drawn2 = overlay._drawn[rec.id].seg_uv
    outline2 = _sphere_outline_uv(cam, T2[:3, 3], r)
    assert _to_polyline(drawn2.reshape(-1, 2), outline2).max() <= 0.5
    assert _to_polyline(drawn2.reshape(-1, 2), outline).max() > 5.0  # it did move


def test_a_mesh_with_nothing_to_draw_warns_naming_the_file(tmp_path):
    flat = tmp_path / "twice.obj"  # one triangle given twice: no sharp edge, no outline
    flat.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 3\n")
    with pytest.warns(MeshWarning, match=rf"^{flat.resolve()}: this mesh gives nothing to draw"):
        read_mesh(flat)
    for name, m in (
        ("ball.obj", trimesh.creation.icosphere(3, 0.1)),
        ("pill.stl", trimesh.creation.capsule(0.2, 0.05)),
        ("can.ply", trimesh.creation.cylinder(0.05, 0.2)),
    ):
        m.export(str(tmp_path / name))
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a sphere, a capsule, a cylinder: drawn by their outlines
            model = read_mesh(tmp_path / name)
        assert len(model.faces)


@pytest.mark.parametrize(
    "name,mesh",
    [
        ("sphere", trimesh.creation.icosphere(3, 0.1)),
        ("cylinder", trimesh.creation.cylinder(0.05, 0.2, sections=64)),
        ("cone", trimesh.creation.cone(0.05, 0.2, sections=64)),
        ("capsule", trimesh.creation.capsule(0.2, 0.05, count=[16, 16])),
    ],
)
def test_a_meshs_cao_keeps_its_faces_and_reads_back(tmp_path, name, mesh):
    model = _mesh(mesh)
    text = cao_text(model)
    path = tmp_path / f"{name}.cao"
    path.write_text(text)
    back = read_cao(path)
    assert np.array_equal(back.vertices, model.vertices)
    assert back.faces == model.faces and len(back.faces) > 0
    # the sharp edges stay edges; a .cao face's sides are all edges, so the smooth sides become edges too
    sides = {(min(a, b), max(a, b)) for f in model.faces for a, b in zip(f, f[1:] + f[:1])}
    edges = {tuple(e) for e in back.edges.tolist()}
    assert {tuple(e) for e in model.edges.tolist()} <= edges and edges == sides | {
        tuple(e) for e in model.edges.tolist()
    }
    assert text.count("\n") == 1 + 2 + len(model.vertices) + 2 + 2 + 2 + len(model.faces) + 2 + 2  # no lines left over
