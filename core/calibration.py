"""Calibration of the camera (the global model C, by DLT) and of the range finder's turret.

* ``calibrate_dlt``: C from ≥ 6 clicked pixels of known, non-coplanar world points: the
  Hartley-normalised direct linear transform, then Levenberg–Marquardt on the reprojection
  error in pixels (the maximum-likelihood estimate under pixel noise).
* ``calibrate_turret``: ``T_world_turret`` from range-finder measurements (pan, tilt, range)
  of ≥ 3 known, non-collinear world points: closed form (Kabsch), then refined with each
  measurement weighted by the sensor's anisotropic noise (range along the beam, angles across).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .checks import MAX_M, MAX_PX, MAX_SCALE, MIN_SCALE, finite_array, image_size
from .rangefinder import RangeFinderSpec, beam_direction, beam_point_cov
from .transforms import check_T, exp_so3, invert_T, log_so3, make_T

__all__ = [
    "DLTResult",
    "calibrate_dlt",
    "check_covariance",
    "perturbed_camera",
    "perturbed_turret",
    "principal_steps",
    "dlt",
    "TurretCalibration",
    "calibrate_turret",
    "calibrate_turret_planes",
    "turret_plane_rows",
    "next_turret_point",
    "kabsch",
]


class DLTResult(tuple):
    """``(camera, rms_px)``, unpackable as a pair, with the per-point residuals as attributes.

    camera : Camera. rms_px : float, RMS reprojection distance in pixels.
    residuals_px : array, shape (N, 2), projected minus clicked pixels.
    errors_px : array, shape (N,), their norms. linear_rms_px : the RMS of the DLT alone.
    cov : array, shape (12, 12), or None (not refined): covariance of ``camera.C.ravel()`` (row
    major, C as the Camera normalises it), first order, in the gauge orthogonal to C (C's scale
    is not observable). variance_factor : the weighted
    residuals' χ² per degree of freedom; the covariance is scaled by it when the χ² test rejects the
    stated σ (above its 99 % quantile: clicks worse than stated, or a wrong world point), never
    shrunk below the stated σ.
    """

    def __new__(
        cls,
        camera: Camera,
        rms_px: float,
        residuals_px: np.ndarray,
        linear_rms_px: float,
        cov: np.ndarray | None = None,
        variance_factor: float = float("nan"),
    ):
        self = super().__new__(cls, (camera, float(rms_px)))
        self.camera = camera
        self.rms_px = float(rms_px)
        self.residuals_px = residuals_px
        self.errors_px = np.linalg.norm(residuals_px, axis=1)
        self.linear_rms_px = float(linear_rms_px)
        self.cov = cov
        self.variance_factor = float(variance_factor)
        return self


def _normaliser(P: np.ndarray) -> np.ndarray:
    """Hartley similarity: centroid to the origin, mean distance √dim."""
    dim = P.shape[1]
    c = P.mean(axis=0)
    dist = np.linalg.norm(P - c, axis=1).mean()
    s = np.sqrt(dim) / dist
    T = np.eye(dim + 1)
    T[:dim, :dim] *= s
    T[:dim, dim] = -s * c
    return T


def _check_calibration_points(X: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    X = finite_array(X, (None, 3), "X_world", max_abs=MAX_M, unit=" m")
    uv = finite_array(uv, (None, 2), "uv", max_abs=MAX_PX, unit=" px")
    if len(X) != len(uv):
        raise ValueError(f"X_world has {len(X)} points but uv has {len(uv)}: they must pair one to one")
    if len(X) < 6:
        raise ValueError(
            f"calibration needs at least 6 points (11 unknowns in C), got {len(X)}; click more known points"
        )
    sv = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
    if sv[1] <= 1e-6 * sv[0]:
        raise ValueError("the calibration points are collinear: use points spread over a 3D calibration object")
    if sv[2] <= 1e-6 * sv[0]:
        raise ValueError(
            "the calibration points are coplanar: the DLT cannot recover C from one plane; "
            "add points off that plane (use a 3D calibration object)"
        )
    return X, uv


def dlt(X_world: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Hartley-normalised direct linear transform: the 3×4 C (unit Frobenius norm) from ≥ 6 pairs."""
    X, uv = _check_calibration_points(X_world, uv)
    T3 = _normaliser(X)
    T2 = _normaliser(uv)
    Xn = np.column_stack([X, np.ones(len(X))]) @ T3.T
    un = np.column_stack([uv, np.ones(len(uv))]) @ T2.T
    n = len(X)
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Xn
    A[0::2, 8:12] = -un[:, :1] * Xn
    A[1::2, 4:8] = Xn
    A[1::2, 8:12] = -un[:, 1:2] * Xn
    if not np.isfinite(A).all():
        raise ValueError(_DEGENERATE_DLT)
    _, sv, Vt = np.linalg.svd(A)
    if sv[-2] <= 1e-10 * sv[0]:
        raise ValueError("the DLT system is degenerate (the points are in a critical configuration); add points")
    Pn = Vt[-1].reshape(3, 4)
    P = np.linalg.inv(T2) @ Pn @ T3
    return P / np.linalg.norm(P)


