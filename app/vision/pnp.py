"""The camera's pose from ≥ 4 clicked known points when its intrinsics K are known (PnP).

With K known (a checkerboard calibration, ``mcit calibrate-intrinsics``, or the scene's camera
block), C = K [R | t] has 6 unknowns instead of the DLT's 11: 4 points fix it, and every point
beyond gives redundancy. ``solve_pnp`` starts from OpenCV's solvers (SQPnP, the iterative one,
EPnP), refines each by the pose pipeline's one refinement (``core.pose.refine_many``: Levenberg–Marquardt
on the reprojection error in pixels, each point weighed by its σ — the maximum-likelihood pose under pixel
noise, as ``core.calibration.calibrate_dlt`` does for C), and keeps the one with the smallest weighted
error. The camera's pose T_cam_world is refined as the pose of an "object", the world, seen by the camera
K [I | 0] at the origin: the clicked points are the object's points, and refine's perturbation (δt, δr) in
that frame is this module's (δω, δt) reordered.

The covariance is the pose's, (Jᵀ W J)⁻¹ from the refinement (the χ² policy of
``calibrate_dlt``: scaled by χ²/dof when the χ² test rejects the stated σ, never shrunk), and
taken through C = K [R | t] to the 12 entries of C for the workflows that propagate the
calibration's uncertainty. K is taken as exact: its own uncertainty (a checkerboard calibration's)
is not in it.
"""

from __future__ import annotations

import numpy as np

from core.camera import Camera
from core.checks import MAX_M, MAX_PX, MAX_SCALE, MIN_SCALE, finite_array, image_size
from core.pose import refine_many
from core.pose.residuals import as_clicks, residuals
from core.pose.uncertainty import (
    CAMERA_PRIOR_C_PX,
    CAMERA_PRIOR_F_REL,
    MODEL_PRIOR_M,
    first_order_moves,
    grouped_share,
    model_scale_share,
)
from core.transforms import exp_so3, make_T

__all__ = ["PnPResult", "solve_pnp", "MIN_PNP_POINTS"]

MIN_PNP_POINTS = 4


class PnPResult:
    """A pose solved with K known.

    camera : Camera, C = K [R | t] (normalised as Camera does). T_cam_world : (4, 4).
    rms_px : RMS reprojection distance. residuals_px : (N, 2) projected minus clicked; errors_px (N,).
    cov_pose : (6, 6) covariance of the pose's perturbation (δω rad, δt m), R = exp(δω) R̂, t = t̂ + δt
    (camera frame), K's stated prior and the world points' included. cov : (12, 12) covariance of
    ``camera.C.ravel()`` from it and K's prior.
    variance_factor : χ² of the weighted residuals per degree of freedom (2N − 6).
    std_position_m : σ of the camera's optical centre in the world along its worst direction (m).
    std_angle_rad : σ of its orientation about its worst axis (rad).
    """

    def __init__(
        self, camera, T_cam_world, rms_px, residuals_px, cov_pose, cov, variance_factor, std_position_m, std_angle_rad
    ):
        self.camera = camera
        self.T_cam_world = T_cam_world
        self.rms_px = float(rms_px)
        self.residuals_px = residuals_px
        self.errors_px = np.linalg.norm(residuals_px, axis=1)
        self.cov_pose = cov_pose
        self.cov = cov
        self.variance_factor = float(variance_factor)
        self.std_position_m = float(std_position_m)
        self.std_angle_rad = float(std_angle_rad)


def _check_K(K) -> np.ndarray:
    K = finite_array(K, (3, 3), "K")
    if K[2, 2] == 0 or abs(K[1, 0]) + abs(K[2, 0]) + abs(K[2, 1]) > 1e-9 * np.abs(K).max():
        raise ValueError("K must be upper triangular (fx, skew, u0; 0, fy, v0; 0, 0, 1)")
    K = K / K[2, 2]
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise ValueError(f"K's focal lengths must be positive, got fx {K[0, 0]:g}, fy {K[1, 1]:g}")
    return K


