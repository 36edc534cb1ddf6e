"""Can a pose be the answer? The checks every pose offered to the operator passes.

A least-squares fit always returns a pose; it is offered only when its clicks' RMS is within the
limit the click noise allows, every vertex of the object is in front of the camera, and the
object's projection reaches into the image (a fit can slide an object behind the camera or off
screen while matching the clicked lines).
"""

from __future__ import annotations

import numpy as np

from ..brep import BRep
from ..camera import Camera
from ..checks import finite_array

__all__ = ["plausibility"]


def plausibility(
    camera: Camera, model: BRep, T_world_obj: np.ndarray, rms_px: float | None = None, max_rms_px: float = np.inf
) -> str:
    """Why the pose cannot be the answer, in one phrase ("" when it can).

    camera : the camera the clicks were made in. model : the object (object frame; a model without
    vertices is checked by the corners of its bounds). T_world_obj : (4, 4), object → world.
    rms_px, max_rms_px : the fit's RMS over the clicks and its limit (e.g. 3 σ), pixels; None skips
    that check. Reasons: the RMS above the limit, part of the object behind the camera, or its
    projection entirely outside the image.
    """
    T_world_obj = finite_array(T_world_obj, (4, 4), "T_world_obj")
    if rms_px is not None and not rms_px <= max_rms_px:
        return f"RMS {rms_px:.1f} px, more than the {max_rms_px:.1f} px allowed"
    V = model.vertices
    if not len(V):
        lo, hi = model.bounds()
        V = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    X = V @ T_world_obj[:3, :3].T + T_world_obj[:3, 3]
    if np.any(camera.depth(X) <= 0):
        return "it puts the object behind the camera"
    uv = camera.project(X)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    if hi[0] < -0.5 or hi[1] < -0.5 or lo[0] > camera.width - 0.5 or lo[1] > camera.height - 0.5:
        return "it puts the object outside the image"
    return ""
