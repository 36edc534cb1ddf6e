"""Robust pose refinement from points measured across projected model edges (the tracker's step).

Finds T_world_obj minimising Σ ρ(n_i·(m_i − π(X_i))) over samples X_i on model edges (object
frame) and image points m_i measured along the normals n_i of the projected edges: the distance
of each measured point to the tangent line of its projected model edge. This is the paper's small-motion
step (linearised rotation, least squares, §IV) iterated (Gauss–Newton) with the residuals in
pixels and a robust loss (Huber or Tukey, scale from the median absolute deviation), the
"moving edges" formulation of model-based trackers (Comport, Marchand et al., 2006).

The camera is the global model C (DESIGN.md); the projection Jacobian is written on C. The
normal n_i is recomputed at every iteration from the projected edge direction; only the distance
across the edge is measured, so a sample may slide along its edge.

Why not the pose pipeline's refinement (``core.pose.refine_views``), whose clicked segment is the same
point-to-projected-line distance: that one is the maximum-likelihood pose for clicks of *known* noise
σ (weights 1/σ², a Huber loss at a fixed pixel threshold, covariance (Jᵀ W J)⁻¹ without rescaling).
The tracker's hundreds of edge points a frame have no known σ and many gross outliers (an occluder's
edge, a shadow): its scale is estimated from their spread at every iteration (the median absolute
deviation), Tukey's loss gives those outliers no say at all, each sample carries a prior weight (its edge
strength), and the covariance is scaled by the residuals' variance. Both down-weight through
``core.robust``.

Pose perturbation, as in ``core.pose``: δ = (δt, δr), δt a translation of the object's origin in
the world frame (metres), δr a rotation vector in world axes about the object's origin::

    R ← exp([δr]×) R,    t ← t + δt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .robust import LOSSES, robust_weights
from .transforms import check_T, exp_so3, make_T

__all__ = ["PointLineFit", "point_line_residuals", "robust_weights", "refine_point_to_line"]

_LOSSES = LOSSES


@dataclass(frozen=True)
class PointLineFit:
    """Result of ``refine_point_to_line``.

    T_world_obj : array, shape (4, 4), the refined pose.
    residuals_px : array, shape (N,), signed distances (pixels) of the measured points to their
        projected edge lines at the refined pose.
    weights : array, shape (N,), the robust weights in [0, 1] of the last iteration.
    scale_px : float, the robust scale of the residuals (pixels) at the last iteration.
    cov : array, shape (6, 6), covariance of δ = (δt [m], δr [rad]) at the solution (the inverse
        weighted normal matrix times the residual variance).
    iterations : int, Gauss–Newton iterations done.
    converged : bool, the last step moved every sample less than ``tol_px``.
    """

    T_world_obj: np.ndarray
    residuals_px: np.ndarray
    weights: np.ndarray
    scale_px: float
    cov: np.ndarray
    iterations: int
    converged: bool

    @property
    def rms_px(self) -> float:
        """Weighted RMS of the residuals (pixels)."""
        w = self.weights
        return float(np.sqrt(np.sum(w * self.residuals_px**2) / max(np.sum(w), 1e-12)))


def _check_inputs(X_obj, D_obj, uv):
    X = np.asarray(X_obj, dtype=float)
    D = np.asarray(D_obj, dtype=float)
    m = np.asarray(uv, dtype=float)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"X_obj must have shape (N, 3), got {X.shape}")
    if D.shape != X.shape:
        raise ValueError(f"D_obj must have the shape of X_obj {X.shape}, got {D.shape}")
    if m.shape != (len(X), 2):
        raise ValueError(f"uv must have shape ({len(X)}, 2) (one measured pixel per sample), got {m.shape}")
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(D)) and np.all(np.isfinite(m))):
        raise ValueError("X_obj, D_obj and uv must be finite (drop the samples where no edge was found)")
    return X, D, m


def point_line_residuals(
    camera: Camera, T_world_obj: np.ndarray, X_obj: np.ndarray, D_obj: np.ndarray, uv: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed point-to-projected-line distances and their Jacobian.

    Parameters
    ----------
    camera : Camera
    T_world_obj : array, shape (4, 4)
    X_obj : array, shape (N, 3), metres, object frame: sample points on model edges.
    D_obj : array, shape (N, 3), object frame: the edges' directions at the samples (any length).
    uv : array, shape (N, 2), pixels: the measured image points.

    Returns
    -------
    r : array, shape (N,), pixels: n·(uv − π(X)), n the unit normal (rotated +90° on the screen
        from the projected direction of D) of the projected edge at π(X).
    J : array, shape (N, 6): ∂r/∂δ for δ = (δt, δr) (see the module docstring).
    n : array, shape (N, 2): the unit normals used.
    Samples behind the camera (depth ≤ 0) raise ValueError.
    """
    T = np.asarray(T_world_obj, dtype=float)
    R, t = T[:3, :3], T[:3, 3]
    Xw = X_obj @ R.T + t
    Dw = D_obj @ R.T
    C = camera.C
    h = Xw @ C[:, :3].T + C[:, 3]
    s = h[:, 2]
    if np.any(s <= 1e-9):
        raise ValueError(f"{int(np.sum(s <= 1e-9))} sample(s) lie behind the camera at this pose")
    u = h[:, 0] / s
    v = h[:, 1] / s
    # Rows of the projection Jacobian ∂(u, v)/∂X on C: (C0 − u C2)/s and (C1 − v C2)/s.
    Ju = (C[0, :3][None, :] - u[:, None] * C[2, :3][None, :]) / s[:, None]
    Jv = (C[1, :3][None, :] - v[:, None] * C[2, :3][None, :]) / s[:, None]
    du = np.einsum("ij,ij->i", Ju, Dw)
    dv = np.einsum("ij,ij->i", Jv, Dw)
    norm = np.hypot(du, dv)
    if np.any(norm <= 1e-12):
        raise ValueError("an edge is seen end-on (its projection is a point); drop those samples")
    n = np.column_stack([-dv, du]) / norm[:, None]
    r = n[:, 0] * (uv[:, 0] - u) + n[:, 1] * (uv[:, 1] - v)
    a = n[:, :1] * Ju + n[:, 1:] * Jv  # ∂(n·π)/∂X, shape (N, 3)
    J = -np.hstack([a, np.cross(Xw - t, a)])
    return r, J, n


