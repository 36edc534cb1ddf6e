"""Exact ray casting of B-Rep bodies: convex polyhedra, solids of revolution, other faced models."""

import numpy as np
import pytest

from app.render.raycast import LABEL_SOLID, BodyCaster, SceneCaster
from app.scene import default_scene_path, load_scene
from core.brep import BRep
from core.transforms import make_T, rot_z


def test_box_hits_at_the_analytic_distance_on_the_right_face():
    box = BRep.box(0.4, 0.2, 0.1)
    caster = BodyCaster(box)
    assert box.polyhedron.convex  # cast by its planes
    rng = np.random.default_rng(0)
    o = np.array([0.05, -1.0, 0.5])
    # points on the top face (z = 0.1) and on the −y face (y = −0.1)
    top = np.column_stack([rng.uniform(-0.19, 0.19, 50), rng.uniform(-0.09, 0.09, 50), np.full(50, 0.1)])
    front = np.column_stack([rng.uniform(-0.19, 0.19, 50), np.full(50, -0.1), rng.uniform(0.01, 0.09, 50)])
    for P, face, normal in ((top, 1, [0, 0, 1]), (front, 2, [0, -1, 0])):
        d = (P - o) * rng.uniform(0.5, 2.0, (len(P), 1))  # any length: t scales accordingly
        t, f, n = caster.cast(o, d)
        np.testing.assert_allclose(o + t[:, None] * d, P, atol=1e-12)
        assert np.all(f == face)
        np.testing.assert_allclose(n, np.tile(normal, (len(P), 1)), atol=1e-12)
    t, f, _ = caster.cast(o, np.array([[0.0, 1.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]))  # over, away, beside
    assert np.all(np.isinf(t)) and np.all(f == -1)


def test_cylinder_and_cone_hits_lie_on_the_surface_and_are_the_first():
    rng = np.random.default_rng(1)
    for model in (BRep.cylinder(0.05, 0.2), BRep.cone(0.08, 0.03, 0.15)):
        s = model.solids[0]
        caster = BodyCaster(model)
        o = np.array([0.3, -0.9, 0.4])
        d = np.column_stack([rng.uniform(-0.1, 0.1, 400), rng.uniform(-0.1, 0.1, 400), rng.uniform(-0.1, 0.2, 400)]) - o
        t, f, n = caster.cast(o, d)
        hit = np.isfinite(t)
        assert 50 < hit.sum() < 400
        X = o + t[hit, None] * d[hit]
        lateral = f[hit] == LABEL_SOLID
        r_at = s.r0 + (s.r1 - s.r0) * X[:, 2] / s.height
        np.testing.assert_allclose(np.hypot(X[lateral, 0], X[lateral, 1]), r_at[lateral], atol=1e-12)
        top = f[hit] == LABEL_SOLID + 2
        np.testing.assert_allclose(X[top, 2], s.height, atol=1e-12)
        assert np.all(np.hypot(X[top, 0], X[top, 1]) <= s.r1 + 1e-12)
        # nothing of the solid lies on the ray before the hit
        for k in np.flatnonzero(hit)[:40]:
            for a in np.linspace(0.0, t[k] * (1 - 1e-6), 200)[1:]:
                Y = o + a * d[k]
                inside = 0 <= Y[2] <= s.height and np.hypot(Y[0], Y[1]) < s.r0 + (s.r1 - s.r0) * Y[2] / s.height - 1e-9
                assert not inside
        # outward unit normals
        np.testing.assert_allclose(np.linalg.norm(n[hit], axis=1), 1.0, atol=1e-12)
        assert np.all(np.einsum("ij,ij->i", n[hit], d[hit]) < 0)


def test_non_convex_model_is_cast_by_its_triangles():
    # An L-shaped prism: the notch must not be filled in.
    L = BRep.prism(np.array([[0, 0], [0.2, 0], [0.2, 0.1], [0.1, 0.1], [0.1, 0.2], [0, 0.2]]), 0.1)
    caster = BodyCaster(L)
    assert not L.polyhedron.convex  # cast by its triangles
    o = np.array([0.15, 0.15, 1.0])  # above the notch: falls through to nothing
    t, f, _ = caster.cast(o, np.array([[0.0, 0.0, -1.0], [-0.1, -0.1, -1.0]]))
    assert np.isinf(t[0])
    np.testing.assert_allclose(t[1], 0.9, atol=1e-12)  # lands on the top face at (0.05, 0.05, 0.1)
    assert f[1] == 1  # the top face (face 1 of prism)


def test_scene_caster_depth_occlusion_and_skip():
    bodies = [type("B", (), {"model": BRep.box(0.2, 0.2, 0.2)})() for _ in range(2)]
    poses = [make_T(np.eye(3), [0, 0, 0]), make_T(rot_z(0.3), [0, 1.0, 0])]
    sc = SceneCaster(bodies, poses)
    o = np.array([0.0, -2.0, 0.1])
    h = sc.cast(o, np.array([[0.0, 1.0, 0.0]]))
    assert h.body[0] == 0 and abs(h.t[0] - 1.9) < 1e-12
    np.testing.assert_allclose(h.normal[0], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(h.X_obj[0], [0, -0.1, 0.1], atol=1e-12)
    h = sc.cast(o, np.array([[0.0, 1.0, 0.0]]), skip=(0,))
    assert h.body[0] == 1
    X_behind = np.array([[0.0, 1.0, 0.1]])  # inside body 1, behind body 0
    assert sc.occluded(o, X_behind, body=1)[0]
    assert not sc.occluded(o, np.array([[0.0, -0.1, 0.1]]), body=0)[0]  # on body 0's near face


def test_agrees_with_trimesh_on_the_workcell():
    trimesh = pytest.importorskip("trimesh")
    scene = load_scene(default_scene_path())
    sc = SceneCaster.for_scene(scene, 0.0)
    rng = np.random.default_rng(2)
    uv = np.column_stack([rng.uniform(0, 511, 1500), rng.uniform(0, 255, 1500)])
    o, d = scene.camera.rays(uv)
    ours = sc.cast(o, d)
    best = np.full(len(d), np.inf)
    for _name, V, F in scene.truth_meshes(0.0):
        mesh = trimesh.Trimesh(V, F, process=False)
        loc, ray_idx, _ = trimesh.ray.ray_triangle.RayMeshIntersector(mesh).intersects_location(
            np.tile(o, (len(d), 1)), d, multiple_hits=False
        )
        dist = np.linalg.norm(loc - o, axis=1)
        best[ray_idx] = np.minimum(best[ray_idx], dist)
    cyl = ours.body == [b.name for b in scene.bodies].index("unknown_cylinder")
    poly = np.isfinite(best) & ~cyl
    np.testing.assert_allclose(ours.t[poly], best[poly], atol=1e-9)  # polyhedra: exact both ways
    # the cylinder: trimesh meets its 48-sided tessellation, at most r (1 − cos(π/48)) / cos(incidence) away
    assert np.all(np.abs(ours.t[cyl] - best[cyl]) < 2e-3)
    assert np.array_equal(np.isfinite(ours.t), np.isfinite(best))
