"""URDF's geometry elements as link shapes (``LinkShape``): B-Reps placed in the link's frame.

URDF centres its primitives on the geometry's origin (a box on its centre, a cylinder on the middle
of its axis, along z); ``BRep.box`` and ``BRep.cylinder`` stand on z = 0 with their frame at the
centre of the bottom face. So a URDF box of height h at ``T_link_geom`` is ``BRep.box`` at
``T_link_geom @ (0, 0, −h/2)``, and likewise a cylinder of length L at ``(0, 0, −L/2)``.
"""

from __future__ import annotations

import numpy as np

from ..brep import BRep, Sphere
from ..transforms import check_T
from .model import LinkShape

__all__ = ["box_shape", "cylinder_shape", "sphere_shape", "mesh_shape"]


def _lowered(T_link_geom: np.ndarray, dz: float) -> np.ndarray:
    T = check_T(T_link_geom, "T_link_geom").copy()
    T[:3, 3] -= dz * T[:3, 2]
    return T


def box_shape(size, T_link_geom: np.ndarray) -> LinkShape:
    """A URDF box of ``size`` (3,) metres centred at ``T_link_geom`` (4, 4)."""
    sx, sy, sz = (float(v) for v in np.asarray(size, dtype=float).reshape(3))
    return LinkShape(BRep.box(sx, sy, sz), _lowered(T_link_geom, sz / 2.0))


def cylinder_shape(radius: float, length: float, T_link_geom: np.ndarray) -> LinkShape:
    """A URDF cylinder (axis along the geometry's z, centred) at ``T_link_geom`` (4, 4)."""
    if not (radius > 0 and length > 0):
        raise ValueError(f"a cylinder needs a positive radius and length, got {radius}, {length}")
    return LinkShape(BRep.cylinder(float(radius), float(length)), _lowered(T_link_geom, float(length) / 2.0))


def sphere_shape(radius: float, T_link_geom: np.ndarray) -> LinkShape:
    """A URDF sphere centred at ``T_link_geom`` (4, 4)."""
    model = BRep(np.zeros((0, 3)), np.zeros((0, 2), dtype=np.int64), (), (Sphere(np.zeros(3), float(radius)),))
    return LinkShape(model, check_T(T_link_geom, "T_link_geom"))


def mesh_shape(brep: BRep, T_link_geom: np.ndarray, scale=(1.0, 1.0, 1.0)) -> LinkShape:
    """A mesh model (its file's frame is the geometry's origin) scaled by ``scale`` (3,), at ``T_link_geom``."""
    s = np.asarray(scale, dtype=float).reshape(3)
    if not np.all(s > 0):
        raise ValueError(f"a mesh's scale must be positive, got {s}")
    if not np.allclose(s, 1.0):
        if brep.solids or brep.circles:
            raise ValueError("only a polyhedral mesh model can be scaled")
        brep = BRep(brep.vertices * s, brep.edges, brep.faces)
    return LinkShape(brep, check_T(T_link_geom, "T_link_geom"))
