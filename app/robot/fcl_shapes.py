"""B-Rep parts as python-fcl collision geometries, each with its pose in the B-Rep's frame.

A part that is one primitive becomes fcl's own: a polyhedral part that is an axis-aligned box →
``fcl.Box`` (at its centre), a cylinder → ``fcl.Cylinder`` (fcl's is centred on its axis, along z),
a cone with a point → ``fcl.Cone``, a sphere → ``fcl.Sphere``. Other convex parts (a rotated box,
a prism, a frustum) become ``fcl.Convex`` (their hull's faces), and a non-convex mesh an
``fcl.BVHModel`` of its triangles (a mesh is its surface: a shape wholly inside a closed mesh touches
none of its triangles and is not seen; convex parts have no such blind spot). Free circles (edges,
no surface) are not solid and are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np
from scipy.spatial import ConvexHull

from core.brep import BRep
from core.primitives import Polyhedron, Revolution, Sphere
from core.transforms import make_T

__all__ = ["FclPart", "fcl_parts", "make_fcl"]


@dataclass(frozen=True)
class FclPart:
    """One collision geometry: ``geometry`` (fcl) at ``T_brep_geom`` (4, 4) in the B-Rep's frame, the
    part's bounds (2, 3) in that frame (for the broad phase), its kind ("box", "cylinder", "cone",
    "sphere", "convex", "mesh") and the numbers that make it (``params``: the box's sides; radius and
    height; the radius; the hull's points (V, 3) and triangles (T, 3); the mesh's), in its own frame,
    so that another collision library can build the same geometry."""

    geometry: object
    T_brep_geom: np.ndarray
    bounds: np.ndarray
    kind: str
    params: tuple


def _z_onto(axis: np.ndarray) -> np.ndarray:
    """A rotation taking +z onto the unit vector ``axis``."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, axis)
    s, c = float(np.linalg.norm(v)), float(z @ axis)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * ((1 - c) / s**2)


def _hull(points: np.ndarray) -> tuple[str, tuple]:
    hull = ConvexHull(points)
    return "convex", (np.asarray(points, dtype=float), hull.simplices.astype(np.int64))


def _polyhedron(p: Polyhedron) -> tuple[str, tuple, np.ndarray]:
    V = p.vertices
    lo, hi = V.min(axis=0), V.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    scale = max(float(np.max(hi - lo)), 1e-9)
    off_corner = np.min(np.linalg.norm(V[:, None] - corners[None], axis=2), axis=1)
    if len(V) == 8 and len(p.faces) == 6 and np.all(off_corner < 1e-9 * scale):
        return "box", tuple(float(v) for v in hi - lo), make_T(np.eye(3), (lo + hi) / 2.0)
    if p.convex:
        return (*_hull(V), np.eye(4))
    V_t, T = p.triangles()
    return "mesh", (np.asarray(V_t, dtype=float), np.asarray(T, dtype=np.int64)), np.eye(4)


def _revolution(s: Revolution) -> tuple[str, tuple, np.ndarray]:
    if s.is_cylinder:
        return "cylinder", (s.r0, s.height), make_T(_z_onto(s.axis), (s.p0 + s.p1) / 2.0)
    if min(s.r0, s.r1) == 0.0:  # fcl's cone: base at −h/2, apex at +h/2 along its z
        apex, base = (s.p1, s.p0) if s.r1 == 0.0 else (s.p0, s.p1)
        return "cone", (max(s.r0, s.r1), s.height), make_T(_z_onto((apex - base) / s.height), (apex + base) / 2.0)
    return (*_hull(s.support_points(48)), np.eye(4))


def make_fcl(kind: str, params: tuple):
    """The fcl geometry of a part's kind and numbers (``FclPart.params``)."""
    if kind == "box":
        return fcl.Box(*params)
    if kind == "cylinder":
        return fcl.Cylinder(*params)
    if kind == "cone":
        return fcl.Cone(*params)
    if kind == "sphere":
        return fcl.Sphere(*params)
    V, T = params
    if kind == "convex":
        return fcl.Convex(V, len(T), np.hstack([np.full((len(T), 1), 3), T]).ravel())
    mesh = fcl.BVHModel()
    mesh.beginModel(len(V), len(T))
    mesh.addSubModel(V, T)
    mesh.endModel()
    return mesh


def fcl_parts(brep: BRep) -> list[FclPart]:
    """The solid parts of ``brep`` as fcl geometries (see the module docstring); ValueError when it has none."""
    out = []
    for part in brep.parts:
        if not part.surface or part.bounds() is None:
            continue
        if isinstance(part, Polyhedron):
            if not part.faces:
                continue
            kind, params, T = _polyhedron(part)
        elif isinstance(part, Revolution):
            kind, params, T = _revolution(part)
        elif isinstance(part, Sphere):
            kind, params, T = "sphere", (part.radius,), make_T(np.eye(3), part.centre)
        else:  # a primitive kind added later: its hull
            kind, params, T = (*_hull(part.support_points(48)), np.eye(4))
        out.append(FclPart(make_fcl(kind, params), T, np.asarray(part.bounds(), dtype=float), kind, params))
    if not out:
        raise ValueError("the model has no solid part (faces, a solid of revolution or a sphere) to collide with")
    return out
