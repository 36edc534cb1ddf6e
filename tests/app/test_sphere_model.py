"""A sphere, added to core as one primitive class (core.primitives.sphere), goes through the
application with no change there: cast by the renderer's caster, drawn on the overlay, sampled by
the tracker and the search, stored in the database, written as a mesh; refused by the .cao writer
(the format has no sphere), saying what to export instead."""

import numpy as np
import pytest

from app.db import Database
from app.models_io import cao_text, load_model, save_model
from app.overlay import project_wireframe
from app.render.raycast import LABEL_SOLID, SceneCaster
from app.vision.search import _ModelSamples, heading_period
from app.vision.track import sample_visible_edges
from core.brep import BRep, Sphere
from core.pose.synthetic import paper_camera
from core.transforms import make_T, random_rotation

BALL = Sphere([0.0, 0.0, 0.05], 0.05)  # resting on z = 0 in its own frame


def _ball_model() -> BRep:
    return BRep(np.zeros((0, 3)), np.zeros((0, 2)), (), (BALL,))


def _pose() -> np.ndarray:
    return make_T(random_rotation(np.random.default_rng(0)), [0.1, 0.45, 0.0])  # ~2 m before the camera


def _tangent_distance(cam, uv, centre_world):
    """Distance (N,) from the sphere's centre to the rays of pixels uv."""
    o, d = cam.rays(uv)
    w = centre_world - o
    return np.linalg.norm(w - (w @ d.T)[:, None] * d, axis=1)


def test_scene_caster_hits_the_sphere_where_it_is():
    T = _pose()
    box = BRep.box(0.2, 0.2, 0.2)
    bodies = [type("B", (), {"model": m})() for m in (_ball_model(), box)]
    centre = T[:3, :3] @ BALL.centre + T[:3, 3]
    sc = SceneCaster(bodies, [T, make_T(np.eye(3), [0.0, 2.0, 0.0])])
    o = centre + [0.0, -1.0, 0.0]
    d = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.04], [0.0, 1.0, 0.06]])  # the last passes above the ball
    h = sc.cast(o, d)
    assert h.body.tolist() == [0, 0, -1] and h.face[:2].tolist() == [LABEL_SOLID, LABEL_SOLID]
    assert h.t[0] == pytest.approx(1.0 - BALL.radius, abs=1e-12)
    X = o + h.t[:2, None] * d[:2]
    np.testing.assert_allclose(np.linalg.norm(X - centre, axis=1), BALL.radius, atol=1e-12)
    np.testing.assert_allclose(h.normal[:2], (X - centre) / BALL.radius, atol=1e-9)
    to_box = np.array([0.0, 2.0, 0.1]) - o
    assert sc.occluded(o, o + np.array([[0.0, 1.2, 0.0], [0.0, 0.5, 0.0]])).tolist() == [True, False]  # behind, before
    assert sc.cast(o, to_box[None], skip=(0,)).body[0] == 1


def test_overlay_draws_the_sphere_by_its_outline_through_C():
    cam, T = paper_camera(), _pose()
    pw = project_wireframe(cam, _ball_model(), T)
    assert len(pw.seg_uv) == 48 and pw.visible.all() and set(pw.kind) == {"silhouette"}
    centre = T[:3, :3] @ BALL.centre + T[:3, 3]
    # every drawn point's ray is tangent to the sphere
    np.testing.assert_allclose(_tangent_distance(cam, pw.seg_uv.reshape(-1, 2), centre), BALL.radius, atol=1e-9)


def test_tracker_and_search_sample_its_outline():
    cam, T = paper_camera(), _pose()
    model = _ball_model()
    s = sample_visible_edges(cam, model, T, step_px=3.0)
    centre = T[:3, :3] @ BALL.centre + T[:3, 3]
    r_px = 500.0 * BALL.radius / np.linalg.norm(centre - cam.center)
    assert len(s) >= int(2 * np.pi * r_px / 3.0) - 2  # every 3 px around the outline, not only its chords' middles
    assert np.all(s.chord >= 0) and len(np.unique(s.feature)) > 10
    sag = BALL.radius * (1.0 - np.cos(np.pi / 48))  # samples lie on the outline's 48 chords
    np.testing.assert_allclose(_tangent_distance(cam, s.uv, centre), BALL.radius - sag / 2, atol=sag / 2 + 1e-9)
    R, t = T[None, :3, :3], T[None, :3, 3]
    ((X, D, V),) = _ModelSamples(model, per_edge=3, n_rim=16).groups(R, t, cam.center)
    assert X.shape == (1, 16, 3) and V.all()
    np.testing.assert_allclose(_tangent_distance(cam, cam.project_obj(T, X[0]), centre), BALL.radius, atol=1e-9)
    assert heading_period(model, T[:3, :3], T[:3, :3] @ [0.0, 0.0, 1.0]) == 0.0  # a ball's heading is not seen


def test_database_stores_and_returns_the_sphere(tmp_path):
    db = Database.open(tmp_path / "site.sqlite", client="test")
    try:
        db.add_object("ball", "sphere", _ball_model(), _pose())
        assert db.get("ball").model == _ball_model()
    finally:
        db.close()


def test_written_as_a_mesh_refused_as_cao(tmp_path):
    with pytest.raises(ValueError, match=r"a \.cao model has no spheres.*export it as glTF or OBJ"):
        cao_text(_ball_model())
    save_model(_ball_model(), tmp_path / "ball.obj")
    mesh = load_model(tmp_path / "ball.obj")
    np.testing.assert_allclose(
        np.linalg.norm(mesh.vertices - BALL.centre, axis=1), BALL.radius, atol=1e-7
    )  # OBJ digits
    V, F = mesh.triangles()
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    assert area == pytest.approx(4 * np.pi * BALL.radius**2, rel=0.01)
