"""The primitive protocol (core.primitives): every primitive answers the same questions, and a
sphere — added as one class — is cast, drawn, sampled, tessellated and stored like the others."""

import numpy as np
import pytest

from core.brep import BRep
from core.primitives import KINDS, Circle, Polyhedron, Primitive, Revolution, Sphere, primitive_from_dict
from core.transforms import make_T, random_rotation


def _primitives():
    rng = np.random.default_rng(0)
    T = make_T(random_rotation(rng), rng.normal(size=3) * 0.1)
    box = BRep.box(0.3, 0.2, 0.1).polyhedron
    L = BRep.prism(np.array([[0, 0], [0.2, 0], [0.2, 0.1], [0.1, 0.1], [0.1, 0.2], [0, 0.2]]), 0.1).polyhedron
    return {
        "box": box.transformed(T),
        "L prism": L.transformed(T),
        "cylinder": Revolution([0.1, 0, 0], [0.1, 0.05, 0.2], 0.05, 0.05),
        "frustum": Revolution([0, 0, 0], [0.05, -0.03, 0.15], 0.08, 0.03),
        "cone": Revolution([0, 0, 0], [0, 0, 0.12], 0.06, 0.0),
        "circle": Circle([0.1, -0.2, 0.3], [0.3, 0.2, 1.0], 0.05),
        "sphere": Sphere([0.05, -0.02, 0.1], 0.07),
    }


@pytest.mark.parametrize("name", list(_primitives()))
def test_every_primitive_is_a_primitive_and_round_trips(name):
    p = _primitives()[name]
    assert isinstance(p, Primitive) and KINDS[p.kind] is type(p)
    d = p.to_dict()
    again = type(p).from_dict(d) if isinstance(p, Polyhedron) else primitive_from_dict(d, p.kind)
    assert again == p and again is not p
    assert p != Sphere([9.0, 9.0, 9.0], 1.0) or name == "sphere"


@pytest.mark.parametrize("name", [n for n, p in _primitives().items() if p.surface])
def test_ray_casts_agree_with_the_tessellated_surface(name):
    """Each primitive's exact cast against a ray cast of its own fine tessellation: the same rays hit,
    at the same place to within the tessellation's sag, with outward normals."""
    p = _primitives()[name]
    V, F = p.triangles(128)
    mesh = Polyhedron(V, np.zeros((0, 2)), tuple(map(tuple, F)))
    rng = np.random.default_rng(1)
    lo, hi = p.bounds()
    o = 0.5 * (lo + hi) + np.array([0.6, -0.8, 0.5])
    d = rng.uniform(lo - 0.02, hi + 0.02, (400, 3)) - o
    t, label, n = p.ray_cast(o, d)
    t_m, _, _ = mesh._cast_triangles(o, d)
    hit = np.isfinite(t)
    assert 40 < hit.sum() < 400
    sure = np.abs(np.isfinite(t_m).astype(int) - hit) == 0
    assert sure.mean() > 0.97  # rays grazing the surface may differ
    both = hit & np.isfinite(t_m)
    size = float(np.linalg.norm(hi - lo))
    assert np.max(np.abs(t[both] - t_m[both]) * np.linalg.norm(d[both], axis=1)) < 2e-3 * size
    assert np.all((label[hit] >= 0) & (label[hit] < p.n_labels)) and np.all(label[~hit] == -1)
    np.testing.assert_allclose(np.linalg.norm(n[hit], axis=1), 1.0, atol=1e-9)
    assert np.all(np.einsum("ij,ij->i", n[hit], d[hit]) < 0)  # met from outside: against the ray


@pytest.mark.parametrize("name", list(_primitives()))
def test_outline_features_are_stable_ids_and_curves_are_chains(name):
    p = _primitives()[name]
    rng = np.random.default_rng(2)
    for _ in range(5):
        c = rng.normal(size=3) * 2.0
        o = p.outline(c, n_circle=24)
        K = len(o.segments)
        assert o.segments.shape == (K, 2, 3) and o.visible.shape == o.kind.shape == o.chord.shape == (K,)
        assert np.all((o.feature >= 0) & (o.feature < o.n_features)) and len(set(o.feature)) == K
        curved = o.chord >= 0
        # a curve's chords have consecutive features from feature − chord, and join end to end
        first = o.feature[curved] - o.chord[curved]
        for f0 in np.unique(first):
            sel = np.flatnonzero(curved & (o.feature - o.chord == f0))
            assert np.array_equal(o.chord[sel], np.arange(len(sel)))
            np.testing.assert_allclose(o.segments[sel[1:], 0], o.segments[sel[:-1], 1], atol=1e-12)