def _pose(R0: np.ndarray, t0: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return exp_so3(x[:3]) @ R0, t0 + x[3:]


def _project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pixels (N, 2), depths (N,))."""
    Xc = X @ R.T + t
    h = Xc @ K.T
    return h[:, :2] / h[:, 2:3], Xc[:, 2]


def _starts(K: np.ndarray, X: np.ndarray, uv: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    import cv2

    out = []
    flags = [cv2.SOLVEPNP_SQPNP, cv2.SOLVEPNP_ITERATIVE, cv2.SOLVEPNP_EPNP]
    for flag in flags:
        try:
            ok, rvec, tvec = cv2.solvePnP(X.astype(np.float64), uv.astype(np.float64), K, None, flags=flag)
        except cv2.error:
            continue
        if ok and np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec)):
            out.append((cv2.Rodrigues(rvec)[0], tvec.reshape(3)))
    return out


def _prior_shares(K, fit, X, uv, sig, k_prior, points_sigma_m, cov_pose, Jc, order):
    """(cov_pose, cov_C) with K's prior and the world points' added (``solve_pnp``): the pose's move with each
    ±1σ step of (fx, fy, u0, v0) (``first_order_moves``) and C's, K's own step and the pose's together."""
    R, t = fit.T_world_obj[:3, :3], fit.T_world_obj[:3, 3]
    clicks = as_clicks(points_uv=uv, points_obj=X)
    origin = Camera(np.column_stack([K, np.zeros(3)]), 1, 1)
    _, J, _ = residuals(origin, R, t, clicks, jacobian=True)
    w = np.repeat(1.0 / sig**2, 2)
    cov_C = Jc @ cov_pose @ Jc.T
    if points_sigma_m > 0:
        moved = lambda d: residuals(origin, R, t, as_clicks(points_uv=uv, points_obj=X + d))[0]  # noqa: E731
        share = grouped_share(J, w, moved, np.arange(2 * len(X)) // 2, points_sigma_m)
        # the points' set scaled along each world axis, its extents each read to √2 σ
        scaled = lambda scale: residuals(origin, R, t, as_clicks(points_uv=uv, points_obj=scale(X)))[0]  # noqa: E731
        bounds = np.array([X.min(axis=0), X.max(axis=0)])
        share = (share + model_scale_share(J, w, scaled, bounds, points_sigma_m))[np.ix_(order, order)]
        cov_pose, cov_C = cov_pose + share, cov_C + Jc @ share @ Jc.T
    f_rel, c_px = k_prior
    if f_rel > 0 or c_px > 0:
        P = np.column_stack([R, t])

        def K_of(k):
            return K + np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 0]])

        cov_k = np.diag(np.array([f_rel * K[0, 0], f_rel * K[1, 1], c_px, c_px]) ** 2)
        resid = lambda k: residuals(Camera(np.column_stack([K_of(k), np.zeros(3)]), 1, 1), R, t, clicks)[0]  # noqa: E731
        steps, moves = first_order_moves(J, w, resid, cov_k)
        for d, dq in zip(steps, moves):
            dq = dq[order]
            cov_pose = cov_pose + np.outer(dq, dq)
            dC = (K_of(d) - K) @ P
            dC = dC.ravel() + Jc @ dq
            cov_C = cov_C + np.outer(dC, dC)
    return 0.5 * (cov_pose + cov_pose.T), cov_C


