"""Meshes reduced to feature edges: no false edges from triangulated faces, real creases kept."""

import numpy as np
import pytest
import trimesh

from core.mesh_features import brep_from_mesh, feature_edges


def _edge_set(model):
    return {tuple(sorted(map(tuple, np.round(model.vertices[e], 9)))) for e in model.edges}


def test_box_triangles_become_six_quads_with_outward_normals():
    m = trimesh.creation.box([0.3, 0.2, 0.1])
    b = brep_from_mesh(m.vertices, m.faces)
    assert b.vertices.shape == (8, 3) and b.edges.shape == (12, 2)
    assert sorted(len(f) for f in b.faces) == [4] * 6
    # every face normal points away from the centre
    assert np.all(np.einsum("ij,ij->i", b.face_normals(), b.face_centroids()) > 0)
    lengths = sorted(np.round(np.linalg.norm(np.diff(b.edge_segments(), axis=1)[:, 0], axis=1), 9))
    assert lengths == [0.1] * 4 + [0.2] * 4 + [0.3] * 4


def test_subdivided_faces_and_split_sides_merge_back():
    m = trimesh.creation.box([0.3, 0.2, 0.1]).subdivide().subdivide()
    assert len(m.faces) == 192
    b = brep_from_mesh(m.vertices, m.faces)
    assert b.vertices.shape == (8, 3) and b.edges.shape == (12, 2)
    assert sorted(len(f) for f in b.faces) == [4] * 6


def _l_prism(h=0.05):
    """An L-shaped prism: caps triangulated by hand (non-convex), sides as two triangles each."""
    L = np.array([[0, 0], [0.2, 0], [0.2, 0.1], [0.1, 0.1], [0.1, 0.2], [0, 0.2]])
    V = np.vstack([np.column_stack([L, np.zeros(6)]), np.column_stack([L, np.full(6, h)])])
    cap = [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)]
    F = [(a + 6, b + 6, c + 6) for a, b, c in cap] + [(a, c, b) for a, b, c in cap]
    for i in range(6):
        j = (i + 1) % 6
        F += [(i, j, j + 6), (i, j + 6, i + 6)]
    return V, np.array(F)


def test_non_convex_face_keeps_its_triangles_but_draws_only_real_edges():
    V, F = _l_prism()
    b = brep_from_mesh(V, F)
    assert b.edges.shape == (18, 2) and b.vertices.shape == (12, 3)
    # the two L-shaped caps stay triangles (not convex); the six sides are quads
    assert sorted(len(f) for f in b.faces) == [3] * 8 + [4] * 6
    # no edge crosses a cap: every edge is vertical or axis-aligned along a cap border
    seg = b.edge_segments()
    d = seg[:, 1] - seg[:, 0]
    vertical = np.isclose(np.abs(d[:, 2]), 0.05)
    axis_aligned = np.isclose(np.abs(d[:, :2]).min(axis=1), 0.0) & np.isclose(d[:, 2], 0.0)
    assert np.all(vertical | axis_aligned)
    assert int(vertical.sum()) == 6
    # hidden lines: seen from above, the bottom cap's border edges that no side faces are hidden
    wf = b.wireframe(np.array([0.05, 0.05, 5.0]), np.eye(4))
    assert wf.visible.sum() < len(wf.visible)


def test_cylinder_mesh_keeps_the_rims_only():
    m = trimesh.creation.cylinder(radius=0.05, height=0.2, sections=48)
    b = brep_from_mesh(m.vertices, m.faces, angle_deg=30.0)
    assert b.edges.shape == (96, 2)
    seg = b.edge_segments()
    assert np.allclose(np.abs(seg[..., 2]), 0.1)  # every edge lies on a rim
    assert sorted(len(f) for f in b.faces).count(48) == 2  # the caps became polygons


@pytest.mark.parametrize("angle_deg, expected_lateral", [(40.0, 6), (70.0, 0)])
def test_dihedral_threshold_decides_which_creases_are_edges(angle_deg, expected_lateral):
    m = trimesh.creation.cylinder(radius=0.05, height=0.2, sections=6)  # hexagonal prism: 60° creases
    E = feature_edges(m.vertices, m.faces, angle_deg=angle_deg)
    d = m.vertices[E[:, 1]] - m.vertices[E[:, 0]]
    assert int(np.sum(np.isclose(np.abs(d[:, 2]), 0.2))) == expected_lateral
    assert int(np.sum(np.isclose(d[:, 2], 0.0))) == 12  # the rims (90° to the caps) always


def test_open_borders_are_edges_and_degenerate_triangles_are_ignored():
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 4, 1]])  # the last one has zero area
    b = brep_from_mesh(V, F)
    assert b.edges.shape == (4, 2) and [len(f) for f in b.faces] == [4]


@pytest.mark.parametrize(
    "V, F, match",
    [
        (np.zeros((3, 2)), np.array([[0, 1, 2]]), "vertices must have shape"),
        (np.eye(3), np.array([[0, 1, 5]]), "out of range"),
        (np.eye(3), np.array([[0.0, 1.0, 2.0]]), "integer"),
        (np.eye(3), np.zeros((0, 3), int), "triangles must have shape"),
        (np.zeros((3, 3)), np.array([[0, 1, 2]]), "no extent"),
    ],
)
def test_bad_input_raises(V, F, match):
    with pytest.raises(ValueError, match=match):
        brep_from_mesh(V, F)


def test_bad_angle_raises():
    m = trimesh.creation.box([1, 1, 1])
    with pytest.raises(ValueError, match="angle_deg"):
        feature_edges(m.vertices, m.faces, angle_deg=0.0)
