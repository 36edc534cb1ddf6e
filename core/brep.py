"""The B-Rep model of an object: what the database stores, the overlay draws and the solvers use.

A model lives in its own frame ``obj`` (metres); its pose in the site is ``T_world_obj``.

* ``vertices`` (V, 3), ``edges`` (E, 2) vertex indices, ``faces``: vertex loops, counter-clockwise
  seen from outside (their right-hand normal points out).
* ``solids``: analytic solids of revolution (``Revolution``: a cylinder, or a cone/frustum with two
  radii) given by their axis endpoints and radii. Their silhouette lines depend on the view and
  are computed per camera (``Revolution.silhouette``).
* ``circles``: free circular edges (``Circle``: centre, plane normal, radius), e.g. the ViSP
  ``.cao`` circles block. They are edges only (no surface) and are always drawn.

Hidden lines: for a convex object an edge is visible when one of its faces faces the camera;
this is what ``wireframe`` computes (exact for convex objects, back-face culling otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .geometry import as_points
from .transforms import transform_points

__all__ = ["Revolution", "Circle", "BRep", "Wireframe"]


@dataclass(frozen=True)
class Revolution:
    """A cylinder or cone (frustum) in the object frame.

    p0, p1 : array, shape (3,), axis endpoints (metres). r0, r1 : radii at p0 and p1 (metres);
    equal for a cylinder, one may be 0 for a full cone.
    """

    p0: np.ndarray
    p1: np.ndarray
    r0: float
    r1: float

    def __post_init__(self):
        p0 = np.asarray(self.p0, dtype=float).reshape(3)
        p1 = np.asarray(self.p1, dtype=float).reshape(3)
        if not (np.all(np.isfinite(p0)) and np.all(np.isfinite(p1))):
            raise ValueError("a solid of revolution's axis endpoints must be finite")
        if np.linalg.norm(p1 - p0) <= 1e-12:
            raise ValueError("a solid of revolution needs two distinct axis endpoints")
        if not (self.r0 >= 0 and self.r1 >= 0) or self.r0 + self.r1 <= 0:
            raise ValueError(f"radii must be non-negative and not both zero, got {self.r0}, {self.r1}")
        object.__setattr__(self, "p0", p0)
        object.__setattr__(self, "p1", p1)
        object.__setattr__(self, "r0", float(self.r0))
        object.__setattr__(self, "r1", float(self.r1))

    @property
    def axis(self) -> np.ndarray:
        """Unit axis direction p0 → p1, shape (3,)."""
        a = self.p1 - self.p0
        return a / np.linalg.norm(a)

    @property
    def height(self) -> float:
        """Length of the axis, metres."""
        return float(np.linalg.norm(self.p1 - self.p0))

    @property
    def is_cylinder(self) -> bool:
        return abs(self.r0 - self.r1) <= 1e-12

    def _radial_basis(self) -> tuple[np.ndarray, np.ndarray]:
        a = self.axis
        e1 = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        e1 /= np.linalg.norm(e1)
        return e1, np.cross(a, e1)

    def rim(self, which: int, n: int = 48) -> np.ndarray:
        """Closed polyline (n + 1, 3) of the rim circle at p0 (which=0) or p1 (which=1), obj frame."""
        e1, e2 = self._radial_basis()
        th = np.linspace(0.0, 2.0 * np.pi, n + 1)
        centre, r = (self.p0, self.r0) if which == 0 else (self.p1, self.r1)
        return centre + r * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)

    def silhouette(self, center_obj: np.ndarray) -> np.ndarray:
        """The two contour generators seen from an optical centre (3,) in the object frame.

        Returns array, shape (2, 2, 3): two segments (from the p0 rim to the p1 rim), or shape
        (0, 2, 3) when the centre is inside the surface's extension (no silhouette).
        The lateral surface's outward normal at angle θ is ``h·e(θ) + (r0 − r1)·a``; a generator
        is on the contour when its tangent plane passes through the centre: ``e·w = k`` with
        w the centre's radial offset and ``k = r0 − (r0 − r1)·q_a / h``.
        """
        a = self.axis
        h = self.height
        q = np.asarray(center_obj, dtype=float) - self.p0
        q_a = float(q @ a)
        w = q - q_a * a
        D = float(np.linalg.norm(w))
        k = self.r0 - (self.r0 - self.r1) * q_a / h
        if D <= abs(k) or D < 1e-12:
            return np.zeros((0, 2, 3))
        w_hat = w / D
        b_hat = np.cross(a, w_hat)
        c = k / D
        s = np.sqrt(max(0.0, 1.0 - c * c))
        out = []
        for sign in (1.0, -1.0):
            e = c * w_hat + sign * s * b_hat
            out.append([self.p0 + self.r0 * e, self.p1 + self.r1 * e])
        return np.array(out)

    def lateral_normal(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Radial unit vectors e(θ) (N, 3) and outward lateral normals (N, 3) (unnormalised)."""
        e1, e2 = self._radial_basis()
        e = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
        return e, self.height * e + (self.r0 - self.r1) * self.axis

    def triangles(self, n: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """Closed triangle mesh (vertices (2n + 2, 3), triangles (4n, 3)), outward-facing."""
        e1, e2 = self._radial_basis()
        th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        ring = np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2
        V = np.vstack([self.p0 + self.r0 * ring, self.p1 + self.r1 * ring, self.p0, self.p1])
        i = np.arange(n)
        j = (i + 1) % n
        c0, c1 = 2 * n, 2 * n + 1
        side = np.vstack([np.column_stack([i, j, n + j]), np.column_stack([i, n + j, n + i])])
        bottom = np.column_stack([np.full(n, c0), j, i])
        top = np.column_stack([np.full(n, c1), n + i, n + j])
        return V, np.vstack([side, bottom, top]).astype(np.int64)

    def to_dict(self) -> dict[str, Any]:
        return {"p0": self.p0.tolist(), "p1": self.p1.tolist(), "r0": self.r0, "r1": self.r1}


@dataclass(frozen=True)
class Circle:
    """A circular edge in the object frame.

    centre : array, shape (3,), metres. normal : array, shape (3,), unit normal of the circle's
    plane (normalised on construction). radius : metres, > 0.
    """

    centre: np.ndarray
    normal: np.ndarray
    radius: float

    def __post_init__(self):
        c = np.asarray(self.centre, dtype=float).reshape(3)
        n = np.asarray(self.normal, dtype=float).reshape(3)
        norm = float(np.linalg.norm(n))
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(n))) or norm <= 1e-12:
            raise ValueError(f"a circle needs a finite centre and a non-zero normal, got {c}, {n}")
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"a circle's radius must be positive, got {self.radius}")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "normal", n / norm)
        object.__setattr__(self, "radius", float(self.radius))

    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors (3,), (3,) spanning the circle's plane (e1 × e2 = normal)."""
        n = self.normal
        e1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
        e1 /= np.linalg.norm(e1)
        return e1, np.cross(n, e1)

    def polyline(self, n: int = 48) -> np.ndarray:
        """Closed polyline (n + 1, 3) on the circle, object frame."""
        e1, e2 = self.basis()
        th = np.linspace(0.0, 2.0 * np.pi, n + 1)
        return self.centre + self.radius * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)

    def to_dict(self) -> dict[str, Any]:
        return {"centre": self.centre.tolist(), "normal": self.normal.tolist(), "radius": self.radius}


