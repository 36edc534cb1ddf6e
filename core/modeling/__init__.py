"""Modelling unknown objects from clicked image edges and the range finder (source paper §III).

The operator gives the semantics (box, polyhedron, cylinder, cone; vertical or oblique; "lies on
the table"), the sensors give the numbers:

* ``model_box(camera, faces, support)`` — a box from its visible faces (range points + clicked
  sides), the paper's plane construction, then a box fitted to the constructed corners; with
  ``method="fused"`` a maximum-likelihood fit of the raw data, profile scans included (``box_scans``);
* ``model_polyhedron(camera, faces, ...)`` — any polyhedron from a face/edge topology (prisms,
  pyramids): every vertex is the least-squares point of the planes that meet there;
* ``model_cylinder(camera, method, ...)`` — cylinders and cones by the paper's "tangential",
  "bisecting", "rf_tangential" methods or the "fused" maximum-likelihood fit.

Every result is a ``ModelResult``: a B-Rep in its object frame, ``T_world_obj``, the dimensions
and their standard deviations.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .box import BoxFace, model_box
    from .cylinder import METHODS
    from .observations import PlaneObs, fit_face_plane, interpretation_plane_obs
    from .polyhedron import model_polyhedron
    from .result import ModelResult
    from .revolution import model_cylinder

# The names below load their module on first use (PEP 562): the interface imports
# ``core.modeling.result`` at start-up, and the solvers' modules need not load before its first page.
_WHERE = {
    "BoxFace": "box",
    "model_box": "box",
    "METHODS": "cylinder",
    "model_cylinder": "revolution",
    "PlaneObs": "observations",
    "fit_face_plane": "observations",
    "interpretation_plane_obs": "observations",
    "model_polyhedron": "polyhedron",
    "ModelResult": "result",
}


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


__all__ = [
    "BoxFace",
    "METHODS",
    "ModelResult",
    "PlaneObs",
    "fit_face_plane",
    "interpretation_plane_obs",
    "model_box",
    "model_cylinder",
    "model_polyhedron",
]
