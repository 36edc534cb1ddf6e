"""Planes, 3D lines, their intersections and distances, and plane fitting.

Conventions (DESIGN.md §Frames): a plane is ``(n, d)`` with unit normal n and ``n·X + d = 0``;
a 3D line is ``(point, unit direction)``. Every point is in metres, in whatever frame the caller
uses consistently. ``Plane`` and ``Line`` are named tuples, so ``n, d = plane`` works.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = [
    "Plane",
    "Line",
    "PlaneFit",
    "as_points",
    "make_plane",
    "plane_from_points",
    "plane_through_point",
    "signed_distance",
    "project_onto_plane",
    "intersect_planes",
    "intersect_line_plane",
    "point_from_planes",
    "bisecting_planes",
    "distance_point_line",
    "closest_points_lines",
    "distance_lines",
    "line_from_points",
    "angle_between_planes",
    "fit_plane_ols",
    "fit_plane_tls",
    "hull_overlap",
]

_EPS_PARALLEL = 1e-9


class Plane(NamedTuple):
    """Plane ``n·X + d = 0``; n : array, shape (3,), unit; d : float, metres."""

    n: np.ndarray
    d: float

    def flipped(self) -> Plane:
        """The same plane with the opposite orientation."""
        return Plane(-self.n, -self.d)

    def as_vector(self) -> np.ndarray:
        """Homogeneous 4-vector (n, d)."""
        return np.append(self.n, self.d)


class Line(NamedTuple):
    """3D line through ``point`` (3,) along unit ``direction`` (3,)."""

    point: np.ndarray
    direction: np.ndarray

    def at(self, s: np.ndarray | float) -> np.ndarray:
        """Points at signed abscissa s (metres) along the line: shape (3,) or (N, 3)."""
        s = np.asarray(s, dtype=float)
        return self.point + s[..., None] * self.direction


def as_points(X: np.ndarray, name: str = "X", min_count: int = 1) -> np.ndarray:
    """Validate an (N, 3) finite array of points and return it as float."""
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {X.shape}")
    if X.shape[0] < min_count:
        raise ValueError(f"{name} needs at least {min_count} points, got {X.shape[0]}")
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{name} contains NaN or inf")
    return X


def _as_vec3(v: np.ndarray, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be a finite 3-vector, got {v}")
    return v


def make_plane(n: np.ndarray, d: float) -> Plane:
    """Plane from any non-zero normal and offset (``n·X + d = 0``), normalised to a unit normal."""
    n = _as_vec3(n, "plane normal")
    norm = np.linalg.norm(n)
    if norm < 1e-300 or not np.isfinite(d):
        raise ValueError(f"a plane needs a non-zero normal and a finite offset, got n={n}, d={d}")
    return Plane(n / norm, float(d) / norm)


def plane_through_point(n: np.ndarray, X: np.ndarray) -> Plane:
    """Plane with normal n through the point X (3,)."""
    n = _as_vec3(n, "plane normal")
    X = _as_vec3(X, "point")
    p = make_plane(n, 0.0)
    return Plane(p.n, float(-p.n @ X))


def plane_from_points(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> Plane:
    """Plane through three points, normal along ``(B − A) × (C − A)``.

    ValueError when the points are collinear (to 1e-12 of the square of their spread).
    """
    A, B, C = (_as_vec3(P, "point") for P in (A, B, C))
    n = np.cross(B - A, C - A)
    scale = max(np.linalg.norm(B - A), np.linalg.norm(C - A), 1e-300)
    if np.linalg.norm(n) <= 1e-12 * scale**2:
        raise ValueError("the three points are collinear: they do not define a plane")
    return plane_through_point(n, A)


def signed_distance(plane: Plane, X: np.ndarray) -> np.ndarray | float:
    """Signed distance ``n·X + d`` (metres) of X, shape (3,) → float or (N, 3) → (N,)."""
    n, d = plane
    X = np.asarray(X, dtype=float)
    out = X @ n + d
    return float(out) if X.ndim == 1 else out


def project_onto_plane(plane: Plane, X: np.ndarray) -> np.ndarray:
    """Orthogonal projection of points X, shape (3,) or (N, 3), onto the plane."""
    n, d = plane
    X = np.asarray(X, dtype=float)
    return X - (X @ n + d)[..., None] * n


def intersect_planes(p1: Plane, p2: Plane) -> Line:
    """Line where two planes meet; the point returned is the one nearest the origin.

    ValueError when the planes are parallel (normals within ~1e-9 rad).
    """
    n1, d1 = p1
    n2, d2 = p2
    u = np.cross(n1, n2)
    norm = np.linalg.norm(u)
    if norm < _EPS_PARALLEL:
        raise ValueError("the two planes are parallel: they have no line of intersection")
    # Point nearest the origin: solve [n1; n2; u] X = [-d1; -d2; 0].
    A = np.vstack([n1, n2, u])
    X = np.linalg.solve(A, np.array([-d1, -d2, 0.0]))
    return Line(X, u / norm)


def intersect_line_plane(line: Line, plane: Plane) -> np.ndarray:
    """Point (3,) where a line crosses a plane; ValueError when the line is parallel to it."""
    P, u = line
    n, d = plane
    denom = float(n @ u)
    if abs(denom) < _EPS_PARALLEL:
        raise ValueError("the line is parallel to the plane: no single intersection point")
    s = -(n @ P + d) / denom
    return P + s * u


def point_from_planes(planes: Sequence[Plane], weights: np.ndarray | None = None, return_cov: bool = False):
    """Least-squares point of k ≥ 3 planes: minimises Σ wᵢ (nᵢ·X + dᵢ)².

    planes : sequence of k Plane; weights : array, shape (k,), optional (1/σᵢ², 1/m²).
    Returns X : array, shape (3,), and when ``return_cov`` the covariance (3, 3) of X given
    the weights as inverse variances of each plane's offset (m²).
    ValueError when fewer than 3 planes or when their normals do not span 3D.
    """
    if len(planes) < 3:
        raise ValueError(f"a point needs at least 3 planes, got {len(planes)}")
    N = np.array([p[0] for p in planes], dtype=float)
    d = np.array([p[1] for p in planes], dtype=float)
    w = np.ones(len(planes)) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (len(planes),) or np.any(w < 0):
        raise ValueError(f"weights must be non-negative, shape ({len(planes)},), got {w.shape}")
    A = N.T @ (w[:, None] * N)
    sv = np.linalg.svd(A, compute_uv=False)
    if sv[-1] <= 1e-10 * sv[0]:
        raise ValueError(
            "the planes' normals do not span 3D (they share a common direction): "
            "their least-squares point is not unique"
        )
    X = np.linalg.solve(A, -(N.T @ (w * d)))
    if return_cov:
        return X, np.linalg.inv(A)
    return X


def bisecting_planes(p1: Plane, p2: Plane) -> tuple[Plane, Plane]:
    """The two planes bisecting the dihedral angles of p1 and p2 (points equidistant from both).

    The first returned is ``{X : dist1(X) = dist2(X)}`` with signed distances, the second is
    ``{X : dist1(X) = −dist2(X)}``. With both planes' normals pointing into a wedge, the first
    bisects the wedge that contains the points on the positive side of both. ValueError when
    the planes are parallel (their bisector is then not a single well-defined pair).
    """
    n1, d1 = p1
    n2, d2 = p2
    if np.linalg.norm(np.cross(n1, n2)) < _EPS_PARALLEL:
        raise ValueError("the two planes are parallel: no dihedral angle to bisect")
    return make_plane(n1 - n2, d1 - d2), make_plane(n1 + n2, d1 + d2)


def line_from_points(A: np.ndarray, B: np.ndarray) -> Line:
    """Line through two distinct points, directed from A to B."""
    A, B = _as_vec3(A, "point"), _as_vec3(B, "point")
    u = B - A
    norm = np.linalg.norm(u)
    if norm < 1e-12 * max(1.0, np.linalg.norm(A)):
        raise ValueError("the two points coincide: they do not define a line")
    return Line(A, u / norm)


def distance_point_line(X: np.ndarray, line: Line) -> np.ndarray | float:
    """Distance (metres) from X, shape (3,) or (N, 3), to a line."""
    P, u = line
    X = np.asarray(X, dtype=float)
    D = X - P
    out = np.linalg.norm(D - (D @ u)[..., None] * u, axis=-1)
    return float(out) if X.ndim == 1 else out


def closest_points_lines(l1: Line, l2: Line) -> tuple[np.ndarray, np.ndarray]:
    """The pair of closest points (on l1, on l2); for parallel lines, l1's point and its foot."""
    P1, u1 = l1
    P2, u2 = l2
    w = P1 - P2
    b = float(u1 @ u2)
    denom = 1.0 - b * b
    if denom < 1e-14:
        s1 = 0.0
        s2 = float(w @ u2)
    else:
        d1, d2 = float(u1 @ w), float(u2 @ w)
        s1 = (b * d2 - d1) / denom
        s2 = (d2 - b * d1) / denom
    return P1 + s1 * u1, P2 + s2 * u2


