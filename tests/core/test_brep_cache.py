"""BRep keeps its face normals and centroids once computed, and computes a mesh's triangles at
once: the same values as the per-face formulas, the same edge visibility as the per-edge rule."""

import numpy as np
import trimesh

from core.brep import BRep
from core.mesh_features import brep_from_mesh


def _per_face(model):
    normals, cents = [], []
    for f in model.faces:
        P = model.vertices[list(f)]
        Q = np.roll(P, -1, axis=0)
        n = np.array(
            [
                np.sum((P[:, 1] - Q[:, 1]) * (P[:, 2] + Q[:, 2])),
                np.sum((P[:, 2] - Q[:, 2]) * (P[:, 0] + Q[:, 0])),
                np.sum((P[:, 0] - Q[:, 0]) * (P[:, 1] + Q[:, 1])),
            ]
        )
        normals.append(n / max(np.linalg.norm(n), 1e-300))
        cents.append(P.mean(axis=0))
    return np.array(normals).reshape(-1, 3), np.array(cents).reshape(-1, 3)


def _models():
    rng = np.random.default_rng(0)
    out = [
        BRep.box(0.3, 0.2, 0.1),
        BRep.prism(np.array([[0, 0], [1, 0], [1.2, 0.7], [0.5, 1.0]]), 0.2),
        BRep(np.array([[0, 0, 0], [0, 0, 1.0]]), np.array([[0, 1]])),
    ]
    for m in (
        trimesh.creation.icosphere(2, 0.3),
        trimesh.creation.cylinder(0.05, 0.2, sections=37),
        trimesh.creation.annulus(0.03, 0.05, 0.1),
        trimesh.creation.capsule(0.2, 0.05),
    ):
        V = m.vertices * rng.uniform(0.1, 3.0, 3) + rng.normal(size=3)
        out.append(brep_from_mesh(V, m.faces))  # triangles and polygons mixed
    return out


def test_normals_and_centroids_are_the_per_face_values_and_copies():
    for model in _models():
        n, c = _per_face(model)
        assert np.array_equal(model.face_normals(), n) and np.array_equal(model.face_centroids(), c)
        got = model.face_normals()
        got[:] = 0.0  # a caller's copy: the model keeps its own
        assert np.array_equal(model.face_normals(), n)


def test_edge_visibility_is_the_per_edge_rule():
    rng = np.random.default_rng(1)
    for model in _models():
        n, c = _per_face(model)
        for _ in range(100):
            centre = rng.normal(size=3) * 2.0
            facing = np.einsum("ij,ij->i", n, centre - c) > 0 if len(model.faces) else np.zeros(0, bool)
            rule = [
                True if not fs else bool(np.any(facing[list(fs)]))
                for fs in map(model.edge_faces, range(len(model.edges)))
            ]
            assert model.wireframe(centre, np.eye(4)).visible[: len(model.edges)].tolist() == rule