@pytest.mark.parametrize("name", list(_primitives()))
def test_bounds_are_exact(name):
    p = _primitives()[name]
    dense = np.vstack([p.support_points(512), p.triangles(64)[0]]) if p.surface else p.support_points(512)
    lo, hi = p.bounds()
    assert np.all(dense >= lo - 1e-12) and np.all(dense <= hi + 1e-12)
    np.testing.assert_allclose(dense.min(axis=0), lo, atol=5e-6)
    np.testing.assert_allclose(dense.max(axis=0), hi, atol=5e-6)


def test_sphere_ray_cast_is_the_analytic_hit():
    s = Sphere([0.1, -0.2, 0.3], 0.05)
    rng = np.random.default_rng(3)
    o = np.array([1.0, 0.5, -0.4])
    u = rng.normal(size=(300, 3))
    X = s.centre + s.radius * u / np.linalg.norm(u, axis=1, keepdims=True)
    front = (X - s.centre) @ (o - s.centre) > np.linalg.norm(o - s.centre) * s.radius  # seen from o
    X = X[front]
    d = (X - o) * rng.uniform(0.5, 3.0, (len(X), 1))  # any length
    t, label, n = s.ray_cast(o, d)
    np.testing.assert_allclose(o + t[:, None] * d, X, atol=1e-12)
    np.testing.assert_allclose(n, (X - s.centre) / s.radius, atol=1e-9)
    assert np.all(label == 0)
    t, label, _ = s.ray_cast(o, np.array([o - s.centre, [0.0, 0.0, 1.0]]))  # away from it, beside it
    assert np.all(np.isinf(t)) and np.all(label == -1)
    t, _, n = s.ray_cast(s.centre, np.array([[0.0, 0.0, 2.0]]))  # from inside: the way out
    np.testing.assert_allclose(t, [s.radius / 2.0])
    np.testing.assert_allclose(n, [[0, 0, 1.0]])


def test_sphere_outline_is_the_tangent_cone_circle():
    s = Sphere([0.1, -0.2, 0.3], 0.05)
    for c in (np.array([1.0, 0.5, -0.4]), np.array([0.1, -0.2, 0.36]), s.centre + [0.0, 0.0, 0.0501]):
        o = s.outline(c, n_circle=64)
        P = o.segments[:, 0]
        D = np.linalg.norm(c - s.centre)
        assert len(P) == 64 and o.visible.all() and set(o.kind) == {"silhouette"}
        np.testing.assert_allclose(np.linalg.norm(P - s.centre, axis=1), s.radius, atol=1e-12)  # on the sphere
        np.testing.assert_allclose(np.einsum("ij,ij->i", P - c, P - s.centre), 0.0, atol=1e-12)  # tangent lines
        half_angle = np.arccos(np.einsum("ij,j->i", P - c, s.centre - c) / np.linalg.norm(P - c, axis=1) / D)
        np.testing.assert_allclose(half_angle, np.arcsin(s.radius / D), atol=1e-7)  # the cone's half-angle
    assert len(s.outline(s.centre + [0.0, 0.01, 0.0]).segments) == 0  # from inside: no outline


def test_sphere_edge_samples_lie_on_its_outline_from_each_point():
    s = Sphere([0.0, 0.0, 0.1], 0.05)
    rng = np.random.default_rng(4)
    centres = rng.normal(size=(7, 3))
    centres[0] = s.centre + [0.0, 0.0, 0.01]  # inside
    ((X, D, V),) = s.edge_samples(centres, per_edge=5, n_rim=16)
    assert X.shape == D.shape == (7, 16, 3) and V.shape == (7, 16)
    assert not V[0].any() and V[1:].all()
    for k in range(1, 7):
        np.testing.assert_allclose(np.linalg.norm(X[k] - s.centre, axis=1), s.radius, atol=1e-12)
        np.testing.assert_allclose(np.einsum("ij,ij->i", X[k] - centres[k], X[k] - s.centre), 0.0, atol=1e-12)
        np.testing.assert_allclose(np.einsum("ij,ij->i", D[k], X[k] - s.centre), 0.0, atol=1e-12)  # tangents


def test_sphere_triangles_close_its_surface():
    s = Sphere([0.3, 0.1, -0.2], 0.05)
    V, F = s.triangles(96)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cross = np.cross(B - A, C - A)
    area = 0.5 * np.linalg.norm(cross, axis=1).sum()
    volume = np.einsum("ij,ij->i", A - s.centre, cross).sum() / 6.0  # > 0 only if outward-facing
    assert area == pytest.approx(4 * np.pi * s.radius**2, rel=2e-3)
    assert volume == pytest.approx(4 / 3 * np.pi * s.radius**3, rel=3e-3)
    np.testing.assert_allclose(np.linalg.norm(V - s.centre, axis=1), s.radius, atol=1e-15)
    edges = np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    assert np.all(count == 2)  # closed: every side shared by two triangles


