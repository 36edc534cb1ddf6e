"""What every primitive of a B-Rep model answers (``Primitive``), and the plain data it answers with.

A model (``core.brep.BRep``) is a list of primitives in one object frame: its polyhedral part
(vertices, edges, faces: boxes, prisms, imported meshes), solids of revolution, spheres, free circles.
Each primitive implements every per-kind behaviour once — ray cast, outline (edges, silhouettes and
rims seen from a point), edge samples for the image search, triangles, its ``.cao`` records, its
stored form — so a model, a renderer or a search loops over its primitives and never asks their kind.

All geometry is in the object frame (metres). A new primitive is one class that satisfies
``Primitive`` plus one line in ``core.primitives.KINDS``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol, Self, runtime_checkable

import numpy as np

__all__ = [
    "Primitive",
    "Outline",
    "CaoPart",
    "SampleGroup",
    "circle_basis",
    "closed_curve_outline",
    "join_outlines",
    "no_hits",
    "same_arrays",
]

# One group of edge samples at N poses: points X and tangents D, (M, 3) shared by the poses or
# (N, M, 3) per pose, and which are seen at each pose, (N, M) bool.
SampleGroup = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class Outline:
    """What one primitive draws seen from one point, in the object frame.

    segments : array, shape (K, 2, 3), metres. visible : array, shape (K,), bool (hidden-line rule
    of the primitive). kind : array, shape (K,), str: "edge" (a model edge), "silhouette" (a contour
    generator, view-dependent), "rim" (the edge of a solid's flat cap) or "circle" (a free circle).
    edge : array, shape (K,), int, the polyhedral edge index (−1 for anything else). feature :
    array, shape (K,), int in [0, n_features), an id stable across views (a tracker keys an edge's
    polarity on it). chord : array, shape (K,), int, −1 for a straight segment, else the segment's
    index along its closed curve (a rim, a circle, a sphere's outline), whose chords have the
    consecutive features ``feature − chord`` onwards. n_features : how many ids the primitive uses.
    """

    segments: np.ndarray
    visible: np.ndarray
    kind: np.ndarray
    edge: np.ndarray
    feature: np.ndarray
    chord: np.ndarray
    n_features: int

    def subset(self, mask: np.ndarray) -> Outline:
        """The segments where mask (K,) is True; the ids keep their meaning (n_features unchanged)."""
        return Outline(
            self.segments[mask],
            self.visible[mask],
            self.kind[mask],
            self.edge[mask],
            self.feature[mask],
            self.chord[mask],
            self.n_features,
        )

    @classmethod
    def empty(cls, n_features: int = 0) -> Outline:
        return cls(
            np.zeros((0, 2, 3)),
            np.zeros(0, bool),
            np.zeros(0, dtype="<U10"),
            np.zeros(0, np.int64),
            np.zeros(0, np.int64),
            np.zeros(0, np.int64),
            n_features,
        )


@dataclass(frozen=True)
class CaoPart:
    """A primitive's contribution to a ViSP ``.cao`` file, indices local to its own ``points``.

    points : array, shape (P, 3), metres. lines : array, shape (L, 2), int, point pairs written as
    "3D lines". faces : tuple of point loops written as "faces from 3D points". cylinders : tuple of
    (i, j, radius): axis ends and radius. circles : tuple of (radius, centre, i, j): two rim points
    spanning the plane.
    """

    points: np.ndarray
    lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    faces: tuple = ()
    cylinders: tuple = ()
    circles: tuple = ()


@runtime_checkable
class Primitive(Protocol):
    """One kind of part of a model, in the object frame (see the module docstring).

    kind : the tag of its stored form. surface : True when it bounds a volume (it casts rays and
    is drawn as a solid's surface), False for an edge alone (a free circle). n_labels : how many
    surface labels its ``ray_cast`` uses (its faces; 0 without a surface).
    """

    kind: ClassVar[str]
    surface: ClassVar[bool]

    @property
    def n_labels(self) -> int: ...

    def ray_cast(self, o_obj: np.ndarray, d_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest hits of rays ``o_obj + t·d`` (origin (3,), directions (N, 3), any length), t > 0.

        Returns t (N,) (inf for a miss), label (N,) int in [0, n_labels) (−1 for a miss) and the
        outward unit normal (N, 3) (0 for a miss). From inside, the surface met on the way out.
        """
        ...

    def outline(self, center_obj: np.ndarray, n_circle: int = 48) -> Outline:
        """Its edges, silhouettes and rims seen from the point (3,), curves as ``n_circle`` chords."""
        ...

    def edge_samples(self, centers_obj: np.ndarray, per_edge: int, n_rim: int) -> list[SampleGroup]:
        """Points on its outline for the image search, seen from each of N points (N, 3) at once:
        ``per_edge`` along each straight edge or silhouette line, ``n_rim`` around each circle."""
        ...

    def triangles(self, n_circle: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """Its surface as triangles: vertices (M, 3), triangles (T, 3) int, outward-facing."""
        ...

    def cao_part(self) -> CaoPart:
        """Its ``.cao`` records; ValueError naming what to export instead when the format has none."""
        ...

    def bounds(self) -> np.ndarray | None:
        """Exact axis-aligned bounds (2, 3): (min, max); None when it holds no point."""
        ...

    def support_points(self, n: int = 48, min_radius: float = 0.0) -> np.ndarray:
        """Points (P, 3) whose convex hull is its shape's (curves as ``n`` points; radii at least
        ``min_radius``, so that a cone's apex still spans a volume)."""
        ...

    def plane_normals(self) -> np.ndarray:
        """Outward normals (F, 3) of its flat faces (a face or a cap it could rest on)."""
        ...

    def turn_invariant(self, axis_obj: np.ndarray) -> bool:
        """True when any turn about the line through the frame's origin along ``axis_obj`` (3,), unit,
        leaves it unchanged (its heading about that line cannot be seen)."""
        ...

    def transformed(self, T_new_obj: np.ndarray) -> Self:
        """The same primitive mapped by the rigid transform ``T_new_obj`` (4, 4)."""
        ...

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; ``from_dict`` reads it back."""
        ...

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Self: ...


def circle_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,), (3,) spanning the plane of unit ``normal`` (e1 × e2 = normal)."""
    n = np.asarray(normal, dtype=float).reshape(3)
    e1 = _cross3(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    e1 /= np.linalg.norm(e1)
    return e1, _cross3(n, e1)


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of two 3-vectors (np.cross costs ~20 µs a call for one pair: a third of drawing a cylinder once)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def closed_curve_outline(P: np.ndarray, visible: np.ndarray, kind: str, first_feature: int) -> Outline:
    """The chords of a closed polyline P (n + 1, 3) (last point = first) as an ``Outline``.

    visible : (n,) bool per chord. Features ``first_feature + chord``; n_features is theirs' end.
    """
    n = len(P) - 1
    chord = np.arange(n)
    return Outline(
        np.stack([P[:-1], P[1:]], axis=1),
        np.asarray(visible, bool),
        np.full(n, kind, dtype="<U10"),
        np.full(n, -1, np.int64),
        first_feature + chord,
        chord,
        first_feature + n,
    )


def no_hits(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ray_cast``'s answer for n rays that meet nothing."""
    return np.full(n, np.inf), np.full(n, -1, np.int64), np.zeros((n, 3))


def join_outlines(outlines: list[Outline]) -> Outline:
    """Several outlines as one: features offset so each keeps its own ids (n_features summed)."""
    outlines = [o for o in outlines if o.n_features]  # no ids: no segments and no offset
    if not outlines:
        return Outline.empty()
    if len(outlines) == 1:
        return outlines[0]
    offsets = np.cumsum([0] + [o.n_features for o in outlines])
    return Outline(
        np.concatenate([o.segments.reshape(-1, 2, 3) for o in outlines]),
        np.concatenate([o.visible for o in outlines]),
        np.concatenate([o.kind.astype("<U10") for o in outlines]),
        np.concatenate([o.edge for o in outlines]),
        np.concatenate([o.feature + k for o, k in zip(outlines, offsets)]),
        np.concatenate([o.chord for o in outlines]),
        int(offsets[-1]),
    )


def same_arrays(a: Any, b: Any, names: tuple[str, ...]) -> bool:
    """Exact equality of the named fields of two primitives of one type (arrays compared whole)."""
    return type(a) is type(b) and all(np.array_equal(getattr(a, k), getattr(b, k)) for k in names)