def _mad_scale(r: np.ndarray) -> float:
    return 1.4826 * float(np.median(np.abs(r - np.median(r))))


def refine_point_to_line(
    camera: Camera,
    T_world_obj: np.ndarray,
    X_obj: np.ndarray,
    D_obj: np.ndarray,
    uv: np.ndarray,
    *,
    loss: str = "tukey",
    scale_px: float | None = None,
    min_scale_px: float = 0.3,
    sample_weights: np.ndarray | None = None,
    max_iter: int = 10,
    tol_px: float = 1e-3,
    damping: float = 1e-9,
) -> PointLineFit:
    """Iterated robust small-motion step: the pose that puts the projected edges on the measured points.

    Parameters
    ----------
    camera : Camera
    T_world_obj : array, shape (4, 4), the starting pose (e.g. the previous frame's).
    X_obj : array, shape (N, 3), metres, object frame: sample points on model edges.
    D_obj : array, shape (N, 3), object frame: the edge directions at the samples.
    uv : array, shape (N, 2), pixels: the image edge point measured for each sample.
    loss : "l2", "huber" or "tukey" (default; rejects gross outliers completely).
    scale_px : float, optional
        The residuals' scale (pixels). Default: estimated at every iteration from the median
        absolute deviation, never below ``min_scale_px``.
    sample_weights : array, shape (N,), optional
        Prior weights (e.g. edge strength), multiplied with the robust ones.
    max_iter : int; tol_px : stop when a step moves every sample's projection less than this.
    damping : relative Levenberg damping of the normal matrix (keeps a step defined when few
        edges constrain the pose, e.g. a single visible face).

    Returns
    -------
    PointLineFit
    """
    T = check_T(T_world_obj, "T_world_obj").copy()
    X, D, m = _check_inputs(X_obj, D_obj, uv)
    if loss not in _LOSSES:
        raise ValueError(f"loss must be one of {_LOSSES}, got {loss!r}")
    N = len(X)
    if N < 6:
        raise ValueError(f"a pose has 6 degrees of freedom: give at least 6 samples, got {N}")
    if scale_px is not None and not scale_px > 0:
        raise ValueError(f"scale_px must be positive, got {scale_px}")
    w0 = np.ones(N) if sample_weights is None else np.asarray(sample_weights, dtype=float).reshape(N)
    if np.any(w0 < 0) or not np.all(np.isfinite(w0)):
        raise ValueError("sample_weights must be finite and non-negative")
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count of iterations, returned
        r, J, _ = point_line_residuals(camera, T, X, D, m)
        scale = scale_px if scale_px is not None else max(_mad_scale(r), min_scale_px)
        w = w0 * robust_weights(r, loss, scale)
        if np.count_nonzero(w) < 6:
            break
        A = J.T @ (w[:, None] * J)
        b = J.T @ (w * r)
        A += damping * np.trace(A) / 6.0 * np.eye(6)
        delta = -np.linalg.solve(A, b)
        T = make_T(exp_so3(delta[3:]) @ T[:3, :3], T[:3, 3] + delta[:3])
        if np.max(np.abs(J @ delta)) < tol_px:
            converged = True
            break
    r, J, _ = point_line_residuals(camera, T, X, D, m)
    scale = scale_px if scale_px is not None else max(_mad_scale(r), min_scale_px)
    w = w0 * robust_weights(r, loss, scale)
    A = J.T @ (w[:, None] * J)
    dof = max(float(np.sum(w > 0)) - 6.0, 1.0)
    sigma2 = float(np.sum(w * r * r) / dof)
    try:
        cov = sigma2 * np.linalg.inv(A)
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.inf)
    return PointLineFit(T, r, w, float(scale), cov, it, converged)
