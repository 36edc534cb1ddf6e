"""Fit the range finder's profile of a cylinder or cone with a known axis direction.

The paper's Fig. III.3: a horizontal scan gives the object's profile. With the axis direction
fixed (the operator's "vertical", or what the silhouettes give), the returns are fitted by a
surface of revolution — the axis position in the cross-section (2 numbers) and the radius (a
cylinder) or the radius at a reference height and its slope (a cone) — by maximum likelihood on
the ranges along their beams (``returns.range_residuals``), with a Huber loss at 3σ against stray
returns. The front tangent plane (the paper's P3) follows from the fitted profile.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..geometry import Plane
from ..robust import huber_weights
from .lm import levenberg_marquardt
from .returns import MIN_INCIDENCE_COS, Returns, incidence_cos, range_residuals

__all__ = ["axis_basis", "ProfileFit", "fit_profile", "front_plane", "front_plane_jacobian"]


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
    t = (X − X0)·a. cov : covariance of params. residuals : normalised residuals of the returns
    used (those away from grazing). inliers : (N,) bool, returns used and within 3σ.
    """

    a: np.ndarray
    X0: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    params: np.ndarray
    cov: np.ndarray
    residuals: np.ndarray
    inliers: np.ndarray
    cone: bool

    def centre(self, t: float, params: np.ndarray | None = None) -> np.ndarray:
        """Axis point (3,) at axial coordinate t."""
        p = self.params if params is None else params
        return self.X0 + t * self.a + p[0] * self.e1 + p[1] * self.e2

    def radius(self, t: float, params: np.ndarray | None = None) -> float:
        """Radius (m) at axial coordinate t."""
        p = self.params if params is None else params
        return float(p[2] + (p[3] * t if self.cone else 0.0))


def _kasa(q: np.ndarray) -> tuple[np.ndarray, float]:
    A = np.column_stack([q, np.ones(len(q))])
    b = -(q**2).sum(axis=1)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    c = -0.5 * np.array([D, E])
    return c, float(np.sqrt(max(c @ c - F, 1e-12)))


# The last fits, by their inputs' bytes. No lock (core/ stays free of threading): each OrderedDict
# operation is atomic under the GIL, and a fit evicted by another thread between two is fitted again.
_RECENT: OrderedDict[bytes, ProfileFit] = OrderedDict()
_RECENT_MAX = 16


def fit_profile(ret: Returns, a: np.ndarray, *, cone: bool = False, groups: np.ndarray | None = None) -> ProfileFit:
    """Maximum-likelihood surface of revolution with axis direction a through range returns.

    ret : Returns (beams, ranges, noise). a : unit axis (3,). groups : array, shape (N,), int,
    the scan of each return (a cone's starting values need two scans at different heights).
    ValueError for too few returns, a cone measured at a single height, or no plausible radius.

    The fit is a pure function of its inputs, and the cylinder methods fit the same profile
    several times (the tangential constructions, the fused fit's start, rebuilds through another
    camera calibration): the last few fits are kept by their inputs' exact bytes and returned
    again (read-only arrays).
    """
    h = hashlib.blake2b(digest_size=20)
    for x in (
        ret.origin,
        ret.dirs,
        ret.range_m,
        ret.e_pan,
        ret.e_tilt,
        ret.sigma_pan_rad,
        ret.sigma_tilt_rad,
        [ret.sigma_range_m],
        a,
        [float(cone)],
        np.zeros(0) if groups is None else groups,
    ):
        x = np.ascontiguousarray(x, dtype=float)
        h.update(repr(x.shape).encode())
        h.update(x.tobytes())
    key = h.digest()
    fit = _RECENT.get(key)
    if fit is not None:
        try:
            _RECENT.move_to_end(key)
        except KeyError:  # evicted meanwhile: still the right fit
            pass
        return fit
    fit = _fit_profile(ret, a, cone=cone, groups=groups)
    for x in (fit.a, fit.X0, fit.e1, fit.e2, fit.params, fit.cov, fit.residuals, fit.inliers):
        x.setflags(write=False)
    _RECENT[key] = fit
    while len(_RECENT) > _RECENT_MAX:
        try:
            _RECENT.popitem(last=False)
        except KeyError:  # emptied meanwhile
            break
    return fit


