"""Measured planes with their covariance: interpretation planes of clicks, fitted face planes.

A ``PlaneObs`` is a plane ``n·X + d = 0`` (unit n) with the 4×4 covariance of ``(n, d)``; the
construction of vertices, edges and solids works on these and propagates the covariance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Camera, as_segment
from ..checks import MAX_M, finite_array, positive_scale
from ..geometry import Plane, PlaneFit, fit_plane_ols, fit_plane_tls, make_plane
from .robust import ransac_plane
from .small import interp_plane_jacobian

__all__ = ["PlaneObs", "interpretation_plane_obs", "support_obs", "FaceFit", "fit_face_plane", "plane_var_at"]


@dataclass(frozen=True)
class PlaneObs:
    """A plane and its uncertainty. plane : Plane; cov : array, shape (4, 4), of (n, d); label : str."""

    plane: Plane
    cov: np.ndarray
    label: str = ""


def plane_var_at(obs: PlaneObs, X: np.ndarray) -> np.ndarray | float:
    """Variance (m²) of the plane's signed distance at points X, shape (3,) → float, (N, 3) → (N,)."""
    X = np.asarray(X, dtype=float)
    H = np.concatenate([X, np.ones(X.shape[:-1] + (1,))], axis=-1)
    v = np.einsum("...i,ij,...j->...", H, obs.cov, H)
    return float(v) if X.ndim == 1 else v


def interpretation_plane_obs(camera: Camera, seg_uv: np.ndarray, sigma_px: float, label: str = "") -> PlaneObs:
    """Interpretation plane Cᵀl of a clicked segment (2, 2) with the covariance of (n, d).

    sigma_px : standard deviation of each clicked coordinate, pixels (independent). The
    covariance is σ² J Jᵀ with J the derivative of (n, d) with respect to the four coordinates
    (analytic: ``small.interp_plane_jacobian``).
    """
    seg = as_segment(seg_uv)
    if sigma_px != 0:  # 0: exact clicks (a zero covariance)
        positive_scale(sigma_px, "sigma_px", " px")
    p = camera.interpretation_plane(seg)
    v0 = p.as_vector()
    v, J = interp_plane_jacobian(camera.C, seg)
    if v @ v0 < 0:  # the same orientation as the plane returned
        J = -J
    return PlaneObs(p, sigma_px**2 * (J @ J.T), label)


def support_obs(support: Plane, sigma_m: float, label: str = "support") -> PlaneObs:
    """The support plane (a table top from the database) with offset noise σ (m), normal exact."""
    if not isinstance(support, Plane):
        raise ValueError(f"support must be a core.geometry.Plane, got {type(support).__name__}")
    if sigma_m != 0:
        positive_scale(sigma_m, "support_sigma_m", " m")
    p = make_plane(support.n, support.d)
    cov = np.zeros((4, 4))
    cov[3, 3] = sigma_m**2
    return PlaneObs(p, cov, label)


@dataclass(frozen=True)
class FaceFit:
    """A face plane fitted to range points.

    obs : PlaneObs used downstream (from the chosen fit). fits : {"ols": PlaneFit | None,
    "tls": PlaneFit} (the paper's form fails for faces parallel to z: then None).
    inliers : array, shape (N,), bool. method : the fit used ("tls" or "ols").
    """

    obs: PlaneObs
    fits: dict
    inliers: np.ndarray
    method: str


def _normal_sigma(covs: np.ndarray, n: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(np.einsum("i,nij,j->n", n, covs, n), 1e-18))


