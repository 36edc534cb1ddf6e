"""The polyhedral part of a model: vertices, straight edges and planar faces.

Boxes, prisms, pyramids, modelled polyhedra and imported meshes are all this one primitive. A mesh
imported as a feature-edge model (``core.mesh_features.brep_from_mesh``) keeps its sharp edges as
``edges`` and its curved regions as triangles whose sides are not edges (smooth sides); seen from a
point, such a region is drawn by its contour generator (``core.silhouette``), so a faceted model
needs no class of its own: what tells a mesh apart is in its data, and it survives the database.

Faces are vertex loops, counter-clockwise seen from outside (their right-hand normal points out).
Hidden lines: an edge is visible when one of its faces faces the point (exact for a convex object,
back-face culling otherwise); an edge bordering no face is always visible.

Ray cast: a convex polyhedron (every vertex on the inner side of every face plane) by clipping the
ray against its face planes (Kay–Kajiya slabs generalised); any other by its fan triangles
(Möller–Trumbore, all triangles at once). Labels are face indices.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..geometry import as_points
from ..silhouette import SmoothSides
from .base import CaoPart, Outline, SampleGroup, no_hits

__all__ = ["Polyhedron"]

_EPS = 1e-12


def _newell(P: np.ndarray) -> np.ndarray:
    """Newell normals (..., 3) of loops P (..., L, 3), summed over the loop's sides (not normalised)."""
    Q = P[..., (np.arange(P.shape[-2]) + 1) % P.shape[-2], :]  # each vertex's next (np.roll's values, sooner)
    return np.stack(
        [
            ((P[..., 1] - Q[..., 1]) * (P[..., 2] + Q[..., 2])).sum(axis=-1),
            ((P[..., 2] - Q[..., 2]) * (P[..., 0] + Q[..., 0])).sum(axis=-1),
            ((P[..., 0] - Q[..., 0]) * (P[..., 1] + Q[..., 1])).sum(axis=-1),
        ],
        axis=-1,
    )


