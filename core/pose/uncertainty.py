"""The camera calibration's share of a refined pose's covariance.

``refine`` states the pose's covariance from the clicks for a given C. C is an estimate too (its
DLT covariance, ``core.calibration.calibrate_dlt(...).cov``); its error shifts the pose the same
way whatever the clicks. ``with_camera_uncertainty`` refines again from the solution with C moved
±1σ along each principal axis of its covariance (2 × 11 refinements, a few milliseconds each) and
adds the spread of the pose: ``cov = cov_clicks + Σ_k δ_k δ_kᵀ``, δ_k the central difference of
(δt, δr) in refine's convention (world frame, about the object's origin). With clicks in several cameras
(``with_views_camera_uncertainty``) each camera's calibration is moved in turn, the others held: their
errors are independent, and their shares add.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..calibration import check_covariance, perturbed_camera, principal_steps
from ..camera import Camera
from ..transforms import log_so3
from .refine import RefineResult, ViewClicks, refine_views

__all__ = ["with_camera_uncertainty", "with_views_camera_uncertainty", "pose_delta"]


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
    view = ViewClicks(camera, segs_uv, edges_obj, points_uv, points_obj, sigma_px=result.sigma_px)
    return with_views_camera_uncertainty(result, [view], [camera_cov], huber_px=huber_px)


def with_views_camera_uncertainty(
    result: RefineResult, views: Sequence[ViewClicks], camera_covs: Sequence[np.ndarray | None], huber_px: float = 3.0
) -> RefineResult:
    """``result`` (refined by ``refine_views`` on ``views``) with every camera calibration's share added to its
    ``cov``: each view's C moved ±1σ along the principal axes of its covariance (``camera_covs``, one (12, 12)
    or None per view), the other views held. ``cov_parts`` holds "clicks" and "camera calibration".
    Unchanged when no view has a covariance."""
    if all(c is None for c in camera_covs):
        return result
    T0, share = result.T_world_obj, np.zeros((6, 6))
    for i, cov in enumerate(camera_covs):
        if cov is None:
            continue
        for d in principal_steps(check_covariance(cov, 12, "camera_cov (of C's entries)")):
            moved = []
            for step in (d, -d):
                vs = list(views)
                vs[i] = replace(views[i], camera=perturbed_camera(views[i].camera, step))
                moved.append(refine_views(vs, T0, loss=result.loss, huber_px=huber_px).T_world_obj)
            dq = 0.5 * (pose_delta(moved[0], T0) - pose_delta(moved[1], T0))
            share += np.outer(dq, dq)
    return replace(result, cov=result.cov + share, cov_parts={"clicks": result.cov, "camera calibration": share})