@dataclass(frozen=True)
class Wireframe:
    """What the overlay draws for one object in one view, in world coordinates.

    segments : array, shape (K, 2, 3), world points. visible : array, shape (K,), bool.
    edge_index : array, shape (K,), the model edge each segment is (−1 for silhouettes and rims).
    kind : array, shape (K,), of str: "edge", "silhouette" or "rim".
    """

    segments: np.ndarray
    visible: np.ndarray
    edge_index: np.ndarray
    kind: np.ndarray


@dataclass(frozen=True)
class BRep:
    """Boundary representation of an object in its own frame (metres).

    vertices : array, shape (V, 3). edges : array, shape (E, 2), int. faces : tuple of vertex
    loops (tuples of int), counter-clockwise seen from outside. solids : tuple of Revolution.
    circles : tuple of Circle (free circular edges).
    """

    vertices: np.ndarray
    edges: np.ndarray
    faces: tuple = ()
    solids: tuple = ()
    circles: tuple = ()
    _edge_faces: tuple = field(default=(), repr=False, compare=False)

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
        solids = tuple(self.solids)
        if not all(isinstance(s, Revolution) for s in solids):
            raise ValueError("solids must be Revolution instances")
        circles = tuple(self.circles)
        if not all(isinstance(c, Circle) for c in circles):
            raise ValueError("circles must be Circle instances")
        if len(V) == 0 and not solids and not circles:
            raise ValueError("a model needs vertices, a solid of revolution or a circle")
        V.setflags(write=False)
        E.setflags(write=False)
        object.__setattr__(self, "vertices", V)
        object.__setattr__(self, "edges", E)
        object.__setattr__(self, "faces", faces)
        object.__setattr__(self, "solids", solids)
        object.__setattr__(self, "circles", circles)
        # Which faces each edge borders (for hidden-line removal).
        lookup: dict[tuple[int, int], list[int]] = {}
        for k, f in enumerate(faces):
            for a, b in zip(f, f[1:] + f[:1]):
                lookup.setdefault((min(a, b), max(a, b)), []).append(k)
        object.__setattr__(self, "_edge_faces", tuple(tuple(lookup.get((min(a, b), max(a, b)), ())) for a, b in E))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_faces(cls, vertices: np.ndarray, faces, solids=()) -> BRep:
        """Model whose edges are the sides of its faces (each shared side once)."""
        seen: dict[tuple[int, int], None] = {}
        for f in faces:
            f = tuple(int(i) for i in f)
            for a, b in zip(f, f[1:] + f[:1]):
                seen.setdefault((min(a, b), max(a, b)), None)
        return cls(vertices, np.array(list(seen), dtype=np.int64).reshape(-1, 2), tuple(faces), tuple(solids))

    @classmethod
    def box(cls, size_x: float, size_y: float, size_z: float) -> BRep:
        """Rectangular box with its frame at the centre of its bottom face, z up (lies on z = 0)."""
        if min(size_x, size_y, size_z) <= 0:
            raise ValueError(f"box sizes must be positive, got {size_x}, {size_y}, {size_z}")
        x, y = size_x / 2.0, size_y / 2.0
        V = np.array(
            [
                [-x, -y, 0],
                [x, -y, 0],
                [x, y, 0],
                [-x, y, 0],
                [-x, -y, size_z],
                [x, -y, size_z],
                [x, y, size_z],
                [-x, y, size_z],
            ],
            dtype=float,
        )
        faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
        return cls.from_faces(V, faces)

    @classmethod
    def prism(cls, base_xy: np.ndarray, height: float) -> BRep:
        """Right prism over a convex polygon base_xy (N, 2) (counter-clockwise seen from +z) on z = 0."""
        B = np.asarray(base_xy, dtype=float)
        n = len(B)
        if B.shape != (n, 2) or n < 3 or height <= 0:
            raise ValueError("a prism needs a base of ≥ 3 (x, y) points and a positive height")
        V = np.vstack([np.column_stack([B, np.zeros(n)]), np.column_stack([B, np.full(n, height)])])
        faces = [tuple(range(n - 1, -1, -1)), tuple(range(n, 2 * n))]
        faces += [(i, (i + 1) % n, n + (i + 1) % n, n + i) for i in range(n)]
        return cls.from_faces(V, faces)

    @classmethod
    def pyramid(cls, base_xy: np.ndarray, apex: np.ndarray) -> BRep:
        """Pyramid over a convex polygon base_xy (N, 2) on z = 0 (counter-clockwise from +z) with an apex (3,)."""
        B = np.asarray(base_xy, dtype=float)
        n = len(B)
        if B.shape != (n, 2) or n < 3 or float(np.asarray(apex)[2]) <= 0:
            raise ValueError("a pyramid needs a base of ≥ 3 (x, y) points and an apex above it")
        V = np.vstack([np.column_stack([B, np.zeros(n)]), np.asarray(apex, dtype=float).reshape(1, 3)])
        faces = [tuple(range(n - 1, -1, -1))] + [(i, (i + 1) % n, n) for i in range(n)]
        return cls.from_faces(V, faces)

    @classmethod
    def cylinder(cls, radius: float, height: float) -> BRep:
        """Cylinder standing on z = 0, axis along +z through the frame's origin."""
        return cls.cone(radius, radius, height)

    @classmethod
    def cone(cls, radius_bottom: float, radius_top: float, height: float) -> BRep:
        """Cone or frustum standing on z = 0, axis along +z through the frame's origin."""
        if height <= 0:
            raise ValueError(f"height must be positive, got {height}")
        return cls(
            np.zeros((0, 3)),
            np.zeros((0, 2), dtype=np.int64),
            (),
            (Revolution([0, 0, 0], [0, 0, height], radius_bottom, radius_top),),
        )

    # ------------------------------------------------------------------ queries
    def edge_segments(self, T_world_obj: np.ndarray | None = None) -> np.ndarray:
        """Edges as segments (E, 2, 3), in the object frame or, given ``T_world_obj``, in the world."""
        S = self.vertices[self.edges]
        if T_world_obj is not None:
            S = transform_points(T_world_obj, S.reshape(-1, 3)).reshape(-1, 2, 3)
        return S

    def edge_faces(self, k: int) -> tuple[int, ...]:
        """Indices of the faces that edge k borders."""
        return self._edge_faces[k]

    def _cached(self, name: str, compute):
        """A pose-independent array computed once per model (the model is immutable)."""
        value = self.__dict__.get(name)
        if value is None:
            value = compute()
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        return value

    def face_normals(self) -> np.ndarray:
        """Outward unit normals (F, 3) by Newell's method (robust for non-planar loops)."""
        return self._cached("_face_normals", self._compute_face_normals).copy()

    def _compute_face_normals(self) -> np.ndarray:
        out = np.zeros((len(self.faces), 3))
        tri = np.fromiter((len(f) == 3 for f in self.faces), dtype=bool, count=len(self.faces))
        if tri.any():  # a mesh's triangles at once, summed and normalised as the loop below does
            P = self.vertices[np.array([f for f, t in zip(self.faces, tri) if t], dtype=np.int64)]
            Q = np.roll(P, -1, axis=1)
            n = np.stack(
                [
                    (P[..., 1] - Q[..., 1]) * (P[..., 2] + Q[..., 2]),
                    (P[..., 2] - Q[..., 2]) * (P[..., 0] + Q[..., 0]),
                    (P[..., 0] - Q[..., 0]) * (P[..., 1] + Q[..., 1]),
                ],
                axis=-1,
            ).sum(axis=1)
            out[tri] = [v / max(np.linalg.norm(v), 1e-300) for v in n]
        for k in np.flatnonzero(~tri):
            f = self.faces[k]
            P = self.vertices[list(f)]
            Q = np.roll(P, -1, axis=0)
            n = np.array(
                [
                    np.sum((P[:, 1] - Q[:, 1]) * (P[:, 2] + Q[:, 2])),
                    np.sum((P[:, 2] - Q[:, 2]) * (P[:, 0] + Q[:, 0])),
                    np.sum((P[:, 0] - Q[:, 0]) * (P[:, 1] + Q[:, 1])),
                ]
            )
            out[k] = n / max(np.linalg.norm(n), 1e-300)
        return out

    def face_centroids(self) -> np.ndarray:
        """Centroids (F, 3) of the faces' vertex loops."""
        return self._cached("_face_centroids", self._compute_face_centroids).copy()

    def _compute_face_centroids(self) -> np.ndarray:
        out = np.zeros((len(self.faces), 3))
        tri = np.fromiter((len(f) == 3 for f in self.faces), dtype=bool, count=len(self.faces))
        if tri.any():
            out[tri] = self.vertices[np.array([f for f, t in zip(self.faces, tri) if t], dtype=np.int64)].mean(axis=1)
        for k in np.flatnonzero(~tri):
            out[k] = self.vertices[list(self.faces[k])].mean(axis=0)
        return out

    def _edge_face_pairs(self) -> np.ndarray:
        """(M, 2) int: every (edge, face it borders) pair, edges in order (for vectorised visibility)."""

        def compute():
            pairs = [(k, f) for k, fs in enumerate(self._edge_faces) for f in fs]
            return np.array(pairs, dtype=np.int64).reshape(-1, 2)

        return self._cached("_edge_face_pairs_", compute)

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2, 3) in the object frame: (min, max)."""
        pts = [self.vertices] + [np.vstack([s.rim(0, 16), s.rim(1, 16)]) for s in self.solids]
        pts += [c.polyline(16) for c in self.circles]
        P = np.vstack([p for p in pts if len(p)])
        return np.array([P.min(axis=0), P.max(axis=0)])

    def triangles(self, n_circle: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """Triangle mesh of the whole model in the object frame: vertices (M, 3), triangles (T, 3).

        Faces are fan-triangulated (convex faces); solids are tessellated with ``n_circle`` sides.
        """
        Vs = [self.vertices]
        Ts = []
        for f in self.faces:
            Ts += [(f[0], f[i], f[i + 1]) for i in range(1, len(f) - 1)]
        Ts = [np.array(Ts, dtype=np.int64).reshape(-1, 3)]
        offset = len(self.vertices)
        for s in self.solids:
            V, T = s.triangles(n_circle)
            Vs.append(V)
            Ts.append(T + offset)
            offset += len(V)
        return np.vstack(Vs), np.vstack(Ts)

    def transformed(self, T_new_obj: np.ndarray) -> BRep:
        """The same model with its vertices mapped by ``T_new_obj`` (e.g. to bake a pose)."""
        R, t = T_new_obj[:3, :3], T_new_obj[:3, 3]
        solids = tuple(Revolution(R @ s.p0 + t, R @ s.p1 + t, s.r0, s.r1) for s in self.solids)
        circles = tuple(Circle(R @ c.centre + t, R @ c.normal, c.radius) for c in self.circles)
        V = transform_points(T_new_obj, self.vertices) if len(self.vertices) else self.vertices
        return BRep(V, self.edges, self.faces, solids, circles)

    def wireframe(self, center_world: np.ndarray, T_world_obj: np.ndarray, n_circle: int = 48) -> Wireframe:
        """Segments to draw from an optical centre (3,), world frame, with their visibility.

        Polyhedral edges: visible when a bordering face faces the centre (edges with no face
        are always visible). Solids: the two silhouette generators (visible) and the rim
        circles, each piece visible when its cap or the lateral surface next to it faces the centre.
        Free circles (``circles``) are drawn as "rim" segments, always visible (they bound no face).
        """
        T = np.asarray(T_world_obj, dtype=float)
        c_obj = (np.asarray(center_world, dtype=float) - T[:3, 3]) @ T[:3, :3]
        segs, vis, idx, kind = [], [], [], []
        if len(self.edges):
            if len(self.faces):
                normals = self._cached("_face_normals", self._compute_face_normals)
                cents = self._cached("_face_centroids", self._compute_face_centroids)
                facing = np.einsum("ij,ij->i", normals, c_obj - cents) > 0
            else:
                facing = np.zeros(0, bool)
            # an edge is visible when it borders no face or one of its faces faces the centre
            pairs = self._edge_face_pairs()
            has_face = np.bincount(pairs[:, 0], minlength=len(self.edges)) > 0
            seen = np.bincount(pairs[:, 0], weights=facing[pairs[:, 1]], minlength=len(self.edges)) > 0
            vis += (~has_face | seen).tolist()
            segs.append(self.edge_segments())
            idx += list(range(len(self.edges)))
            kind += ["edge"] * len(self.edges)
        for s in self.solids:
            sil = s.silhouette(c_obj)
            if len(sil):
                segs.append(sil)
                vis += [True] * len(sil)
                idx += [-1] * len(sil)
                kind += ["silhouette"] * len(sil)
            th = np.linspace(0.0, 2.0 * np.pi, n_circle + 1)
            e, lat_n = s.lateral_normal(th)
            for _which, (centre, r, cap_n) in enumerate(((s.p0, s.r0, -s.axis), (s.p1, s.r1, s.axis))):
                if r <= 0:
                    continue
                P = centre + r * e
                cap_facing = float(cap_n @ (c_obj - centre)) > 0
                lat_facing = np.einsum("ij,ij->i", lat_n, c_obj - P) > 0
                seg = np.stack([P[:-1], P[1:]], axis=1)
                segs.append(seg)
                vis += list(cap_facing | (lat_facing[:-1] & lat_facing[1:]))
                idx += [-1] * len(seg)
                kind += ["rim"] * len(seg)
        for c in self.circles:
            P = c.polyline(n_circle)
            segs.append(np.stack([P[:-1], P[1:]], axis=1))
            vis += [True] * n_circle
            idx += [-1] * n_circle
            kind += ["rim"] * n_circle
        if not segs:
            return Wireframe(np.zeros((0, 2, 3)), np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0, dtype="<U10"))
        S = np.vstack(segs)
        S = transform_points(T, S.reshape(-1, 3)).reshape(-1, 2, 3)
        return Wireframe(S, np.array(vis, bool), np.array(idx, np.int64), np.array(kind, dtype="<U10"))

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (lists of floats and ints); "circles" only when there are some."""
        d = {
            "vertices": self.vertices.tolist(),
            "edges": self.edges.tolist(),
            "faces": [list(f) for f in self.faces],
            "solids": [s.to_dict() for s in self.solids],
        }
        if self.circles:
            d["circles"] = [c.to_dict() for c in self.circles]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BRep:
        """Inverse of ``to_dict``; ValueError naming the field on bad input."""
        try:
            solids = tuple(Revolution(s["p0"], s["p1"], s["r0"], s["r1"]) for s in d.get("solids", []))
            circles = tuple(Circle(c["centre"], c["normal"], c["radius"]) for c in d.get("circles", []))
            return cls(
                np.asarray(d.get("vertices", []), dtype=float).reshape(-1, 3),
                np.asarray(d.get("edges", []), dtype=np.int64).reshape(-1, 2),
                tuple(tuple(f) for f in d.get("faces", [])),
                solids,
                circles,
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"malformed model description: {exc!r}") from exc

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, BRep):
            return NotImplemented
        return (
            np.array_equal(self.vertices, other.vertices)
            and np.array_equal(self.edges, other.edges)
            and self.faces == other.faces
            and len(self.solids) == len(other.solids)
            and all(
                np.array_equal(a.p0, b.p0) and np.array_equal(a.p1, b.p1) and a.r0 == b.r0 and a.r1 == b.r1
                for a, b in zip(self.solids, other.solids)
            )
            and len(self.circles) == len(other.circles)
            and all(
                np.array_equal(a.centre, b.centre) and np.array_equal(a.normal, b.normal) and a.radius == b.radius
                for a, b in zip(self.circles, other.circles)
            )
        )

    __hash__ = None  # mutable-looking arrays: not hashable