def test_sphere_rejects_bad_input_and_unknown_kinds_are_refused():
    with pytest.raises(ValueError, match="positive"):
        Sphere([0, 0, 0], 0.0)
    with pytest.raises(ValueError, match="finite"):
        Sphere([0, np.nan, 0], 1.0)
    with pytest.raises(ValueError, match="unknown primitive kind 'torus'"):
        BRep.from_dict({"solids": [{"kind": "torus", "centre": [0, 0, 0]}]})
    with pytest.raises(ValueError, match="malformed"):
        BRep.from_dict({"solids": [{"kind": "sphere", "centre": [0, 0, 0]}]})
    with pytest.raises(ValueError, match="solids must be primitives with a surface"):
        BRep(np.zeros((0, 3)), np.zeros((0, 2)), solids=(Circle([0, 0, 0], [0, 0, 1], 1.0),))


def test_a_model_holding_a_sphere_draws_casts_tessellates_and_round_trips():
    ball = Sphere([0.0, 0.0, 0.3], 0.05)
    box = BRep.box(0.2, 0.2, 0.2)
    model = BRep(box.vertices, box.edges, box.faces, (ball,))
    rng = np.random.default_rng(5)
    T = make_T(random_rotation(rng), rng.normal(size=3))
    c_world = T[:3, :3] @ [0.4, -1.0, 0.6] + T[:3, 3]
    wf = model.wireframe(c_world, T, n_circle=32)
    assert (wf.kind == "edge").sum() == 12 and (wf.kind == "silhouette").sum() == 32
    assert set(wf.feature[wf.kind == "silhouette"]) == set(range(12, 44))  # after the box's edges
    X = wf.segments[wf.kind == "silhouette"].reshape(-1, 3)
    ball_world = T[:3, :3] @ ball.centre + T[:3, 3]
    np.testing.assert_allclose(np.linalg.norm(X - ball_world, axis=1), ball.radius, atol=1e-12)
    V, F = model.triangles(32)
    assert len(V) == 8 + len(ball.triangles(32)[0]) and F.max() == len(V) - 1
    assert model.bounds()[1, 2] == pytest.approx(0.35)
    again = BRep.from_dict(model.to_dict())
    assert again == model and again.to_dict()["solids"] == [
        {"kind": "sphere", "centre": [0.0, 0.0, 0.3], "radius": 0.05}
    ]
    assert model.transformed(T).solids[0] == Sphere(ball_world, 0.05)
    assert model.turn_invariant(np.array([0.0, 0.0, 1.0])) is False  # the box turns
    assert BRep(np.zeros((0, 3)), np.zeros((0, 2)), (), (ball,)).turn_invariant(np.array([0.0, 0.0, 1.0]))


def test_stored_forms_of_the_first_kinds_carry_no_tag():
    """Databases written before the protocol hold solids and circles untagged: read and written the same."""
    stored = {
        "vertices": [],
        "edges": [],
        "faces": [],
        "solids": [{"p0": [0.0, 0.0, 0.0], "p1": [0.0, 0.0, 0.2], "r0": 0.05, "r1": 0.04}],
        "circles": [{"centre": [0.0, 0.0, 0.1], "normal": [0.0, 0.0, 1.0], "radius": 0.03}],
    }
    assert BRep.from_dict(stored).to_dict() == stored


def test_a_meshs_contours_are_drawn_and_can_be_left_out():
    import trimesh

    from core.mesh_features import brep_from_mesh

    mesh = trimesh.creation.cylinder(0.05, 0.2, sections=64)
    model = brep_from_mesh(mesh.vertices, mesh.faces)
    c = np.array([0.3, -0.9, 0.2])
    wf = model.wireframe(c, np.eye(4))
    bare = model.wireframe(c, np.eye(4), contours=False)
    sil = wf.kind == "silhouette"
    assert 2 <= sil.sum() <= 4 and np.all(wf.edge_index[sil] == -1) and np.all(wf.feature[sil] >= len(model.edges))
    assert set(bare.kind) == {"edge"} and np.array_equal(bare.feature, wf.feature[~sil])
    # the contour sides are the mesh's generators nearest the analytic ones (tangent plane through c):
    # at angles φ ± arccos(r / |c⊥|), within one of the 64 sections
    X = wf.segments[sil].reshape(-1, 3)
    phi = np.arctan2(c[1], c[0])
    true = phi + np.array([1.0, -1.0]) * np.arccos(0.05 / np.hypot(c[0], c[1]))
    ang = np.arctan2(X[:, 1], X[:, 0])
    off = np.abs(np.angle(np.exp(1j * (ang[:, None] - true[None]))))
    assert np.all(off.min(axis=1) <= 2 * np.pi / 64) and set(off.argmin(axis=1)) == {0, 1}
