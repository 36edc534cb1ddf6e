"""``model_cylinder``: a cylinder or cone by one of ``METHODS`` — the paper's three (core/modeling/cylinder.py)
or the fused maximum-likelihood fit (core/modeling/fused.py), from the data both reduce alike."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..camera import Camera
from ..checks import positive_scale
from ..geometry import Plane
from ..rangefinder import RangeFinderSpec, RangeScan
from .cylinder import METHODS, model_paper, reduce_cylinder_data
from .fused import fit_fused
from .result import ModelResult

__all__ = ["model_cylinder"]


def model_cylinder(
    camera: Camera,
    method: str,
    *,
    silhouettes_uv: np.ndarray | None = None,
    scans: Sequence[RangeScan] = (),
    T_world_turret: np.ndarray | None = None,
    spec: RangeFinderSpec = RangeFinderSpec(),
    support: Plane | None = None,
    axis_dir: np.ndarray | None = None,
    cone: bool = False,
    sigma_px: float = 1.0,
    jump_m: float = 0.05,
) -> ModelResult:
    """Model a cylinder (or, with ``cone=True``, a cone/frustum) by one of ``METHODS``.

    Parameters
    ----------
    camera : Camera
    method : "tangential", "bisecting", "rf_tangential" or "fused"
    silhouettes_uv : array, shape (2, 2, 2), optional
        The two contour generators as clicked segments, each from one end of the contour to the
        other (its ends give the height). Needed by "tangential" and "bisecting".
    scans : sequence of RangeScan
        Horizontal scans across the object, in sweep order, misses (NaN) kept; at least one
        (two for an oblique axis with "bisecting"/"rf_tangential", two heights for a cone).
    T_world_turret : array, shape (4, 4)
    spec : RangeFinderSpec (σ_ρ, step, pointing noise)
    support : Plane, optional
        The object stands on it: its axis is the support's normal and its base lies on it.
    axis_dir : array, shape (3,), optional
        The axis direction when known otherwise ("vertical": (0, 0, 1)); default: from the support,
        else found from the data (cylinders only).
    cone : bool
        Fit two radii (bottom, top).
    sigma_px : float
        Click noise, pixels per coordinate.
    jump_m : float
        A range jump larger than this between neighbouring beams separates the object from the
        background in a scan.

    Returns
    -------
    ModelResult
        kind "cylinder" or "cone"; ``model`` = ``BRep.cylinder`` / ``BRep.cone`` in the object frame
        (base centre, z along the axis); ``axis``; dimensions {"radius", "height"} or
        {"radius_bottom", "radius_top", "height"} with sigmas, plus sigma "axis_position".
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if method in ("tangential", "bisecting") and silhouettes_uv is None:
        raise ValueError(f"method {method!r} needs the two silhouettes (silhouettes_uv, shape (2, 2, 2))")
    sigma_px = positive_scale(sigma_px, "sigma_px", " px")
    data = reduce_cylinder_data(
        camera,
        silhouettes_uv=silhouettes_uv,
        scans=scans,
        T_world_turret=T_world_turret,
        spec=spec,
        support=support,
        axis_dir=axis_dir,
        cone=cone,
        jump_m=jump_m,
    )
    if method == "fused":
        return fit_fused(data, sigma_px=sigma_px).check_finite()
    return model_paper(data, method, sigma_px).check_finite()
