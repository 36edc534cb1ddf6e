"""What a modelling method returns: the model, its pose, its dimensions with standard deviations.

The database stores ``model`` (a B-Rep in the object frame) with ``T_world_obj``; the interface
shows ``dimensions[k] ± sigmas[k]``. Object frames (like ``BRep.box`` / ``BRep.cylinder``):

* box: origin at the centre of the bottom face, axes along the box edges, z up (away from the
  support, or the box axis nearest world +z without one);
* cylinder / cone: origin at the centre of the base, z along the axis from the base to the top;
* general polyhedron: origin at the centroid of the vertices (or of the support face when the
  object lies on a support), z along the support normal when there is one, else world axes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..brep import BRep
from ..geometry import Line

__all__ = ["ModelResult"]


# How the operator reads a dimension's key (a box's sides along its own x and y, its height along z).
DIMENSION_WORDS = {
    "size_x": "side x",
    "size_y": "side y",
    "size_z": "height",
    "radius": "radius",
    "radius_bottom": "bottom radius",
    "radius_top": "top radius",
    "height": "height",
    "axis_position": "axis position",
}


@dataclass(frozen=True)
class ModelResult:
    """A modelled object.

    Attributes
    ----------
    kind : str
        "box", "polyhedron", "cylinder" or "cone".
    method : str
        How it was built: "planes" (the paper's §III.1 construction), "tangential",
        "bisecting", "rf_tangential" or "fused".
    model : BRep
        The shape in its object frame (see the module docstring), metres.
    T_world_obj : array, shape (4, 4)
        Pose of the object frame in the world.
    dimensions : dict[str, float]
        Named sizes in metres: box {"size_x", "size_y", "size_z"}; cylinder {"radius",
        "height"}; cone {"radius_bottom", "radius_top", "height"}; polyhedron {"edge_i_j", ...}.
    sigmas : dict[str, float]
        Standard deviation (metres) of each dimension, plus for cylinders and cones
        "axis_position" (RMS over both directions across the axis, at mid-height) and for
        boxes and polyhedra "position" (of the frame origin, RMS over x, y, z).
    cov : array, shape (K, K)
        Covariance of the quantities named in ``cov_names`` (metres², radians² for angles).
    cov_names : tuple of str
    vertices_world : array, shape (V, 3)
        Polyhedra: the vertices as constructed from the planes (before any shape fit);
        solids of revolution: the two axis endpoints (base centre, top centre).
    axis : Line or None
        Solids of revolution: the axis in the world, point = base centre, direction base → top.
    residuals : dict[str, array]
        Per-measurement residuals by group (metres for range points and planes, pixels for
        clicks), for display and outlier review.
    details : dict
        Method-specific diagnostics (plane fits, inlier masks, intermediate planes).
    notes : tuple of str
        Things the operator should know (e.g. which data gave the height).
    """

    kind: str
    method: str
    model: BRep
    T_world_obj: np.ndarray
    dimensions: dict[str, float]
    sigmas: dict[str, float]
    cov: np.ndarray
    cov_names: tuple[str, ...]
    vertices_world: np.ndarray
    axis: Line | None = None
    residuals: dict[str, np.ndarray] = field(default_factory=dict)
    details: dict[str, Any] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    def check_finite(self) -> ModelResult:
        """The result itself when its pose, dimensions, σ, vertices and covariance are finite; else
        ValueError (the measurements were too degenerate for a model: nothing NaN leaves the core)."""
        bad = [
            k
            for k, v in {**self.dimensions, **{f"σ {k}": s for k, s in self.sigmas.items()}}.items()
            if not np.isfinite(v)
        ]
        bad += [
            k
            for k, a in (("pose", self.T_world_obj), ("vertices", self.vertices_world), ("covariance", self.cov))
            if not np.isfinite(a).all()
        ]
        if bad:
            raise ValueError(
                f"the measurements give no finite {self.kind} (not finite: {', '.join(bad[:4])}); they are too "
                "degenerate (points on a line, faces seen edge-on, clicks at one place): measure again"
            )
        return self

    def model_world(self) -> BRep:
        """The model with its pose baked in (world coordinates)."""
        return self.model.transformed(self.T_world_obj)

    def dimension_text(self, unit: str = "cm") -> str:
        """One line such as ``side x 9.02 ± 0.21 cm, side y …, height …`` for the operator (the
        dimensions' names in words: ``DIMENSION_WORDS``; the keys stay in ``dimensions``)."""
        scale = {"m": 1.0, "cm": 100.0, "mm": 1000.0}[unit]
        parts = []
        for k, v in self.dimensions.items():
            s = self.sigmas.get(k, float("nan"))
            name = DIMENSION_WORDS.get(k, k.replace("_", " "))
            parts.append(f"{name} {v * scale:.2f} ± {s * scale:.2f} {unit}")
        return ", ".join(parts)