def _reprojection(P: np.ndarray, X: np.ndarray, uv: np.ndarray) -> np.ndarray:
    h = X @ P[:, :3].T + P[:, 3]
    return h[:, :2] / h[:, 2:3] - uv


def calibrate_dlt(
    X_world: np.ndarray,
    uv: np.ndarray,
    width: int,
    height: int,
    *,
    refine: bool = True,
    sigma_px: np.ndarray | None = None,
) -> DLTResult:
    """The camera C from clicked pixels of known world points.

    Parameters
    ----------
    X_world : array, shape (N ≥ 6, 3)
        Known world points, metres, not coplanar.
    uv : array, shape (N, 2)
        Their clicked pixels.
    width, height : int
        Image size in pixels.
    refine : bool
        Refine the DLT by Levenberg–Marquardt on the reprojection error (pixels).
    sigma_px : array, shape (N,), optional
        Each pixel's standard deviation (pixels): the refinement weighs each point's reprojection
        error by 1/σ (maximum likelihood when the clicks' precision differs, e.g. corners snapped
        to the image beside raw clicks), and ``cov`` assumes them. Default: 1 px for every point.

    Returns
    -------
    DLTResult
        ``camera, rms_px = calibrate_dlt(...)``; ``.residuals_px`` (N, 2) per point.
    """
    X, uv = _check_calibration_points(X_world, uv)
    width, height = image_size(width, height)
    w = np.ones(len(X))
    if sigma_px is not None:
        sig = np.asarray(sigma_px, dtype=float).reshape(-1)
        if sig.shape != (len(X),) or not (np.all(sig >= MIN_SCALE) and np.all(sig <= MAX_SCALE)):
            raise ValueError(
                f"sigma_px must hold {len(X)} positive finite values (one per point, between {MIN_SCALE:g} and "
                f"{MAX_SCALE:g} px), got {np.shape(sigma_px)} {np.asarray(sigma_px).ravel()[:4].tolist()}"
            )
        w = 1.0 / sig
    P = dlt(X, uv)
    linear_rms = float(np.sqrt(np.mean(np.sum(_reprojection(P, X, uv) ** 2, axis=1))))
    if refine:
        from scipy.optimize import least_squares  # here, not at the top: scipy.optimize/stats cost start-up ~0.5 s

        sol = least_squares(
            lambda p: (_reprojection(p.reshape(3, 4), X, uv) * w[:, None]).ravel(),
            P.ravel(),
            method="lm",
            xtol=1e-14,
            ftol=1e-14,
        )
        P = sol.x.reshape(3, 4)
    # The calibration points were seen, so they are in front: that fixes C's sign for any camera.
    camera = Camera(P, width, height, in_front=X)
    res = _reprojection(camera.C, X, uv)
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    if not (np.isfinite(rms) and np.isfinite(linear_rms)):
        raise ValueError(_DEGENERATE_DLT)
    if not refine:
        return DLTResult(camera, rms, res, linear_rms)
    cov, factor = _dlt_cov(camera.C, X, res, w)
    if not (np.isfinite(cov).all() and np.isfinite(factor)):
        raise ValueError(_DEGENERATE_DLT)
    return DLTResult(camera, rms, res, linear_rms, cov, factor)