def solve_pnp(
    K,
    X_world,
    uv,
    width: int,
    height: int,
    *,
    sigma_px=None,
    k_prior: tuple[float, float] = (CAMERA_PRIOR_F_REL, CAMERA_PRIOR_C_PX),
    points_sigma_m: float = MODEL_PRIOR_M,
) -> PnPResult:
    """The camera C = K [R | t] from ≥ 4 clicked pixels ``uv`` (N, 2) of known world points
    ``X_world`` (N, 3, metres, not all on one line), K (3, 3) known. ``sigma_px`` (N,): each
    pixel's σ (default 1 px). ValueError (plain words) for too few points, collinear points, or no
    pose that puts every point in front of the camera.

    The pose's and C's covariances hold, by first order (issue 27, ``core.pose.uncertainty``), K's stated
    prior ``k_prior`` = (σ(fx)/fx = σ(fy)/fy, σ(u0) = σ(v0) in pixels; (0, 0): K exact) — the pose moves with
    K, and C with both — and the world points' ``points_sigma_m`` (each point off by its own 3D offset, and the
    points' extents along the world's axes each by √2 of it: ``model_scale_share``)."""
    K = _check_K(K)
    X = finite_array(X_world, (None, 3), "X_world", max_abs=MAX_M, unit=" m")
    uv = finite_array(uv, (None, 2), "uv", max_abs=MAX_PX, unit=" px")
    width, height = image_size(width, height)
    n = len(X)
    if len(uv) != n:
        raise ValueError(f"X_world has {n} points but uv has {len(uv)}: they must pair one to one")
    if n < MIN_PNP_POINTS:
        raise ValueError(
            f"{n} points paired; the camera's pose with the lens known needs at least {MIN_PNP_POINTS} "
            "(6 unknowns): pair more"
        )
    sv = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
    if sv[1] <= 1e-6 * sv[0]:
        raise ValueError(
            "the points are on one line: they cannot fix the camera's pose; use corners spread over the scene"
        )
    sig = np.ones(n)
    if sigma_px is not None:
        sig = np.asarray(sigma_px, dtype=float).reshape(-1)
        if sig.shape != (n,) or not (np.all(sig >= MIN_SCALE) and np.all(sig <= MAX_SCALE)):
            raise ValueError(f"sigma_px must hold {n} positive finite values (one per point), got {np.shape(sigma_px)}")

    starts = _starts(K, X, uv)
    best = None
    if starts:  # each OpenCV start refined by core.pose's refinement: the world's pose seen by K [I | 0]
        origin = Camera(np.column_stack([K, np.zeros(3)]), width, height)
        T0 = np.array([make_T(R0, t0) for R0, t0 in starts])
        for fit, _ in refine_many(origin, T0, as_clicks(points_uv=uv, points_obj=X), sigma_px=sig):
            if isinstance(fit, str) or not np.all(np.isfinite(fit.T_world_obj)):
                continue  # a start with a point behind the camera, or none that fixes the pose
            cost = float(np.sum((fit.residuals_px / np.repeat(sig, 2)) ** 2))
            if best is None or cost < best[0]:
                best = (cost, fit)
    if best is None:
        raise ValueError(
            "no camera pose puts every point in front of the camera: check that each click is on its corner"
        )
    cost, fit = best
    R, t = fit.T_world_obj[:3, :3], fit.T_world_obj[:3, 3]
    order = [3, 4, 5, 0, 1, 2]  # refine's (δt, δr) → this module's (δω, δt)
    cov_pose = fit.cov[np.ix_(order, order)]
    dof = 2 * n - 6
    factor = cost / max(dof, 1)
    from scipy.stats import chi2  # here, not at the top (start-up)

    if dof > 0 and cost > chi2.ppf(0.99, dof):
        cov_pose = cov_pose * factor  # the clicks are worse than stated (or a point is wrong): say so in σ
    cov_pose = 0.5 * (cov_pose + cov_pose.T)
    eps = np.array([1e-7] * 3 + [1e-7 * max(1.0, float(np.linalg.norm(t)))] * 3)

    def C_of(x):
        Rx, tx = _pose(R, t, x)
        return (K @ np.column_stack([Rx, tx])).ravel()  # ‖C[2, :3]‖ = 1 as Camera normalises it

    def centre(x):
        Rx, tx = _pose(R, t, x)
        return -Rx.T @ tx

    Jc = np.column_stack([(C_of(e) - C_of(-e)) / (2 * e[i]) for i, e in enumerate(np.diag(eps))])
    Jo = np.column_stack([(centre(e) - centre(-e)) / (2 * e[i]) for i, e in enumerate(np.diag(eps))])
    cov_pose, cov_C = _prior_shares(K, fit, X, uv, sig, k_prior, points_sigma_m, cov_pose, Jc, order)
    cov_centre = Jo @ cov_pose @ Jo.T
    camera = Camera(K @ np.column_stack([R, t]), width, height, in_front=X)
    res = _project(K, R, t, X)[0] - uv
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return PnPResult(
        camera,
        make_T(R, t),
        rms,
        res,
        cov_pose,
        0.5 * (cov_C + cov_C.T),
        factor,
        float(np.sqrt(max(np.linalg.eigvalsh(cov_centre)[-1], 0.0))),
        float(np.sqrt(max(np.linalg.eigvalsh(cov_pose[:3, :3])[-1], 0.0))),
    )
