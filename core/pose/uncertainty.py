"""The camera calibration's share of a refined pose's covariance.

``refine`` states the pose's covariance from the clicks for a given C. C is an estimate too (its
DLT covariance, ``core.calibration.calibrate_dlt(...).cov``); its error shifts the pose the same
way whatever the clicks. ``with_camera_uncertainty`` refines again from the solution with C moved
±1σ along each principal axis of its covariance (2 × 11 refinements, a few milliseconds each) and
adds the spread of the pose: ``cov = cov_clicks + Σ_k δ_k δ_kᵀ``, δ_k the central difference of
(δt, δr) in refine's convention (world frame, about the object's origin).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..calibration import check_covariance, perturbed_camera, principal_steps
from ..camera import Camera
from ..transforms import log_so3
from .refine import RefineResult, refine

__all__ = ["with_camera_uncertainty", "pose_delta"]


def pose_delta(T: np.ndarray, T0: np.ndarray) -> np.ndarray:
    """(δt, δr) with ``T = (exp([δr]×) R0, t0 + δt)`` — refine's perturbation (world frame)."""
    return np.concatenate([T[:3, 3] - T0[:3, 3], log_so3(T[:3, :3] @ T0[:3, :3].T)])


def with_camera_uncertainty(
    result: RefineResult,
    camera: Camera,
    camera_cov: np.ndarray | None,
    *,
    segs_uv: np.ndarray | None = None,
    edges_obj: np.ndarray | None = None,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
    huber_px: float = 3.0,
) -> RefineResult:
    """``result`` (refined with ``camera`` on these clicks) with the camera calibration's share
    added to its ``cov``; ``cov_parts`` holds "clicks" and "camera calibration". Unchanged when
    ``camera_cov`` is None.

    camera_cov : array (12, 12), covariance of ``camera.C.ravel()``.
    """
    if camera_cov is None:
        return result
    steps = principal_steps(check_covariance(camera_cov, 12, "camera_cov (of C's entries)"))
    T0 = result.T_world_obj
    kw = dict(
        segs_uv=segs_uv,
        edges_obj=edges_obj,
        points_uv=points_uv,
        points_obj=points_obj,
        loss=result.loss,
        huber_px=huber_px,
        sigma_px=result.sigma_px,
    )
    share = np.zeros((6, 6))
    for d in steps:
        plus = refine(perturbed_camera(camera, d), T0, **kw).T_world_obj
        minus = refine(perturbed_camera(camera, -d), T0, **kw).T_world_obj
        dq = 0.5 * (pose_delta(plus, T0) - pose_delta(minus, T0))
        share += np.outer(dq, dq)
    return replace(result, cov=result.cov + share, cov_parts={"clicks": result.cov, "camera calibration": share})