def _fit_profile(ret: Returns, a: np.ndarray, *, cone: bool, groups: np.ndarray | None) -> ProfileFit:
    n_par = 4 if cone else 3
    if len(ret) < n_par + 1:
        raise ValueError(f"the profile fit needs at least {n_par + 1} returns on the object, got {len(ret)}")
    a = np.asarray(a, dtype=float) / np.linalg.norm(a)
    e1, e2 = axis_basis(a)
    X = ret.points()
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
        p_init = np.array([*np.mean(cs, axis=0), np.mean(rs) - k * np.mean(ts), k])
    else:
        c, r = _kasa(q)
        p_init = np.array([c[0], c[1], r])

    def model(p):
        return X0 + p[0] * e1 + p[1] * e2, a, p[2], p[3] if cone else 0.0

    # Two passes: returns away from grazing at the algebraic start, then at the first fit.
    p = p_init
    used = None
    for _ in range(2):
        now = incidence_cos(ret, *model(p)) >= MIN_INCIDENCE_COS
        if used is not None and np.array_equal(now, used):
            break
        used = now
        if used.sum() < n_par + 1:
            raise ValueError("too few range returns meet the profile away from grazing incidence")
        sub = ret.subset(used)

        def fun(p):
            if p[2] <= 0:
                return np.full(len(sub), 1e6)
            return range_residuals(sub, *model(p))

        def jac(p):
            _, J8 = range_residuals(sub, *model(p), jac=True)
            J = np.column_stack([J8[:, :3] @ e1, J8[:, :3] @ e2, J8[:, 6], J8[:, 7]])
            return J if cone else J[:, :3]

        p, _ = levenberg_marquardt(fun, jac, p)
    res = fun(p)
    J = jac(p)
    H = J.T @ (huber_weights(res, 3.0)[:, None] * J)
    if p[2] <= 0 or np.linalg.cond(H) > 1e14:
        raise ValueError("the range profile does not look like a cylinder or cone (no radius fits it)")
    cov = np.linalg.inv(H)
    inl = used.copy()
    inl[used] = np.abs(res) <= 3.0
    return ProfileFit(a, X0, e1, e2, p, 0.5 * (cov + cov.T), res, inl, cone)


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


def front_plane_jacobian(
    fit: ProfileFit, origin_world: np.ndarray, t: float, params: np.ndarray | None = None
) -> np.ndarray:
    """Derivative (4, len(params)) of ``front_plane(fit, origin_world, t, params).as_vector()`` — (n, d) —
    with respect to the profile's parameters (analytic).

    With C the axis point at t, u the unit direction from the sensor to C across the axis, k the
    cone's slope: n = (u + k a)/√(1 + k²), X = C − r(t) u, d = −n·X. The section offsets (y1, y2)
    move C along e1, e2 (across the axis), which turns u; r and k move X and n directly.
    """
    p = fit.params if params is None else params
    a = fit.a
    C = fit.centre(t, p)
    w = C - np.asarray(origin_world, dtype=float)
    w_perp = w - (w @ a) * a
    rho = np.linalg.norm(w_perp)
    u = w_perp / rho
    k = p[3] if fit.cone else 0.0
    s = np.sqrt(1 + k * k)
    n = (u + k * a) / s
    r = fit.radius(t, p)
    X = C - r * u
    P = (np.eye(3) - np.outer(u, u)) / rho  # du = P dC for dC across the axis
    J = np.zeros((4, len(p)))
    for j, dC in enumerate((fit.e1, fit.e2)):
        du = P @ dC
        dn = du / s
        dX = dC - r * du
        J[:3, j] = dn
        J[3, j] = -(dn @ X + n @ dX)
    J[3, 2] = n @ u  # dr: X moves by −u
    if fit.cone:
        dn = (a - k * u) / s**3
        J[:3, 3] = dn
        J[3, 3] = -(dn @ X) + t * (n @ u)
    return J
