import numpy as np
import pytest

from core.brep import BRep, Revolution
from core.transforms import make_T, random_rotation


def mesh_volume(V, T):
    a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    return np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0


def test_box_topology_and_outward_normals():
    box = BRep.box(0.35, 0.231, 0.132)
    assert box.vertices.shape == (8, 3) and box.edges.shape == (12, 2) and len(box.faces) == 6
    normals = box.face_normals()
    centre = box.vertices.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", normals, box.face_centroids() - centre) > 0)
    np.testing.assert_allclose(box.bounds(), [[-0.175, -0.1155, 0.0], [0.175, 0.1155, 0.132]])
    for k in range(12):
        assert len(box.edge_faces(k)) == 2  # every edge borders exactly two faces


@pytest.mark.parametrize(
    "model, volume",
    [
        (BRep.box(0.3, 0.2, 0.1), 0.006),
        (BRep.prism(np.array([[0, 0], [1, 0], [0, 1.0]]), 2.0), 1.0),
        (BRep.pyramid(np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]]), [0.5, 0.5, 3.0]), 1.0),
    ],
)
def test_closed_meshes_have_the_right_volume(model, volume):
    V, T = model.triangles()
    assert mesh_volume(V, T) == pytest.approx(volume)  # positive: triangles face outward


def test_cylinder_and_cone_meshes():
    n = 64
    V, T = BRep.cylinder(0.051, 0.166).triangles(n)
    polygon_area = 0.5 * n * np.sin(2 * np.pi / n) * 0.051**2
    assert mesh_volume(V, T) == pytest.approx(polygon_area * 0.166)
    V, T = BRep.cone(0.05, 0.0, 0.3).triangles(n)
    assert mesh_volume(V, T) == pytest.approx(0.5 * n * np.sin(2 * np.pi / n) * 0.05**2 * 0.3 / 3)


def test_box_wireframe_hidden_lines():
    box = BRep.box(1.0, 1.0, 1.0)
    wf = box.wireframe(np.array([3.0, 2.0, 5.0]), np.eye(4))  # sees top, +x and +y faces
    assert wf.segments.shape == (12, 2, 3) and wf.visible.sum() == 9
    wf = box.wireframe(np.array([0.0, 0.0, 5.0]), np.eye(4))  # straight above: only the top face
    assert wf.visible.sum() == 4
    segs = box.edge_segments()
    # The visible ones are the top face's edges; every hidden one touches the bottom.
    assert np.all(segs[wf.visible][:, :, 2] == 1.0)
    assert np.all(np.min(segs[~wf.visible][:, :, 2], axis=1) == 0.0)
    assert all(kind == "edge" for kind in wf.kind)


def test_wireframe_is_expressed_in_the_world():
    rng = np.random.default_rng(0)
    box = BRep.box(0.3, 0.2, 0.1)
    T = make_T(random_rotation(rng), rng.normal(size=3))
    wf = box.wireframe(T[:3, 3] + 10 * rng.normal(size=3), T)
    np.testing.assert_allclose(wf.segments, box.edge_segments(T), atol=1e-12)
    assert wf.edge_index.tolist() == list(range(12))


@pytest.mark.parametrize("r0, r1", [(0.051, 0.051), (0.08, 0.03), (0.06, 0.0)])
def test_silhouettes_are_tangent_seen_from_the_centre(r0, r1):
    rng = np.random.default_rng(1)
    solid = Revolution([0, 0, 0], [0, 0, 0.2], r0, r1)
    for _ in range(20):
        c = rng.normal(size=3) * [1.0, 1.0, 0.3] + [0, 0, 0.1]
        c *= 1.5 / np.linalg.norm(c[:2])
        sil = solid.silhouette(c)
        assert sil.shape == (2, 2, 3)
        h = solid.height
        for seg in sil:
            # Points on the generator lie on the surface...
            for t in (0.0, 0.4, 1.0):
                P = seg[0] + t * (seg[1] - seg[0])
                r_expected = r0 + t * (r1 - r0)
                assert np.hypot(P[0], P[1]) == pytest.approx(r_expected, abs=1e-12)
            # ...and the surface normal there is perpendicular to the line of sight.
            e = seg[0][:2] / np.linalg.norm(seg[0][:2]) if r0 > 0 else seg[1][:2] / np.linalg.norm(seg[1][:2])
            normal = np.array([h * e[0], h * e[1], r0 - r1])
            P = 0.5 * (seg[0] + seg[1])
            assert normal @ (P - c) == pytest.approx(0.0, abs=1e-12)


def test_no_silhouette_from_inside_and_rims_visibility():
    cyl = BRep.cylinder(0.05, 0.2)
    assert cyl.solids[0].silhouette(np.array([0.0, 0.01, 0.1])).shape == (0, 2, 3)
    wf = cyl.wireframe(np.array([2.0, 0.0, 1.0]), np.eye(4))  # from above and aside
    top = wf.kind == "rim"
    rim_z = wf.segments[top][:, 0, 2]
    assert wf.visible[top][rim_z > 0.1].all()  # the top rim is fully visible
    bottom_vis = wf.visible[top][rim_z < 0.1]
    assert 0 < bottom_vis.sum() < len(bottom_vis)  # only the near half of the bottom rim
    assert (wf.kind == "silhouette").sum() == 2


def test_serialisation_round_trip_and_equality():
    model = BRep.from_faces(
        BRep.box(1, 2, 3).vertices, BRep.box(1, 2, 3).faces, (Revolution([0, 0, 0], [0, 0, 1], 0.1, 0.05),)
    )
    again = BRep.from_dict(model.to_dict())
    assert again == model
    assert again != BRep.box(1, 2, 3)
    with pytest.raises(ValueError, match="malformed"):
        BRep.from_dict({"solids": [{"p0": [0, 0, 0]}]})


def test_transformed_bakes_a_pose():
    rng = np.random.default_rng(2)
    T = make_T(random_rotation(rng), rng.normal(size=3))
    model = BRep.box(1, 1, 1)
    np.testing.assert_allclose(model.transformed(T).edge_segments(), model.edge_segments(T), atol=1e-12)


def test_bad_models_raise():
    with pytest.raises(ValueError, match="out of range"):
        BRep(np.zeros((2, 3)), [[0, 2]])
    with pytest.raises(ValueError, match="itself"):
        BRep(np.zeros((2, 3)), [[1, 1]])
    with pytest.raises(ValueError, match="at least 3"):
        BRep(np.eye(3), [[0, 1]], faces=[(0, 1)])
    with pytest.raises(ValueError, match="positive"):
        BRep.box(0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="distinct"):
        Revolution([0, 0, 0], [0, 0, 0], 1.0, 1.0)
    with pytest.raises(ValueError, match="not both zero"):
        Revolution([0, 0, 0], [0, 0, 1], 0.0, 0.0)
    with pytest.raises(ValueError, match="a model needs vertices"):
        BRep(np.zeros((0, 3)), np.zeros((0, 2)))