def distance_lines(l1: Line, l2: Line) -> float:
    """Shortest distance (metres) between two 3D lines."""
    A, B = closest_points_lines(l1, l2)
    return float(np.linalg.norm(A - B))


def angle_between_planes(p1: Plane, p2: Plane) -> float:
    """Unsigned angle (radians, in [0, π/2]) between two planes' normals, orientation ignored."""
    c = abs(float(np.asarray(p1[0]) @ np.asarray(p2[0])))
    return float(np.arccos(np.clip(c, 0.0, 1.0)))


@dataclass(frozen=True)
class PlaneFit:
    """A fitted plane and its uncertainty.

    plane : the fitted Plane (unit n).
    cov : array, shape (4, 4), covariance of the 4-vector (n, d), rank 3 (n stays unit).
    rms_m : root mean square of the point-to-plane residuals, metres.
    residuals_m : array, shape (N,), signed point-to-plane distances, metres.
    sigma_m : the noise level used for ``cov`` (given, or estimated from the residuals).
    method : "ols" (the paper's ``ax + by + z + d = 0``) or "tls" (total least squares).
    params : for "ols", (a, b, d) of the paper's form; for "tls", (n, d) as a 4-vector.
    """

    plane: Plane
    cov: np.ndarray
    rms_m: float
    residuals_m: np.ndarray
    sigma_m: float
    method: str
    params: np.ndarray


