"""The B-Rep model of an object: what the database stores, the overlay draws and the solvers use.

A model lives in its own frame ``obj`` (metres); its pose in the site is ``T_world_obj``. It is a
list of primitives (``core.primitives``), each of which draws, casts rays, tessellates, samples its
edges and writes itself; the model loops over them (``parts``) and never asks their kind:

* its polyhedral part (``Polyhedron``): ``vertices`` (V, 3), ``edges`` (E, 2) vertex indices,
  ``faces``: vertex loops, counter-clockwise seen from outside (their right-hand normal points out).
  An imported mesh is this part too: its curved regions are faces whose sides are not edges.
* ``solids``: analytic solids — solids of revolution (``Revolution``: a cylinder, or a cone/frustum
  with two radii) and spheres (``Sphere``). Their silhouettes depend on the view and are computed
  per camera.
* ``circles``: free circular edges (``Circle``: centre, plane normal, radius), e.g. the ViSP
  ``.cao`` circles block. They are edges only (no surface) and are always drawn.

Hidden lines: for a convex object an edge is visible when one of its faces faces the camera;
this is what ``wireframe`` computes (exact for convex objects, back-face culling otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .primitives import Circle, Outline, Polyhedron, Primitive, Revolution, Sphere, join_outlines, primitive_from_dict
from .transforms import transform_points

__all__ = ["Revolution", "Circle", "Sphere", "Polyhedron", "BRep", "Wireframe"]


@dataclass(frozen=True)
class Wireframe:
    """What the overlay draws for one object in one view, in world coordinates.

    segments : array, shape (K, 2, 3), world points. visible : array, shape (K,), bool.
    edge_index : array, shape (K,), the model edge each segment is (−1 for silhouettes and rims).
    kind : array, shape (K,), of str: "edge", "silhouette", "rim" (a solid's cap) or "circle" (a free
    circle). feature : array, shape (K,), int, an id stable across views (``Outline.feature``, the
    parts' ids one after the other). chord : array, shape (K,), int, −1 for a straight segment, else
    its index along its closed curve (``Outline.chord``).
    """

    segments: np.ndarray
    visible: np.ndarray
    edge_index: np.ndarray
    kind: np.ndarray
    feature: np.ndarray
    chord: np.ndarray


@dataclass(frozen=True)
class BRep:
    """Boundary representation of an object in its own frame (metres).

    vertices : array, shape (V, 3). edges : array, shape (E, 2), int. faces : tuple of vertex
    loops (tuples of int), counter-clockwise seen from outside. solids : tuple of solid primitives
    (``Revolution``, ``Sphere``: primitives with a surface). circles : tuple of edge-only primitives
    (``Circle``).
    """

    vertices: np.ndarray
    edges: np.ndarray
    faces: tuple = ()
    solids: tuple = ()
    circles: tuple = ()

    def __post_init__(self):
        poly = Polyhedron(self.vertices, self.edges, self.faces)
        solids = tuple(self.solids)
        if not all(isinstance(s, Primitive) and s.surface for s in solids):
            raise ValueError("solids must be primitives with a surface (Revolution, Sphere)")
        circles = tuple(self.circles)
        if not all(isinstance(c, Primitive) and not c.surface for c in circles):
            raise ValueError("circles must be edge primitives (Circle)")
        if len(poly.vertices) == 0 and not solids and not circles:
            raise ValueError("a model needs vertices, a solid or a circle")
        object.__setattr__(self, "vertices", poly.vertices)
        object.__setattr__(self, "edges", poly.edges)
        object.__setattr__(self, "faces", poly.faces)
        object.__setattr__(self, "solids", solids)
        object.__setattr__(self, "circles", circles)
        object.__setattr__(self, "_parts", (poly, *solids, *circles))

    @property
    def polyhedron(self) -> Polyhedron:
        """The polyhedral part (vertices, edges, faces; empty for a model of solids alone)."""
        return self._parts[0]

    @property
    def parts(self) -> tuple[Primitive, ...]:
        """Every primitive of the model: the polyhedral part first (possibly empty), the solids, the circles."""
        return self._parts

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
        return self.polyhedron.edge_faces()[k]

    def face_normals(self) -> np.ndarray:
        """Outward unit normals (F, 3) by Newell's method (robust for non-planar loops); a copy."""
        return self.polyhedron.face_normals().copy()

    def face_centroids(self) -> np.ndarray:
        """Centroids (F, 3) of the faces' vertex loops; a copy."""
        return self.polyhedron.face_centroids().copy()

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds (2, 3) in the object frame: (min, max), exact for every part."""
        B = np.array([b for b in (p.bounds() for p in self.parts) if b is not None])
        return np.array([B[:, 0].min(axis=0), B[:, 1].max(axis=0)])

    def support_points(self, n: int = 48, min_radius: float = 0.0) -> np.ndarray:
        """Points (P, 3), object frame, whose convex hull is the model's (``Primitive.support_points``)."""
        pts = [p.support_points(n, min_radius) for p in self.parts]
        return np.vstack([q for q in pts if len(q)]) if any(len(q) for q in pts) else np.zeros((0, 3))

    def plane_normals(self) -> np.ndarray:
        """Outward normals (F, 3) of the model's flat faces and caps (what it can rest on)."""
        return np.vstack([p.plane_normals() for p in self.parts])

    def turn_invariant(self, axis_obj: np.ndarray) -> bool:
        """True when a turn about the line through the origin along ``axis_obj`` (3,), unit, leaves the
        model unchanged (an upright cylinder about its axis)."""
        return all(p.turn_invariant(axis_obj) for p in self.parts)

    def triangles(self, n_circle: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """Triangle mesh of the whole model in the object frame: vertices (M, 3), triangles (T, 3).

        Faces are fan-triangulated (convex faces); curved surfaces are tessellated with ``n_circle`` sides.
        """
        Vs, Ts = [], []
        offset = 0
        for p in self.parts:
            V, T = p.triangles(n_circle)
            Vs.append(np.asarray(V, dtype=float).reshape(-1, 3))
            Ts.append(np.asarray(T, dtype=np.int64).reshape(-1, 3) + offset)
            offset += len(Vs[-1])
        return np.vstack(Vs), np.vstack(Ts)

    def transformed(self, T_new_obj: np.ndarray) -> BRep:
        """The same model with its parts mapped by ``T_new_obj`` (e.g. to bake a pose)."""
        poly, *_ = parts = [p.transformed(T_new_obj) for p in self.parts]
        return BRep(
            poly.vertices,
            poly.edges,
            poly.faces,
            tuple(parts[1 : 1 + len(self.solids)]),
            tuple(parts[1 + len(self.solids) :]),
        )

    def outline(self, center_obj: np.ndarray, n_circle: int = 48, contours: bool = True) -> Outline:
        """Every part's outline seen from a point (3,) in the object frame, one after the other.

        contours : False leaves out the contour generators of a mesh's smooth regions (sides of its
        tessellation, not edges of the object): the polyhedral part then gives its edges alone.
        """
        c = np.asarray(center_obj, dtype=float).reshape(3)
        outlines = [p.outline(c, n_circle) for p in self.parts]
        if not contours:
            outlines[0] = outlines[0].subset(outlines[0].edge >= 0)
        return join_outlines(outlines)

    def wireframe(
        self, center_world: np.ndarray, T_world_obj: np.ndarray, n_circle: int = 48, contours: bool = True
    ) -> Wireframe:
        """Segments to draw from an optical centre (3,), world frame, with their visibility.

        Each part's outline (``Primitive.outline``) in turn: polyhedral edges (visible when a
        bordering face faces the centre; edges with no face always) and the contours of a mesh's
        smooth regions (unless ``contours`` is False); solids' silhouettes (visible) and rims (each
        piece visible when its cap or the lateral surface next to it faces the centre); free
        circles, always visible.
        """
        T = np.asarray(T_world_obj, dtype=float)
        c_obj = (np.asarray(center_world, dtype=float) - T[:3, 3]) @ T[:3, :3]
        o = self.outline(c_obj, n_circle, contours)
        S = transform_points(T, o.segments.reshape(-1, 3)).reshape(-1, 2, 3)
        return Wireframe(S, o.visible, o.edge, o.kind, o.feature, o.chord)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (lists of floats and ints); "circles" only when there are some."""
        d = self.polyhedron.to_dict()
        d["solids"] = [s.to_dict() for s in self.solids]
        if self.circles:
            d["circles"] = [c.to_dict() for c in self.circles]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BRep:
        """Inverse of ``to_dict``; ValueError naming the field on bad input."""
        try:
            poly = Polyhedron.from_dict(d)
            solids = tuple(primitive_from_dict(s, Revolution.kind) for s in d.get("solids", []))
            circles = tuple(primitive_from_dict(c, Circle.kind) for c in d.get("circles", []))
            return cls(poly.vertices, poly.edges, poly.faces, solids, circles)
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"malformed model description: {exc!r}") from exc

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, BRep):
            return NotImplemented
        return len(self.parts) == len(other.parts) and all(a == b for a, b in zip(self.parts, other.parts))

    __hash__ = None  # mutable-looking arrays: not hashable
