"""BeamCaster: first hits against the true meshes, at the bodies' poses of the asked time."""

import numpy as np
import pytest

from app.render.raycast import BeamCaster
from app.scene import Body
from core.brep import BRep
from core.transforms import make_T, rot_z


def test_first_hit_is_the_nearest_face_at_the_analytic_distance(workcell):
    rc = BeamCaster(workcell)
    b = workcell.body("unknown_box")
    T = b.pose_at(0.0)
    normals = b.model.face_normals() @ T[:3, :3].T
    centroids = b.model.face_centroids() @ T[:3, :3].T + T[:3, 3]
    k = int(np.argmax(normals[:, 2]))  # the top face, seen from straight above
    origin = centroids[k] + np.array([0.0, 0.0, 0.8])
    dist, body = rc.cast(origin, [0.0, 0.0, -3.0], 0.0)
    assert body == "unknown_box" and dist == pytest.approx(0.8, abs=1e-9)
    depth = float(np.ptp(b.model.vertices[:, 2]))
    inside = centroids[k] - np.array([0.0, 0.0, 0.3 * depth])  # from inside, out through the top
    d_up, b_up = rc.cast(inside, [0.0, 0.0, 1.0], 0.0)
    assert b_up == "unknown_box" and d_up == pytest.approx(0.3 * depth, abs=1e-9)


def test_a_beam_into_the_sky_misses(workcell):
    top = max(float((b.pose_at(0.0) @ np.r_[b.model.bounds()[1], 1.0])[2]) for b in workcell.bodies)
    assert BeamCaster(workcell).cast([0.0, 0.0, top + 1.0], [0.0, 0.0, 1.0]) == (np.inf, None)


def test_moving_bodies_are_cast_at_the_asked_time():
    start = make_T(np.eye(3), [0.0, 0.0, 0.0])
    moving = Body(
        "crate", "box", "known", BRep.box(0.2, 0.2, 0.1), start, ((2.0, make_T(rot_z(0.3), [0.5, 0.0, 0.0])),)
    )
    rc = BeamCaster([moving])
    origin, down = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
    assert rc.cast(origin, down, 0.0) == (pytest.approx(0.9, abs=1e-9), "crate")
    assert rc.cast(origin, down, 5.0) == (np.inf, None)  # it has gone from under the beam
    halfway = rc.cast(origin + [0.25, 0.0, 0.0], down, 1.0)  # at t = 1 s its centre is at x = 0.25
    assert halfway == (pytest.approx(0.9, abs=1e-9), "crate")


