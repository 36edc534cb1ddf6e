"""Fit the range finder's profile of a cylinder or cone with a known axis direction.

The paper's Fig. III.3: a horizontal scan gives the object's profile. With the axis direction
fixed (the operator's "vertical", or what the silhouettes give), the returns are fitted by a
surface of revolution: the axis position in the cross-section (2 numbers) and the radius (a
cylinder) or the radius at a reference height and its slope (a cone), by weighted least squares
on point-to-surface distances, each weighted by the point's variance along the surface normal.
The front tangent plane (the paper's P3) follows from the fitted profile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import Plane

__all__ = ["axis_basis", "ProfileFit", "fit_profile", "front_plane"]


def axis_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) completing the unit axis a to a right-handed frame (e1, e2, a)."""
    a = np.asarray(a, dtype=float)
    e1 = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


@dataclass(frozen=True)
class ProfileFit:
    """A surface of revolution fitted to range returns, with the axis direction held fixed.

    a : unit axis (3,). X0 : reference point (3,), metres; e1, e2 : the section basis.
    params : (y1, y2, r) for a cylinder, (y1, y2, r_ref, k) for a cone with r(t) = r_ref + k t,
    t = (X − X0)·a. cov : covariance of params. residuals_m : (N,) signed distances of the inliers.
    inliers : (N_all,) bool.
    """

    a: np.ndarray
    X0: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    params: np.ndarray
    cov: np.ndarray
    residuals_m: np.ndarray
    inliers: np.ndarray
    cone: bool

    def centre(self, t: float, params: np.ndarray | None = None) -> np.ndarray:
        p = self.params if params is None else params
        return self.X0 + t * self.a + p[0] * self.e1 + p[1] * self.e2

    def radius(self, t: float, params: np.ndarray | None = None) -> float:
        p = self.params if params is None else params
        return float(p[2] + (p[3] * t if self.cone else 0.0))


def _kasa(q: np.ndarray) -> tuple[np.ndarray, float]:
    A = np.column_stack([q, np.ones(len(q))])
    b = -(q**2).sum(axis=1)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    c = -0.5 * np.array([D, E])
    return c, float(np.sqrt(max(c @ c - F, 1e-12)))


def _residuals(params, q, t, cone):
    d = q - params[:2]
    rho = np.linalg.norm(d, axis=1)
    if not cone:
        return rho - params[2], d, rho
    k = params[3]
    s = np.sqrt(1.0 + k * k)
    return (rho - params[2] - k * t) / s, d, rho


def fit_profile(
    X_world: np.ndarray, covs: np.ndarray, a: np.ndarray, *, cone: bool = False, groups: np.ndarray | None = None,
    reject_sigma: float = 4.0,
) -> ProfileFit:
    """Weighted least-squares surface of revolution with axis direction a through the returns.

    X_world : array, shape (N, 3), metres; covs : array, shape (N, 3, 3), m²; a : unit axis (3,).
    groups : array, shape (N,), int, the scan of each point (a cone's start needs two scans).
    Points farther than ``reject_sigma`` σ from the first fit are dropped and the fit repeated.
    ValueError for too few points, or a cone measured at a single height.
    """
    X = np.asarray(X_world, dtype=float)
    n_par = 4 if cone else 3
    if len(X) < n_par + 1:
        raise ValueError(f"the profile fit needs at least {n_par + 1} returns on the object, got {len(X)}")
    a = np.asarray(a, dtype=float) / np.linalg.norm(a)
    e1, e2 = axis_basis(a)
    X0 = X.mean(axis=0)
    W0 = X - X0
    q = np.column_stack([W0 @ e1, W0 @ e2])
    t = W0 @ a
    groups = np.zeros(len(X), int) if groups is None else np.asarray(groups)
    if cone:
        ids = np.unique(groups)
        if len(ids) < 2:
            raise ValueError("a cone needs scans at two different heights (one scan gives one radius)")
        cs, rs, ts = [], [], []
        for g in ids:
            m = groups == g
            c, r = _kasa(q[m])
            cs.append(c)
            rs.append(r)
            ts.append(t[m].mean())
        k = float(np.polyfit(ts, rs, 1)[0]) if np.ptp(ts) > 1e-6 else 0.0
        params = np.array([*np.mean(cs, axis=0), np.mean(rs) - k * np.mean(ts), k])
    else:
        c, r = _kasa(q)
        params = np.array([c[0], c[1], r])
    inl = np.ones(len(X), bool)
    for rnd in range(2):
        for _ in range(50):
            res, d, rho = _residuals(params, q[inl], t[inl], cone)
            radial = (d / rho[:, None]) @ np.vstack([e1, e2])
            k = params[3] if cone else 0.0
            nrm = (radial - k * a) / np.sqrt(1 + k * k)
            sig = np.sqrt(np.maximum(np.einsum("ni,nij,nj->n", nrm, covs[inl], nrm), 1e-18))
            J = np.zeros((len(res), n_par))
            s = np.sqrt(1 + k * k)
            J[:, :2] = -d / rho[:, None] / s
            J[:, 2] = -1.0 / s
            if cone:
                J[:, 3] = -t[inl] / s - res * k / (1 + k * k)
            Jw = J / sig[:, None]
            step, *_ = np.linalg.lstsq(Jw, -res / sig, rcond=None)
            params = params + step
            if np.linalg.norm(step) < 1e-13:
                break
        if rnd == 0:
            # Reject by each point's σ along the surface normal.
            res_all, d, rho = _residuals(params, q, t, cone)
            radial = (d / rho[:, None]) @ np.vstack([e1, e2])
            kk = params[3] if cone else 0.0
            nrm = (radial - kk * a) / np.sqrt(1 + kk * kk)
            sig_all = np.sqrt(np.maximum(np.einsum("ni,nij,nj->n", nrm, covs, nrm), 1e-18))
            keep = np.abs(res_all) <= reject_sigma * sig_all
            if keep.sum() < n_par + 1 or keep.all():
                break
            inl = keep
    H = Jw.T @ Jw
    cov = np.linalg.inv(H)
    res, _, _ = _residuals(params, q[inl], t[inl], cone)
    if params[2] <= 0:
        raise ValueError("the range profile does not look like a cylinder or cone (fitted radius ≤ 0)")
    return ProfileFit(a, X0, e1, e2, params, 0.5 * (cov + cov.T), res, inl, cone)


def front_plane(fit: ProfileFit, origin_world: np.ndarray, t: float, params: np.ndarray | None = None) -> Plane:
    """The paper's P3: the plane tangent to the fitted surface along the generator facing the sensor.

    origin_world : the range finder's origin (3,); t : axial coordinate where the facing
    direction is taken. Orientation: positive towards the axis (inside the object).
    """
    p = fit.params if params is None else params
    C = fit.centre(t, p)
    w = C - np.asarray(origin_world, dtype=float)
    u = w - (w @ fit.a) * fit.a
    u /= np.linalg.norm(u)
    k = p[3] if fit.cone else 0.0
    n = (u + k * fit.a) / np.sqrt(1 + k * k)
    X_front = C - fit.radius(t, p) * u
    return Plane(n, float(-n @ X_front))