_DEGENERATE_DLT = (
    "the calibration points give no usable camera (they are nearly collinear or coplanar, or a point is on "
    "the camera's principal plane); use points spread over a 3D calibration object"
)


def _dlt_cov(C: np.ndarray, X: np.ndarray, res: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    """First-order covariance of C's 12 entries at the weighted least-squares optimum, gauge ⟂ C.

    Each point's (u, v) = (c₁·X̃, c₂·X̃) / (c₃·X̃); with unit weights 1/σ the inverse of the normal
    matrix JᵀJ is the covariance (scaled by χ²/dof when χ² is above its 99 % quantile). JᵀJ is singular along C itself
    (the scale), so the pseudo-inverse gives the minimum-norm gauge, orthogonal to C.
    """
    Xh = np.column_stack([X, np.ones(len(X))])
    s = Xh @ C[2]
    u = (Xh @ C[0]) / s
    v = (Xh @ C[1]) / s
    J = np.zeros((2 * len(X), 12))
    J[0::2, 0:4] = Xh / s[:, None]
    J[0::2, 8:12] = -(u / s)[:, None] * Xh
    J[1::2, 4:8] = Xh / s[:, None]
    J[1::2, 8:12] = -(v / s)[:, None] * Xh
    J *= np.repeat(w, 2)[:, None]
    dof = max(2 * len(X) - 11, 1)
    factor = float(np.sum((res * w[:, None]) ** 2) / dof)
    c = C.ravel() / np.linalg.norm(C)
    Pc = np.eye(12) - np.outer(c, c)
    cov = Pc @ np.linalg.pinv(J.T @ J, rcond=1e-12) @ Pc
    cov = 0.5 * (cov + cov.T)
    from scipy.stats import chi2  # here, not at the top (start-up)

    if factor * dof > chi2.ppf(0.99, dof):
        cov = cov * factor
    return cov, factor


def kabsch(X_b: np.ndarray, X_a: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Rigid ``T_a_b`` (4, 4) minimising Σ wᵢ ‖X_aᵢ − T_a_b X_bᵢ‖² (no scale); needs 3 non-collinear points."""
    X_b = finite_array(X_b, (None, 3), "X_b", max_abs=MAX_M, unit=" m", min_count=3)
    X_a = finite_array(X_a, (None, 3), "X_a", max_abs=MAX_M, unit=" m", min_count=3)
    if len(X_a) != len(X_b):
        raise ValueError(f"point sets differ in size: {len(X_b)} and {len(X_a)}")
    w = np.ones(len(X_a)) if weights is None else finite_array(weights, (len(X_a),), "weights")
    if np.any(w < 0) or not w.sum() > 0:
        raise ValueError(f"weights must be non-negative with a positive sum, got {w[:4].tolist()}…")
    cb = (w[:, None] * X_b).sum(0) / w.sum()
    ca = (w[:, None] * X_a).sum(0) / w.sum()
    H = ((X_b - cb) * w[:, None]).T @ (X_a - ca)
    U, sv, Vt = np.linalg.svd(H)
    if sv[1] <= 1e-9 * max(sv[0], 1e-300):
        raise ValueError("the points are collinear: a rigid transform needs 3 non-collinear points")
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return make_T(R, ca - R @ cb)


@dataclass(frozen=True)
class TurretCalibration:
    """T_world_turret (4, 4); cov (6, 6) of the pose in (rotation vector rad, translation m), the
    perturbation applied as ``T = T̂ · exp(δ)`` in the turret frame; rms_m and residuals_m
    (N, 3): measured (mapped to the world) minus known points, metres; linear_rms_m: Kabsch alone."""

    T_world_turret: np.ndarray
    cov: np.ndarray
    rms_m: float
    residuals_m: np.ndarray
    linear_rms_m: float


def _check_beams(pan: np.ndarray, tilt: np.ndarray, rho: np.ndarray) -> None:
    """ValueError for angles beyond ±1000 rad or ranges outside (0, MAX_M] (validated as finite)."""
    finite_array(pan, (None,), "pan_rad", max_abs=1e3, unit=" rad")
    finite_array(tilt, (None,), "tilt_rad", max_abs=1e3, unit=" rad")
    finite_array(rho, (None,), "range_m", max_abs=MAX_M, unit=" m")
    if np.any(rho <= 0):
        raise ValueError(f"ranges must be positive, got {rho[rho <= 0][:4].tolist()}")


def calibrate_turret(
    pan_rad: np.ndarray,
    tilt_rad: np.ndarray,
    range_m: np.ndarray,
    X_world: np.ndarray,
    spec: RangeFinderSpec = RangeFinderSpec(),
) -> TurretCalibration:
    """The turret's pose in the world from measurements of known points.

    pan_rad, tilt_rad, range_m : arrays, shape (N ≥ 3,), the beam that hit each known point.
    X_world : array, shape (N, 3), the known points, metres, not collinear.
    The refined estimate minimises the Mahalanobis distances under ``spec``'s noise model.
    """
    X_world = finite_array(X_world, (None, 3), "X_world", max_abs=MAX_M, unit=" m", min_count=3)
    pan, tilt, rho = (np.asarray(a, dtype=float).reshape(-1) for a in (pan_rad, tilt_rad, range_m))
    if not (len(pan) == len(tilt) == len(rho) == len(X_world)):
        raise ValueError(
            "pan, tilt, range and X_world must pair one to one, got "
            f"{len(pan)}, {len(tilt)}, {len(rho)}, {len(X_world)}"
        )
    if not (np.all(np.isfinite(pan)) and np.all(np.isfinite(tilt)) and np.all(np.isfinite(rho))):
        raise ValueError("a measurement is NaN or inf (a missed shot?): measure every point")
    _check_beams(pan, tilt, rho)
    X_turret = rho[:, None] * beam_direction(pan, tilt)
    T0 = kabsch(X_turret, X_world)
    lin_res = (X_turret @ T0[:3, :3].T + T0[:3, 3]) - X_world
    linear_rms = float(np.sqrt(np.mean(np.sum(lin_res**2, axis=1))))

    # Whitening in the turret frame, where each point's covariance does not depend on T.
    cov_t = beam_point_cov(np.eye(4), pan, tilt, rho, spec)
    W = np.linalg.inv(np.linalg.cholesky(cov_t))  # (N, 3, 3): Lᵢ⁻¹

    def residuals(x: np.ndarray) -> np.ndarray:
        T = T0 @ make_T(exp_so3(x[:3]), x[3:])
        X_in_turret = (X_world - T[:3, 3]) @ T[:3, :3]
        return np.einsum("nij,nj->ni", W, X_in_turret - X_turret).ravel()

    from scipy.optimize import least_squares  # here, not at the top (start-up)

    sol = least_squares(residuals, np.zeros(6), method="lm", xtol=1e-15, ftol=1e-15)
    T = T0 @ make_T(exp_so3(sol.x[:3]), sol.x[3:])
    J = sol.jac
    cov = np.linalg.pinv(J.T @ J)
    res = (X_turret @ T[:3, :3].T + T[:3, 3]) - X_world
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return TurretCalibration(T, cov, rms, res, linear_rms)


def calibrate_turret_planes(
    pan_rad: np.ndarray,
    tilt_rad: np.ndarray,
    range_m: np.ndarray,
    n_world: np.ndarray,
    d_world: np.ndarray,
    T_world_turret0: np.ndarray,
    spec: RangeFinderSpec = RangeFinderSpec(),
    prior: tuple[np.ndarray, np.ndarray] | None = None,
) -> TurretCalibration:
    """The turret's pose from measurements that land on known planes (not on known points).

    Minimises Σ (nᵢ·Xᵢ + dᵢ)² / σᵢ² over ``T_world_turret``, where Xᵢ is measurement i mapped to the
    world and σᵢ the standard deviation of its distance along nᵢ under ``spec``'s noise (range along
    the beam, a step's quantisation across). Gauss–Newton from ``T_world_turret0`` (the planes are
    fixed: to re-associate points with planes, call again from the result).

    pan_rad, tilt_rad, range_m : arrays, shape (N,). n_world : array, shape (N, 3), unit normals of
    the plane each point lies on; d_world : array, shape (N,), their offsets (n·X + d = 0).
    Needs N ≥ 6 points on planes of at least 3 independent normals (else ValueError), unless ``prior``
    = (T_prior (4, 4), cov (6, 6)) is given: a Gaussian prior on the pose, ``T = T_prior · exp(δ)``, δ of
    covariance cov (the calibration in use and its spread); the estimate is then the maximum a posteriori
    one from N ≥ 1 points, and its covariance includes the prior (e.g. to aim the next beam before the
    measurements alone fix the pose).
    The result's ``residuals_m`` (N, 3) is each point's offset from its plane, along the normal;
    its ``linear_rms_m`` is the RMS distance at the starting pose.
    """
    pan, tilt, rho = (np.asarray(a, dtype=float).reshape(-1) for a in (pan_rad, tilt_rad, range_m))
    N = np.asarray(n_world, dtype=float).reshape(-1, 3)
    d = np.asarray(d_world, dtype=float).reshape(-1)
    if not (len(pan) == len(tilt) == len(rho) == len(N) == len(d)):
        raise ValueError(f"inputs must pair one to one, got {len(pan)}, {len(tilt)}, {len(rho)}, {len(N)}, {len(d)}")
    if len(pan) < (1 if prior is not None else 6):
        raise ValueError(f"a pose on planes needs at least 6 measurements, got {len(pan)}")
    if not (np.all(np.isfinite(rho)) and np.all(rho > 0)):
        raise ValueError("ranges must be finite and positive (measure every point)")
    _check_beams(pan, tilt, rho)
    N = finite_array(N, (None, 3), "n_world")
    d = finite_array(d, (len(N),), "d_world", max_abs=MAX_M, unit=" m")
    norms = np.linalg.norm(N, axis=1)
    if not np.all(np.abs(norms - 1.0) <= 1e-6):
        raise ValueError(f"n_world must hold unit normals, got norms {norms[:4].tolist()}")
    T0 = check_T(T_world_turret0, "T_world_turret0")
    finite_array(T0[:3, 3], (3,), "T_world_turret0's translation", max_abs=MAX_M, unit=" m")
    sv = np.linalg.svd(N, compute_uv=False) if len(N) >= 3 else np.zeros(3)
    if prior is None and sv[2] <= 0.1 * sv[0]:
        raise ValueError("the planes have fewer than 3 independent normals: the pose is not fixed by them")
    prior_res = _prior_residual(prior)
    X_turret = rho[:, None] * beam_direction(pan, tilt)
    cov_t = beam_point_cov(np.eye(4), pan, tilt, rho, spec)

    def sigma_along(T: np.ndarray) -> np.ndarray:
        n_t = N @ T[:3, :3]  # the normals in the turret frame
        return np.sqrt(np.einsum("ni,nij,nj->n", n_t, cov_t, n_t))

    def residuals(x: np.ndarray, T_base: np.ndarray, sig: np.ndarray) -> np.ndarray:
        T = T_base @ make_T(exp_so3(x[:3]), x[3:])
        X = X_turret @ T[:3, :3].T + T[:3, 3]
        r = (np.einsum("ni,ni->n", N, X) + d) / sig
        return r if prior_res is None else np.concatenate([r, prior_res(T)])

    sig = sigma_along(T0)
    from scipy.optimize import least_squares  # here, not at the top (start-up)

    sol = least_squares(residuals, np.zeros(6), args=(T0, sig), method="lm", xtol=1e-15, ftol=1e-15)
    T = T0 @ make_T(exp_so3(sol.x[:3]), sol.x[3:])
    J = sol.jac
    cov = np.linalg.pinv(J.T @ J)
    X = X_turret @ T[:3, :3].T + T[:3, 3]
    dist = np.einsum("ni,ni->n", N, X) + d
    X0 = X_turret @ T0[:3, :3].T + T0[:3, 3]
    dist0 = np.einsum("ni,ni->n", N, X0) + d
    return TurretCalibration(
        T, cov, float(np.sqrt(np.mean(dist**2))), dist[:, None] * N, float(np.sqrt(np.mean(dist0**2)))
    )


def _prior_residual(prior):
    """The whitened residual T ↦ L⁻¹ δ(T), δ = (log R, t) of ``T_prior⁻¹ T``, of a pose prior
    (T_prior, cov); None without a prior."""
    if prior is None:
        return None
    T_p = check_T(prior[0], "the prior's pose")
    W = np.linalg.inv(np.linalg.cholesky(check_covariance(prior[1], 6, "the prior's covariance")))
    T_p_inv = invert_T(T_p)

    def res(T: np.ndarray) -> np.ndarray:
        rel = T_p_inv @ T
        return W @ np.concatenate([log_so3(rel[:3, :3]), rel[:3, 3]])

    return res


def turret_plane_rows(
    T_world_turret: np.ndarray,
    pan_rad: np.ndarray,
    tilt_rad: np.ndarray,
    range_m: np.ndarray,
    n_world: np.ndarray,
    spec: RangeFinderSpec = RangeFinderSpec(),
) -> np.ndarray:
    """The whitened rows (N, 6) of ``calibrate_turret_planes``' Jacobian at ``T_world_turret``: row i is
    d(nᵢ·Xᵢ + dᵢ)/dδ / σᵢ for the pose ``T · exp(δ)``, δ = (rotation vector, translation) in the turret
    frame. Their Gram matrix RᵀR is the pose's information: its inverse is the covariance the solve would
    state for beams (pan, tilt, range) landing on planes of normals ``n_world`` (N, 3) — known before
    the beams are measured, so where to aim next can be chosen (``next_turret_point``)."""
    pan, tilt, rho = (np.asarray(a, dtype=float).reshape(-1) for a in (pan_rad, tilt_rad, range_m))
    N = np.asarray(n_world, dtype=float).reshape(-1, 3)
    T = check_T(T_world_turret, "T_world_turret")
    X_turret = rho[:, None] * beam_direction(pan, tilt)
    n_t = N @ T[:3, :3]  # the normals in the turret frame
    cov_t = beam_point_cov(np.eye(4), pan, tilt, rho, spec)
    sig = np.sqrt(np.einsum("ni,nij,nj->n", n_t, cov_t, n_t))
    # X = R (exp(ω) Xt + v) + t: d(n·X)/dω = n_t·(ω × Xt) = ω·(Xt × n_t), d(n·X)/dv = n_t
    return np.hstack([np.cross(X_turret, n_t), n_t]) / sig[:, None]


D_OPTIMAL_ABOVE = 4.0  # next_turret_point: beyond this many times the target σ, the D-optimal point


def next_turret_point(
    rows_done: np.ndarray, rows_candidates: np.ndarray, scale: np.ndarray, prior_sd: np.ndarray
) -> tuple[int, np.ndarray]:
    """Which candidate beam, added to those done, leaves the turret pose's worst scaled σ smallest.

    rows_done (K, 6), rows_candidates (M ≥ 1, 6): ``turret_plane_rows``. scale (6,): each parameter's σ is
    divided by it before the worst is taken (e.g. 0.5° for the rotations, 5 mm for the translations, so
    both count); while the worst scaled σ is above D_OPTIMAL_ABOVE, the point that shrinks the pose's
    uncertainty volume most (D-optimal) is taken instead. prior_sd (6,): a weak prior on the pose (the
    current calibration's spread) that keeps the
    information invertible before six independent beams are in. Returns the candidate's index and the σ
    (6,) of the pose with it (rad, m)."""
    done = np.asarray(rows_done, float).reshape(-1, 6)
    cand = np.asarray(rows_candidates, float).reshape(-1, 6)
    if not len(cand):
        raise ValueError("no candidate point to choose from")
    info = done.T @ done + np.diag(1.0 / np.asarray(prior_sd, float) ** 2)
    C = np.linalg.inv(info)
    U = cand @ C  # (M, 6): C jᵢ (C symmetric)
    denom = 1.0 + np.einsum("mi,mi->m", U, cand)
    var = np.diag(C)[None, :] - U**2 / denom[:, None]  # Sherman–Morrison: diag of (info + jjᵀ)⁻¹
    worst = np.sqrt(np.maximum(var, 0.0)) / np.asarray(scale, float)[None, :]
    if (np.sqrt(np.diag(C)) / np.asarray(scale, float)).max() > D_OPTIMAL_ABOVE:
        # far from the target, the worst σ hardly moves whichever point is added (every other direction
        # is loose too): the point that shrinks the uncertainty's volume most, log det (I + jjᵀ) = log(1 + jᵀCj)
        k = int(np.argmax(np.einsum("mi,mi->m", U, cand)))
    else:
        k = int(np.argmin(worst.max(axis=1)))
    return k, np.sqrt(np.maximum(var[k], 0.0))


# ---------------------------------------------------------------------- moving a calibration through its σ
def check_covariance(cov, n: int, what: str) -> np.ndarray:
    """``cov`` as a finite symmetric (n, n) array; ValueError naming ``what`` otherwise."""
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (n, n) or not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T, rtol=1e-6, atol=0.0):
        raise ValueError(f"{what} must be a finite symmetric ({n}, {n}) covariance, got shape {cov.shape}")
    return cov


def principal_steps(cov: np.ndarray, floor: float = 1e-9) -> np.ndarray:
    """±1σ steps along a covariance's principal axes, shape (K, n): row k = √λ_k v_k; axes whose
    variance is below ``floor`` × the largest (a gauge, such as C's scale) are dropped."""
    cov = finite_array(cov, (None, None), "cov")
    if cov.shape[0] != cov.shape[1] or not 0.0 <= floor < 1.0:
        raise ValueError(f"cov must be square and floor in [0, 1), got shape {cov.shape}, floor {floor!r}")
    cov = 0.5 * (cov + cov.T)
    w, V = np.linalg.eigh(cov)
    keep = w > floor * max(float(w.max()), 0.0)
    return (V[:, keep] * np.sqrt(w[keep])).T


def perturbed_camera(camera: Camera, delta: np.ndarray) -> Camera:
    """The camera ``C + δ`` (δ: 12 entries, row major, as ``DLTResult.cov``), normalised as usual,
    with C's sign kept (the points in front stay in front)."""
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    Cp = camera.C + finite_array(np.ravel(delta), (12,), "delta", max_abs=1e6).reshape(3, 4)
    return Camera(Cp, camera.width, camera.height, in_front=camera.center + camera.C[2, :3])


def perturbed_turret(T_world_turret: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``T · exp(δ)``, δ = (rotation vector rad, translation m) in the turret frame — the
    convention of ``TurretCalibration.cov``."""
    d = finite_array(np.ravel(delta), (6,), "delta", max_abs=MAX_M)
    T = check_T(T_world_turret, "T_world_turret")
    finite_array(T[:3, 3], (3,), "T_world_turret's translation", max_abs=MAX_M, unit=" m")
    return T @ make_T(exp_so3(d[:3]), d[3:])