def test_bad_beams_are_refused(workcell):
    rc = BeamCaster(workcell)
    with pytest.raises(ValueError, match="non-zero direction"):
        rc.cast([0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="no bodies"):
        BeamCaster([])


def _trimesh_intersectors(bodies) -> list:
    """Each body's tessellation in trimesh's ray intersector (the reference caster's, made once)."""
    import trimesh

    out = []
    for body in bodies:
        V, F = body.model.triangles()
        out.append(trimesh.ray.ray_triangle.RayMeshIntersector(trimesh.Trimesh(V, F, process=False)))
    return out


def _trimesh_first_hits(bodies, intersectors, origin, directions, t_s):
    """The ray caster the emulator used before (trimesh, per body, tessellated), the reference: for rays from
    ``origin`` along each of ``directions`` (N, 3), the first hit's distance (inf: none) and body name."""
    from core.transforms import invert_T

    D = np.asarray(directions, float)
    D = D / np.linalg.norm(D, axis=1, keepdims=True)
    best, hit = np.full(len(D), np.inf), [None] * len(D)
    for body, rmi in zip(bodies, intersectors):
        T = invert_T(body.pose_at(t_s))
        o_obj, d_obj = T[:3, :3] @ origin + T[:3, 3], D @ T[:3, :3].T
        loc, ray, _ = rmi.intersects_location(np.repeat(o_obj[None], len(D), axis=0), d_obj, multiple_hits=False)
        for k, p in zip(ray, loc):
            dist = float(np.linalg.norm(p - o_obj))
            if dist < best[k]:
                best[k], hit[k] = dist, body.name
    return best, hit


def test_same_hits_as_the_trimesh_caster_it_replaces(workcell):
    """Polyhedra (convex and not, moving, from outside and from inside) hit where the trimesh caster
    did; the cylinder is now exact, within the old tessellation's error of it."""
    ell = BRep.prism(np.array([[0, 0], [0.2, 0], [0.2, 0.1], [0.1, 0.1], [0.1, 0.2], [0, 0.2]]), 0.1)
    bodies = list(workcell.bodies) + [Body("ell", "box", "known", ell, make_T(rot_z(0.4), [0.3, 0.2, 0.9]), ())]
    rc = BeamCaster(bodies)
    intersectors = _trimesh_intersectors(bodies)
    rng = np.random.default_rng(7)
    origins = [workcell.turret.T_world_turret[:3, 3], np.array([0.3, 0.2, 1.5]), np.array([0.35, 0.25, 0.95])]
    origins += [
        (b.pose_at(0.0) @ np.r_[b.model.bounds().mean(axis=0), 1.0])[:3] for b in workcell.bodies
    ]  # inside each
    origins.append(
        (bodies[-1].pose_at(0.0) @ np.r_[0.05, 0.05, 0.05, 1.0])[:3]
    )  # inside the L (its box centre is on its notch)
    hits = same = cylinder = 0
    for origin in origins:
        D = rng.normal(size=(60, 3))
        refs = {t_s: _trimesh_first_hits(bodies, intersectors, origin, D, t_s) for t_s in (0.0, 3.0)}
        for k, d in enumerate(D):
            for t_s in (0.0, 3.0):
                ours, ref = rc.cast(origin, d, t_s), (refs[t_s][0][k], refs[t_s][1][k])
                assert np.isinf(ours[0]) == np.isinf(ref[0])
                if np.isinf(ref[0]):
                    continue
                hits += 1
                if "cylinder" in f"{ours[1]}{ref[1]}":
                    assert ours[0] == pytest.approx(ref[0], abs=5e-4)  # the old caster's tessellation error
                    cylinder += 1
                    continue
                assert ours[0] == pytest.approx(ref[0], abs=1e-9)  # a tie (a box on the table) may name either
                same += ours[1] == ref[1]
    assert hits > 500 and cylinder > 10 and same > 0.95 * (hits - cylinder)


def test_designation_casts_with_the_same_caster_and_finds_the_old_hits(workcell, tmp_path):
    """Site.raycast (designation) hits the database where the merged trimesh index it replaces did
    (polyhedra to 1e-9 m, the cylinder within the old tessellation's error), with outward normals."""
    import trimesh

    from app.db import Database, seed_from_scene
    from app.workflows import Site

    db = Database.open(tmp_path / "site.sqlite")
    try:
        seed_from_scene(db, workcell)
        site = Site(workcell, db, clock=lambda: 0.0, frames=None)
        objects = site.objects()
        meshes = []
        for obj in objects:
            V, F = obj.model.triangles()
            meshes.append(
                (obj.name, trimesh.Trimesh(V @ obj.T_world_obj[:3, :3].T + obj.T_world_obj[:3, 3], F, process=False))
            )
        rng = np.random.default_rng(3)
        uv = np.column_stack(
            [rng.uniform(0, workcell.camera.width - 1, 300), rng.uniform(0, workcell.camera.height - 1, 300)]
        )
        o, D = workcell.camera.rays(uv)
        hits = 0
        for d in D:
            ours = site.raycast(o, d)
            u = d / np.linalg.norm(d)
            ref = (np.inf, None)
            for name, mesh in meshes:
                loc, _, _ = mesh.ray.intersects_location(o[None], u[None], multiple_hits=True)
                ahead = (np.reshape(loc, (-1, 3)) - o) @ u
                if np.any(ahead > 0) and ahead[ahead > 0].min() < ref[0]:
                    ref = (float(ahead[ahead > 0].min()), name)
            assert (ours is None) == (ref[1] is None)
            if ours is None:
                continue
            hits += 1
            tol = 5e-4 if "cylinder" in f"{ours.name}{ref[1]}" else 1e-9
            assert ours.distance_m == pytest.approx(ref[0], abs=tol)
            np.testing.assert_allclose(ours.X_world, o + ours.distance_m * u, atol=1e-12)
            assert ours.normal @ u < 0 and abs(np.linalg.norm(ours.normal) - 1) < 1e-9
        assert hits > 100
        with pytest.raises(ValueError, match="non-zero direction"):
            site.raycast(o, [0.0, 0.0, 0.0])
    finally:
        db.close()