def fit_face_plane(
    X_world: np.ndarray,
    *,
    covs: np.ndarray | None = None,
    sigma_m: float | None = None,
    method: str = "tls",
    robust: bool = True,
    threshold_m: float | None = None,
    label: str = "",
) -> FaceFit:
    """Fit a face plane to range points aimed at it: the paper's least squares and total least squares.

    X_world : array, shape (N ≥ 3, 3), metres. covs : array, shape (N, 3, 3), each point's
    covariance (``core.rangefinder.beam_point_cov``); the TLS fit is then weighted by the
    inverse variance along the normal and its covariance follows from those σ. sigma_m :
    isotropic point noise when ``covs`` is None (estimated from the residuals when both are None,
    at least 0.1 mm).
    method : "tls" (any orientation) or "ols" (the paper's ``ax + by + z + d = 0``; fails for
    faces parallel to z). robust : discard points off the face (edge hits, background) by
    RANSAC with ``threshold_m`` (default 3.5 σ along the beam, at least 3 mm).
    ValueError when fewer than 3 points (or inliers) remain or they are collinear.
    """
    X = np.asarray(X_world, dtype=float)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"face {label!r}: range points must have shape (N, 3), got {X.shape}")
    if len(X) < 3:
        raise ValueError(
            f"face {label!r}: a face plane needs at least 3 range points, "
            f"got {len(X)}; aim the range finder at more points of the face"
        )
    X = finite_array(X, (None, 3), f"face {label!r} range points", max_abs=MAX_M, unit=" m")
    if covs is not None:
        covs = np.asarray(covs, dtype=float)
        if covs.shape != (len(X), 3, 3):
            raise ValueError(f"face {label!r}: covs must have shape ({len(X)}, 3, 3), got {covs.shape}")
        finite_array(covs, (len(X), 3, 3), f"face {label!r}: covs", max_abs=MAX_M)
    if sigma_m is not None:
        sigma_m = positive_scale(sigma_m, "sigma_m", " m")
    if threshold_m is not None:
        threshold_m = positive_scale(threshold_m, "threshold_m", " m")
    if method not in ("tls", "ols"):
        raise ValueError(f"method must be 'tls' or 'ols', got {method!r}")
    inl = np.ones(len(X), bool)
    if robust and len(X) > 3:
        if threshold_m is None:
            if covs is not None:
                s = float(np.sqrt(np.median(np.linalg.eigvalsh(covs)[:, -1])))
            else:
                s = sigma_m if sigma_m is not None else 0.005
            threshold_m = max(3.5 * s, 0.003)
        inl = ransac_plane(X, threshold_m)
        if inl.sum() < 3:
            raise ValueError(
                f"face {label!r}: the {len(X)} range points are collinear or scattered: no 3 of them "
                "lie on one plane; aim the range finder at points spread over the face"
            )
    Xi = X[inl]
    sv = np.linalg.svd(Xi - Xi.mean(axis=0), compute_uv=False)
    if not sv[1] > 1e-6 * sv[0]:
        raise ValueError(
            f"face {label!r}: the {len(Xi)} range points lie on a line (or at one place): they fix no plane; "
            "aim the range finder at points spread over the face"
        )
    try:
        if covs is not None:
            first = fit_plane_tls(Xi)
            w = 1.0 / _normal_sigma(covs[inl], first.plane.n) ** 2
            tls = fit_plane_tls(Xi, sigma_m=1.0, weights=w)
            w = 1.0 / _normal_sigma(covs[inl], tls.plane.n) ** 2
            tls = fit_plane_tls(Xi, sigma_m=1.0, weights=w)
            s_ols = float(np.sqrt(np.mean(1.0 / w)))
        else:
            if sigma_m is None:
                # Estimated from the residuals, floored at 0.1 mm (below any range finder's noise)
                # so that exact data do not claim an exact plane.
                sigma_m = max(fit_plane_tls(Xi).sigma_m, 1e-4)
            tls = fit_plane_tls(Xi, sigma_m=sigma_m)
            s_ols = sigma_m
    except ValueError as exc:
        raise ValueError(f"face {label!r}: {exc}") from None
    try:
        ols = fit_plane_ols(Xi, sigma_m=s_ols)
    except ValueError:
        ols = None
    if method == "ols":
        if ols is None:
            raise ValueError(
                f"face {label!r} is (nearly) parallel to the z axis: the paper's form "
                "ax + by + z + d = 0 cannot represent it; use plane_fit='tls'"
            )
        chosen: PlaneFit = ols
    else:
        chosen = tls
    if not np.isfinite(chosen.cov).all():
        raise ValueError(
            f"face {label!r}: the range points give no finite plane covariance; aim at points spread over the face"
        )
    return FaceFit(PlaneObs(chosen.plane, chosen.cov, label), {"ols": ols, "tls": tls}, inl, method)
