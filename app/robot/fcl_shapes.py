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

__all__ = ["FclPart", "fcl_parts"]


@dataclass(frozen=True)
class FclPart:
    """One collision geometry: ``geometry`` (fcl) at ``T_brep_geom`` (4, 4) in the B-Rep's frame, the
    part's bounds (2, 3) in that frame (for the broad phase) and its kind ("box", "cylinder", "cone",
    "sphere", "convex", "mesh")."""

    geometry: object
    T_brep_geom: np.ndarray
    bounds: np.ndarray
    kind: str


def _z_onto(axis: np.ndarray) -> np.ndarray:
    """A rotation taking +z onto the unit vector ``axis``."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, axis)
    s, c = float(np.linalg.norm(v)), float(z @ axis)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * ((1 - c) / s**2)


def _convex(points: np.ndarray) -> tuple[object, str]:
    hull = ConvexHull(points)
    faces = np.hstack([np.full((len(hull.simplices), 1), 3), hull.simplices]).ravel()
    return fcl.Convex(points, len(hull.simplices), faces), "convex"


def _polyhedron(p: Polyhedron) -> tuple[object, np.ndarray, str]:
    V = p.vertices
    lo, hi = V.min(axis=0), V.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    scale = max(float(np.max(hi - lo)), 1e-9)
    off_corner = np.min(np.linalg.norm(V[:, None] - corners[None], axis=2), axis=1)
    if len(V) == 8 and len(p.faces) == 6 and np.all(off_corner < 1e-9 * scale):
        return fcl.Box(*(hi - lo)), make_T(np.eye(3), (lo + hi) / 2.0), "box"
    if p.convex:
        geometry, kind = _convex(V)
        return geometry, np.eye(4), kind
    V_t, T = p.triangles()
    mesh = fcl.BVHModel()
    mesh.beginModel(len(V_t), len(T))
    mesh.addSubModel(np.asarray(V_t, dtype=float), np.asarray(T, dtype=np.int64))
    mesh.endModel()
    return mesh, np.eye(4), "mesh"


def _revolution(s: Revolution) -> tuple[object, np.ndarray, str]:
    R = _z_onto(s.axis)
    if s.is_cylinder:
        return fcl.Cylinder(s.r0, s.height), make_T(R, (s.p0 + s.p1) / 2.0), "cylinder"
    if min(s.r0, s.r1) == 0.0:  # fcl's cone: base at −h/2, apex at +h/2 along its z
        apex, base = (s.p1, s.p0) if s.r1 == 0.0 else (s.p0, s.p1)
        axis = (apex - base) / s.height
        return fcl.Cone(max(s.r0, s.r1), s.height), make_T(_z_onto(axis), (apex + base) / 2.0), "cone"
    geometry, kind = _convex(s.support_points(48))
    return geometry, np.eye(4), kind


def fcl_parts(brep: BRep) -> list[FclPart]:
    """The solid parts of ``brep`` as fcl geometries (see the module docstring); ValueError when it has none."""
    out = []
    for part in brep.parts:
        if not part.surface or part.bounds() is None:
            continue
        if isinstance(part, Polyhedron):
            if not part.faces:
                continue
            geometry, T, kind = _polyhedron(part)
        elif isinstance(part, Revolution):
            geometry, T, kind = _revolution(part)
        elif isinstance(part, Sphere):
            geometry, T, kind = fcl.Sphere(part.radius), make_T(np.eye(3), part.centre), "sphere"
        else:  # a primitive kind added later: its hull
            geometry, kind = _convex(part.support_points(48))
            T = np.eye(4)
        out.append(FclPart(geometry, T, np.asarray(part.bounds(), dtype=float), kind))
    if not out:
        raise ValueError("the model has no solid part (faces, a solid of revolution or a sphere) to collide with")
    return out
