"""Silhouettes of the smooth regions of a faceted model: the contour generator seen from a point.

A mesh imported as a B-Rep (``core.mesh_features.brep_from_mesh``) keeps its sharp edges (creases,
borders) as ``edges``; a curved region keeps its triangles as ``faces`` whose sides are *not*
edges. Such a side, shared by exactly two faces, is a *smooth side*. Seen from an optical centre
c, the outline of the smooth region — a cylinder's two side lines, a sphere's circle — is its
contour generator: the smooth sides between a face that faces c and one that faces away.

The smooth sides and the faces' planes do not depend on the view: ``SmoothSides.of`` computes
them once per model (vectorised; a 5,120-triangle sphere in 3.5–16 ms on the shared 2-core test
machine, ``bench/silhouette.py``), and ``SmoothSides.contour`` picks the contour sides for one
centre (one dot product per face: 0.06 ms for that sphere).

Accuracy: the contour sides are mesh edges, so they lie on the tessellation, not on the smooth
surface it approximates. For a convex surface whose vertices lie on it (trimesh's primitives,
most CAD exports), the faceted surface lies between the true surface and the true surface shrunk
by the faces' sag (a cylinder of radius r cut into n sides: radius r·cos(π/n); a sphere: the
distance of the nearest face plane from the centre), so its outline lies between the outlines
of those two surfaces (tests/core/test_silhouette.py: 0.09 px for a 5,120-triangle sphere 80 px
in radius, 0.0003 px for a 2,000-triangle cylinder's side lines).
Silhouettes are always drawn as visible: exact for one convex surface, like the rest of the
hidden-line removal (``BRep.wireframe``); on a non-convex one (a torus's inner outline, a bent
pipe) a part hidden by the surface itself is drawn too. A curved surface tessellated so coarsely
that its dihedral angles reach the import's ``angle_deg`` (30°: a cylinder of 12 sides or fewer)
has sharp edges instead, drawn as edges.

Which sides are smooth is read from the model itself (a side of two faces that is not an edge),
so it survives the database (``BRep.to_dict``) with nothing added. Sides between coplanar faces
(the triangles of a planar region that is not one convex polygon) and sides whose two faces are
wound inconsistently (no outside is defined there) are left out: they never bound a silhouette.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np

__all__ = ["SmoothSides", "contour_segments"]

_COPLANAR = 1e-10  # 1 − cos of the angle between two faces' normals below this: the same plane


@dataclass(frozen=True)
class SmoothSides:
    """The smooth sides of a faceted model and what the contour test needs, in the object frame.

    sides : array, shape (K, 2), int, vertex indices of each smooth side. pair : array, shape
    (K, 2), int, the two faces it joins. normals : array, shape (F, 3), the faces' outward normals
    (Newell, not normalised). points : array, shape (F, 3), the faces' centroids.
    """

    sides: np.ndarray
    pair: np.ndarray
    normals: np.ndarray
    points: np.ndarray

    def __len__(self) -> int:
        return len(self.sides)

    @classmethod
    def none(cls) -> SmoothSides:
        """No smooth side (a model whose faces' sides are all edges)."""
        return cls(np.zeros((0, 2), np.int64), np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros((0, 3)))

    @classmethod
    def of(cls, vertices: np.ndarray, faces, edges: np.ndarray) -> SmoothSides:
        """The smooth sides of faces (vertex loops) over vertices (V, 3), given the sharp edges (E, 2).

        A side is smooth when exactly two faces share it, it is not one of ``edges``, the faces
        are wound consistently across it (they run through it in opposite directions) and they are
        not coplanar.
        """
        V = np.asarray(vertices, dtype=float).reshape(-1, 3)
        empty = cls.none()
        if len(faces) < 2:
            return empty
        lengths = np.fromiter((len(f) for f in faces), dtype=np.int64, count=len(faces))
        flat = np.fromiter(chain.from_iterable(faces), dtype=np.int64, count=int(lengths.sum()))
        starts = np.cumsum(lengths) - lengths
        face_of = np.repeat(np.arange(len(faces)), lengths)
        nxt_pos = np.arange(len(flat)) + 1
        nxt_pos[starts + lengths - 1] = starts  # the last vertex of a loop runs back to its first
        a, b = flat, flat[nxt_pos]
        n = len(V)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        key = lo * n + hi
        E = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        sharp = (
            np.isin(key, np.minimum(E[:, 0], E[:, 1]) * n + np.maximum(E[:, 0], E[:, 1]))
            if len(E)
            else np.zeros(len(key), bool)
        )
        if sharp.all():  # every side an edge (a box, any B-Rep built of planar faces): nothing smooth
            return empty
        # Newell normal = Σ P_i × P_i+1 over the loop; centroid = mean of the loop's vertices.
        normals = np.add.reduceat(np.cross(V[a], V[b]), starts, axis=0)
        points = np.add.reduceat(V[a], starts, axis=0) / lengths[:, None]
        order = np.argsort(key, kind="stable")
        k_sorted = key[order]
        first = np.ones(len(k_sorted), bool)
        first[1:] = k_sorted[1:] != k_sorted[:-1]
        run_start = np.flatnonzero(first)
        run_len = np.diff(np.append(run_start, len(k_sorted)))
        two = run_start[run_len == 2]
        h0, h1 = order[two], order[two + 1]  # the two half-sides of each side shared by two faces
        keep = ~sharp[h0] & (face_of[h0] != face_of[h1]) & ((a[h0] < b[h0]) != (a[h1] < b[h1]))
        h0, h1 = h0[keep], h1[keep]
        f0, f1 = face_of[h0], face_of[h1]
        u = normals / np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]
        bent = 1.0 - np.einsum("ij,ij->i", u[f0], u[f1]) > _COPLANAR
        if not np.any(bent):
            return empty
        return cls(np.column_stack([lo[h0], hi[h0]])[bent], np.column_stack([f0, f1])[bent], normals, points)

    def facing(self, center_obj: np.ndarray) -> np.ndarray:
        """(F,) bool: which faces face the centre (3,) (object frame)."""
        c = np.asarray(center_obj, dtype=float).reshape(3)
        return np.einsum("ij,ij->i", self.normals, c - self.points) > 0

    def contour(self, center_obj: np.ndarray) -> np.ndarray:
        """Indices (M,) into ``sides`` of the contour generator seen from the centre (3,), object frame."""
        if len(self.sides) == 0:
            return np.zeros(0, np.int64)
        f = self.facing(center_obj)
        return np.flatnonzero(f[self.pair[:, 0]] != f[self.pair[:, 1]])


def contour_segments(vertices: np.ndarray, smooth: SmoothSides, center_obj: np.ndarray) -> np.ndarray:
    """The contour generator seen from ``center_obj`` (3,) as segments (M, 2, 3), object frame."""
    V = np.asarray(vertices, dtype=float).reshape(-1, 3)
    return V[smooth.sides[smooth.contour(center_obj)]].reshape(-1, 2, 3)