def _check_fit_points(X: np.ndarray) -> np.ndarray:
    X = as_points(X, "points", min_count=3)
    C = X - X.mean(axis=0)
    sv = np.linalg.svd(C, compute_uv=False)
    if sv[1] <= 1e-9 * max(sv[0], 1e-300):
        raise ValueError(
            f"the {len(X)} points are collinear (or coincide): they do not define a plane; "
            "measure points spread over the face"
        )
    return X


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def _plane_cov(X: np.ndarray, plane: Plane, sigma: float, w: np.ndarray | None = None) -> np.ndarray:
    """Covariance of (n, d) for point noise σ/√wᵢ, by linearising n·X + d = 0 about the fit.

    The normal moves in its tangent plane (two angles), the offset freely: J = [e1·X, e2·X, 1].
    """
    n, _ = plane
    e1, e2 = _tangent_basis(n)
    J = np.column_stack([X @ e1, X @ e2, np.ones(len(X))])
    w = np.ones(len(X)) if w is None else w
    cov3 = sigma**2 * np.linalg.inv(J.T @ (w[:, None] * J))
    B = np.zeros((4, 3))
    B[:3, 0] = e1
    B[:3, 1] = e2
    B[3, 2] = 1.0
    return B @ cov3 @ B.T


def fit_plane_ols(X: np.ndarray, sigma_m: float | None = None) -> PlaneFit:
    """The paper's plane fit (§III.1): ordinary least squares of ``a x + b y + z + d = 0`` on z.

    X : array, shape (N ≥ 3, 3), points in metres. sigma_m : point noise (m); estimated from the
    residuals when None (needs N > 3 for a non-zero estimate).
    The form cannot represent a plane parallel to z (a vertical face with the table's z up):
    ValueError then, with the advice to use ``fit_plane_tls``. The covariance of (a, b, d) is
    σ_z² (AᵀA)⁻¹ with σ_z the residual scatter along z, carried to (n, d) by the Jacobian.
    """
    X = _check_fit_points(X)
    A = np.column_stack([X[:, 0], X[:, 1], np.ones(len(X))])
    B = -X[:, 2]
    sol, _, rank, _ = np.linalg.lstsq(A, B, rcond=None)
    a, b, d = sol
    m = np.array([a, b, 1.0])
    norm = float(np.linalg.norm(m))
    if rank < 3 or norm > 1e6:
        raise ValueError(
            "the face is (nearly) parallel to the z axis: the paper's form ax + by + z + d = 0 "
            "cannot represent it; use fit_plane_tls"
        )
    plane = Plane(m / norm, float(d) / norm)
    resid_z = A @ sol - B  # residual along z of the paper's equation
    residuals = X @ plane.n + plane.d
    if sigma_m is None:
        dof = len(X) - 3
        sigma_z = float(np.sqrt(resid_z @ resid_z / dof)) if dof > 0 else 0.0
    else:
        sigma_z = float(sigma_m) * norm  # a point-to-plane σ seen along z
    cov_abd = sigma_z**2 * np.linalg.inv(A.T @ A)
    # (n, d) = (a, b, 1, d) / ‖(a, b, 1)‖: Jacobian with respect to (a, b, d).
    Jm = (np.eye(3) - np.outer(m, m) / norm**2) / norm  # d(m/|m|)/dm
    J = np.zeros((4, 3))
    J[:3, 0] = Jm[:, 0]
    J[:3, 1] = Jm[:, 1]
    J[3, 0] = -d * a / norm**3
    J[3, 1] = -d * b / norm**3
    J[3, 2] = 1.0 / norm
    cov = J @ cov_abd @ J.T
    rms = float(np.sqrt(np.mean(residuals**2)))
    return PlaneFit(plane, cov, rms, residuals, sigma_z / norm, "ols", np.array([a, b, d]))