@dataclass(frozen=True, eq=False)
class Polyhedron:
    """Vertices, edges and faces in the object frame (metres).

    vertices : array, shape (V, 3). edges : array, shape (E, 2), int, vertex indices. faces : tuple
    of vertex loops (tuples of int), counter-clockwise seen from outside. Empty arrays are allowed
    (a model of solids alone has an empty polyhedral part).
    """

    vertices: np.ndarray
    edges: np.ndarray
    faces: tuple = ()

    kind: ClassVar[str] = "polyhedron"
    surface: ClassVar[bool] = True

    def __post_init__(self):
        V = np.asarray(self.vertices, dtype=float).reshape(-1, 3)
        if len(V):
            as_points(V, "vertices")
        E = np.asarray(self.edges, dtype=np.int64).reshape(-1, 2)
        if len(E) and (E.min() < 0 or E.max() >= len(V)):
            raise ValueError(f"edge vertex index out of range 0..{len(V) - 1}")
        if np.any(E[:, 0] == E[:, 1]):
            raise ValueError("an edge joins a vertex to itself")
        faces = tuple(tuple(int(i) for i in f) for f in self.faces)
        for k, f in enumerate(faces):
            if len(f) < 3:
                raise ValueError(f"face {k} has {len(f)} vertices; a face needs at least 3")
            if min(f) < 0 or max(f) >= len(V):
                raise ValueError(f"face {k} has a vertex index out of range 0..{len(V) - 1}")
        V.setflags(write=False)
        E.setflags(write=False)
        object.__setattr__(self, "vertices", V)
        object.__setattr__(self, "edges", E)
        object.__setattr__(self, "faces", faces)

    def __eq__(self, other: object) -> bool:
        return (
            type(other) is Polyhedron
            and np.array_equal(self.vertices, other.vertices)
            and np.array_equal(self.edges, other.edges)
            and self.faces == other.faces
        )

    __hash__ = None  # arrays inside: not hashable

    @property
    def n_labels(self) -> int:
        return len(self.faces)

    # ------------------------------------------------------------------ pose-independent data, kept
    def _cached(self, name: str, compute):
        """A pose-independent value computed once (the primitive is immutable); arrays made read-only."""
        value = self.__dict__.get(name)
        if value is None:
            value = compute()
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)
        return value

    def face_normals(self) -> np.ndarray:
        """Outward unit normals (F, 3) by Newell's method (robust for non-planar loops), read-only."""
        return self._cached("_face_normals", self._compute_face_normals)

    def _compute_face_normals(self) -> np.ndarray:
        out = np.zeros((len(self.faces), 3))
        for which, loops in self._loops_by_length():  # all loops of one length at once (one at a time was a third
            n = _newell(self.vertices[loops])  # of the interface's first draw of 2,000 boxes)
            out[which] = [v / max(np.linalg.norm(v), 1e-300) for v in n]
        return out

    def _loops_by_length(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(face indices (M,), their vertex loops (M, L)) for each loop length L of the faces."""
        by: dict[int, list[int]] = {}
        for k, f in enumerate(self.faces):
            by.setdefault(len(f), []).append(k)
        return [(np.array(ks), np.array([self.faces[k] for k in ks], dtype=np.int64)) for ks in by.values()]

    def face_centroids(self) -> np.ndarray:
        """Centroids (F, 3) of the faces' vertex loops, read-only."""
        return self._cached("_face_centroids", self._compute_face_centroids)

    def _compute_face_centroids(self) -> np.ndarray:
        out = np.zeros((len(self.faces), 3))
        for which, loops in self._loops_by_length():
            out[which] = self.vertices[loops].mean(axis=1)
        return out

    def edge_faces(self) -> tuple[tuple[int, ...], ...]:
        """Per edge, the indices of the faces it borders."""

        def compute():
            lookup: dict[tuple[int, int], list[int]] = {}
            for k, f in enumerate(self.faces):
                for a, b in zip(f, f[1:] + f[:1]):
                    lookup.setdefault((min(a, b), max(a, b)), []).append(k)
            return tuple(tuple(lookup.get((min(a, b), max(a, b)), ())) for a, b in self.edges.tolist())

        return self._cached("_edge_faces", compute)

    def edge_face_pairs(self) -> np.ndarray:
        """(M, 2) int: every (edge, face it borders) pair, edges in order (for vectorised visibility)."""

        def compute():
            pairs = [(k, f) for k, fs in enumerate(self.edge_faces()) for f in fs]
            return np.array(pairs, dtype=np.int64).reshape(-1, 2)

        return self._cached("_edge_face_pairs", compute)

    def incidence(self) -> np.ndarray:
        """(E, F) bool: edge k borders face f."""

        def compute():
            inc = np.zeros((len(self.edges), len(self.faces)), bool)
            pairs = self.edge_face_pairs()
            inc[pairs[:, 0], pairs[:, 1]] = True
            return inc

        return self._cached("_incidence", compute)

    def smooth_sides(self) -> SmoothSides:
        """The sides of its faces that are no edge and join two bent faces (a mesh's curved regions)."""
        return self._cached("_smooth", self._compute_smooth_sides)

    def _compute_smooth_sides(self) -> SmoothSides:
        # every side of every face an edge (a box, any model built of planar faces) has none: told from the
        # faces each edge borders, which the hidden-line rule needs anyway (the search cost a box's first draw
        # 70 us); with two edges on one side the count would not tell, and the search does
        E = self.edges.tolist()
        if len({(min(a, b), max(a, b)) for a, b in E}) == len(E) and sum(map(len, self.edge_faces())) == sum(
            map(len, self.faces)
        ):
            return SmoothSides.none()
        return SmoothSides.of(self.vertices, self.faces, self.edges)

    def _planes(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The face planes (n (F, 3), d (F,)) when the polyhedron is convex, else None."""

        def compute():
            if not self.faces:
                return ()
            n = self.face_normals()
            d = -np.einsum("ij,ij->i", n, self.face_centroids())
            scale = max(float(np.ptp(self.vertices, axis=0).max()), 1e-9)
            return (n, d) if bool(np.all(self.vertices @ n.T + d <= 1e-9 * scale)) else ()

        return self._cached("_convex_planes", compute) or None

    @property
    def convex(self) -> bool:
        """True when it has faces and every vertex is on the inner side of every face plane."""
        return self._planes() is not None

    def fan_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """Its faces fan-triangulated: vertex indices (T, 3) and the face of each triangle (T,)."""

        def compute():
            tris = [(f[0], f[i], f[i + 1]) for f in self.faces for i in range(1, len(f) - 1)]
            owner = [k for k, f in enumerate(self.faces) for _ in range(len(f) - 2)]
            return np.array(tris, dtype=np.int64).reshape(-1, 3), np.array(owner, dtype=np.int64)

        return self._cached("_fan", compute)

    # ------------------------------------------------------------------ the protocol
    def ray_cast(self, o_obj: np.ndarray, d_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest hits (``Primitive.ray_cast``): by its face planes when convex, else by its triangles."""
        o = np.asarray(o_obj, dtype=float).reshape(3)
        d = np.asarray(d_obj, dtype=float).reshape(-1, 3)
        if not self.faces:
            return no_hits(len(d))
        planes = self._planes()
        return self._cast_convex(planes, o, d) if planes is not None else self._cast_triangles(o, d)

    @staticmethod
    def _cast_convex(planes, o: np.ndarray, d: np.ndarray):
        planes_n, planes_d = planes
        num = -(planes_n @ o + planes_d)  # (F,): n·(o + t d) + c ≤ 0  ⇔  t·den ≤ num
        den = d @ planes_n.T  # (N, F)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / den
        entering = den < -_EPS
        exiting = den > _EPS
        parallel_out = (~entering & ~exiting) & (num < 0)[None, :]
        t_in_all = np.where(entering, t, -np.inf)
        t_enter = t_in_all.max(axis=1)
        face = t_in_all.argmax(axis=1)
        t_out_all = np.where(exiting, t, np.inf)
        t_exit = t_out_all.min(axis=1)
        ok = (t_enter <= t_exit) & (t_exit > 0) & ~parallel_out.any(axis=1)
        # from outside the first surface met is the entry face; from inside (t_enter <= 0) the exit face
        inside = t_enter <= 0
        face = np.where(inside, t_out_all.argmin(axis=1), face)
        t_hit = np.where(ok, np.where(inside, t_exit, t_enter), np.inf)
        return t_hit, np.where(ok, face, -1), np.where(ok[:, None], planes_n[face], 0.0)

    def _cast_triangles(self, o: np.ndarray, d: np.ndarray):
        """Möller–Trumbore against every triangle at once (rays from one origin o), in blocks of rays.

        With s = o − A, q = s × e1: det = d·(e2 × e1), u = d·(e2 × s)/det, v = d·q/det, t = (q·e2)/det,
        so each is one (rays × triangles) product. Ties go to the lower triangle index.
        """
        idx, owner = self.fan_triangles()
        n = len(d)
        best = np.full(n, np.inf)
        face = np.full(n, -1, dtype=np.int64)
        normal = np.zeros((n, 3))
        A = self.vertices[idx[:, 0]]
        e1 = self.vertices[idx[:, 1]] - A
        e2 = self.vertices[idx[:, 2]] - A
        s = o - A
        q = np.cross(s, e1)
        w_det = np.cross(e2, e1)
        w_u = np.cross(e2, s)
        t_num = np.einsum("ij,ij->i", q, e2)
        nk = np.cross(e1, e2)
        nk = nk / np.maximum(np.linalg.norm(nk, axis=1, keepdims=True), 1e-300)
        block = max(1, 2_000_000 // max(len(A), 1))
        for lo in range(0, n, block):
            dd = d[lo : lo + block]
            det = dd @ w_det.T  # (m, T)
            ok = np.abs(det) > _EPS
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            u = (dd @ w_u.T) * inv
            v = (dd @ q.T) * inv
            t = t_num * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
            t = np.where(hit, t, np.inf)
            k = t.argmin(axis=1)
            tk = t[np.arange(len(dd)), k]
            got = np.isfinite(tk)
            best[lo : lo + block] = tk
            face[lo : lo + block] = np.where(got, owner[k], -1)
            normal[lo : lo + block] = np.where(got[:, None], nk[k], 0.0)
        return best, face, normal

    def _edge_visibility(self, c: np.ndarray) -> np.ndarray:
        """(E,) bool: the edge borders no face or a face that faces the point c (3,)."""
        E = len(self.edges)
        facing = (
            np.einsum("ij,ij->i", self.face_normals(), c - self.face_centroids()) > 0
            if self.faces
            else np.zeros(0, bool)
        )
        pairs = self.edge_face_pairs()
        faceless = self._cached("_faceless", lambda: ~(np.bincount(pairs[:, 0], minlength=E) > 0))
        seen = np.bincount(pairs[:, 0], weights=facing[pairs[:, 1]], minlength=E) > 0
        return faceless | seen

    def outline(self, center_obj: np.ndarray, n_circle: int = 48) -> Outline:
        """Its edges (features 0..E−1, visible by the hidden-line rule) and the contour generator of its
        smooth regions (the smooth sides between a face that faces the point and one that faces away;
        visible, features E + side index)."""
        c = np.asarray(center_obj, dtype=float).reshape(3)
        E = len(self.edges)
        smooth = self.smooth_sides() if len(self.faces) >= 2 else None
        S = len(smooth) if smooth is not None else 0
        if E == 0 and S == 0:
            return Outline.empty()
        if S == 0:  # its edges alone: all but their visibility kept (they were most of a box's redraw)
            segments, kind, edge, feature, chord = self._cached("_edge_outline", self._edge_outline)
            return Outline(segments.copy(), self._edge_visibility(c), kind, edge, feature, chord, E)
        idx = smooth.contour(c) if S else np.zeros(0, np.int64)
        m = len(idx)
        edge = np.concatenate([np.arange(E), np.full(m, -1)]).astype(np.int64)
        return Outline(
            self.vertices[np.concatenate([self.edges, smooth.sides[idx]]) if m else self.edges].reshape(-1, 2, 3),
            np.concatenate([self._edge_visibility(c) if E else np.zeros(0, bool), np.ones(m, bool)]),
            np.concatenate([np.full(E, "edge", dtype="<U10"), np.full(m, "silhouette", dtype="<U10")]),
            edge,
            np.concatenate([np.arange(E), E + idx]).astype(np.int64),
            np.full(E + m, -1, np.int64),
            E + S,
        )

    def _edge_outline(self) -> tuple[np.ndarray, ...]:
        """The view-independent arrays of ``outline`` with no smooth side: segments (E, 2, 3), kind, edge,
        feature, chord (E,), read-only."""
        E = len(self.edges)
        arrays = (
            self.vertices[self.edges].reshape(-1, 2, 3),
            np.full(E, "edge", dtype="<U10"),
            np.arange(E, dtype=np.int64),
            np.arange(E, dtype=np.int64),
            np.full(E, -1, np.int64),
        )
        for a in arrays:
            a.setflags(write=False)
        return arrays

    def edge_samples(self, centers_obj: np.ndarray, per_edge: int, n_rim: int) -> list[SampleGroup]:
        """``per_edge`` points along each edge (away from its ends), seen by the hidden-line rule.

        The smooth regions' contours are left out: per pose they cost a test per face (thousands for
        a mesh) where an edge costs a few."""
        E = len(self.edges)
        if E == 0:
            return []
        c = np.asarray(centers_obj, dtype=float).reshape(-1, 3)
        s = (np.arange(per_edge) + 0.5) / per_edge * 0.84 + 0.08  # away from the vertices
        A, B = self.vertices[self.edges[:, 0]], self.vertices[self.edges[:, 1]]
        X = A[:, None] + s[None, :, None] * (B - A)[:, None]  # (E, m, 3)
        D = np.broadcast_to((B - A)[:, None], X.shape)
        inc = self.incidence()
        if inc.shape[1]:
            n, cents = self.face_normals(), self.face_centroids()
            facing = (c @ n.T - np.einsum("fi,fi->f", n, cents)[None]) > 0
            vis = (facing.astype(np.float32) @ inc.T.astype(np.float32) > 0) | ~inc.any(axis=1)[None]
        else:
            vis = np.ones((len(c), E), bool)
        return [(X.reshape(-1, 3), D.reshape(-1, 3), np.repeat(vis, per_edge, axis=1))]

    def triangles(self, n_circle: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """Its vertices (V, 3) and faces fan-triangulated (convex faces) (T, 3)."""
        return self.vertices, self.fan_triangles()[0]

    def cao_part(self) -> CaoPart:
        """Its vertices; every face as a face from points; the edges that are no face's side as lines."""
        covered = {(min(a, b), max(a, b)) for f in self.faces for a, b in zip(f, f[1:] + f[:1])}
        lines = [(a, b) for a, b in map(tuple, self.edges.tolist()) if (a, b) not in covered]
        return CaoPart(self.vertices, np.array(lines, dtype=np.int64).reshape(-1, 2), self.faces)

    def bounds(self) -> np.ndarray | None:
        return np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)]) if len(self.vertices) else None

    def support_points(self, n: int = 48, min_radius: float = 0.0) -> np.ndarray:
        return self.vertices

    def plane_normals(self) -> np.ndarray:
        return self.face_normals().reshape(-1, 3)

    def turn_invariant(self, axis_obj: np.ndarray) -> bool:
        """Every vertex lies on the line (none at all: trivially)."""
        u = np.asarray(axis_obj, dtype=float).reshape(3)
        return bool(np.all(np.linalg.norm(np.cross(self.vertices, u), axis=1) < 1e-9))

    def transformed(self, T_new_obj: np.ndarray) -> Polyhedron:
        V = self.vertices @ T_new_obj[:3, :3].T + T_new_obj[:3, 3] if len(self.vertices) else self.vertices
        return Polyhedron(V, self.edges, self.faces)

    def to_dict(self) -> dict[str, Any]:
        return {
            "vertices": self.vertices.tolist(),
            "edges": self.edges.tolist(),
            "faces": [list(f) for f in self.faces],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Polyhedron:
        return cls(
            np.asarray(d.get("vertices", []), dtype=float).reshape(-1, 3),
            np.asarray(d.get("edges", []), dtype=np.int64).reshape(-1, 2),
            tuple(tuple(f) for f in d.get("faces", [])),
        )