def fit_plane_tls(X: np.ndarray, sigma_m: float | None = None, weights: np.ndarray | None = None) -> PlaneFit:
    """Total least squares plane: minimises Σ wᵢ (n·Xᵢ + d)² over unit n (smallest singular vector).

    X : array, shape (N ≥ 3, 3), metres. sigma_m : isotropic point noise (m), estimated from the
    residuals when None. weights : array, shape (N,), optional non-negative per-point weights.
    Works for any orientation. ``cov`` is the linearised covariance of (n, d).
    """
    X = _check_fit_points(X)
    w = np.ones(len(X)) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (len(X),) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"weights must be non-negative, not all zero, shape ({len(X)},)")
    centroid = (w[:, None] * X).sum(axis=0) / w.sum()
    D = (X - centroid) * np.sqrt(w)[:, None]
    _, _, Vt = np.linalg.svd(D, full_matrices=False)
    n = Vt[-1]
    plane = Plane(n, float(-n @ centroid))
    residuals = X @ plane.n + plane.d
    if sigma_m is None:
        dof = len(X) - 3
        sigma = float(np.sqrt((w * residuals) @ residuals / dof)) if dof > 0 else 0.0
    else:
        sigma = float(sigma_m)
    cov = _plane_cov(X, plane, sigma, w)
    rms = float(np.sqrt(np.mean(residuals**2)))
    return PlaneFit(plane, cov, rms, residuals, sigma, "tls", plane.as_vector())


def hull_overlap(A: np.ndarray, B: np.ndarray, n_samples: int = 4000, seed: int = 0) -> float:
    """The share of the convex hull of points A's volume that lies inside the convex hull of B.

    A, B : arrays, shape (N, 3), metres (e.g. two objects' vertices in the world). Returns a number in
    [0, 1]: 0 when the hulls are apart (or A has no volume), 1 when A's hull lies inside B's. Monte
    Carlo over ``n_samples`` points drawn uniformly in A's hull (seeded: the same answer every call;
    its standard error is at most 0.5/√n_samples, 0.008 at the default). B's hull is exact (its faces'
    half-spaces). A flat or degenerate B holds no volume: 0.
    """
    A = as_points(A, "A", 4)
    B = as_points(B, "B", 4)
    if int(n_samples) < 1:
        raise ValueError(f"n_samples must be at least 1, got {n_samples}")
    lo, hi = np.maximum(A.min(0), B.min(0)), np.minimum(A.max(0), B.max(0))
    if np.any(lo > hi):
        return 0.0
    from scipy.spatial import ConvexHull, Delaunay, QhullError  # lazily: start-up imports no scipy.spatial

    try:
        tets = Delaunay(A).simplices
        planes = ConvexHull(B).equations
    except QhullError:  # coplanar or too few distinct points: no volume
        return 0.0
    V = A[tets]  # (T, 4, 3)
    vol = np.abs(np.linalg.det(V[:, 1:] - V[:, :1])) / 6.0
    if not vol.sum() > 0:
        return 0.0
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tets), size=int(n_samples), p=vol / vol.sum())
    w = rng.dirichlet(np.ones(4), size=int(n_samples))  # uniform in a tetrahedron
    P = np.einsum("nk,nkj->nj", w, V[pick])
    scale = max(float(np.ptp(B, axis=0).max()), 1e-12)
    inside = np.all(P @ planes[:, :3].T + planes[:, 3] <= 1e-9 * scale, axis=1)
    return float(inside.mean())
