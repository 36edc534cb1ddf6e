"""Range returns on a surface of revolution: residuals that are the maximum-likelihood ones.

The range finder's noise lies along the beam (σ_ρ = 5 mm) and is small across it (range ×
pointing noise ≈ 0.3 mm). The likelihood of a return is therefore about its *range along its
own beam*, not about the distance of the noisy point to the surface: a point-to-surface fit
turns the along-beam noise of oblique returns into a bias of the axis depth (≈ 0.4 mm at 1.3 m for
r = 5.1 cm, measured) because each point's own error tilts its distance gradient.

For each return: where the commanded beam meets the model, the residual is
``(ρ_measured − ρ_model) / σ_eff`` with ``σ_eff² = σ_ρ² + (∂ρ_model/∂angles)² σ_angle²`` (the
pointing noise moves the model's range a lot near grazing incidence, so grazing returns weigh
little there). Returns nearer than ``MIN_INCIDENCE_COS`` to grazing at the starting model are
left out: the edge is carried by the scan's tangent beams (last hit / first miss) instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Returns",
    "make_returns",
    "concat_returns",
    "range_residuals",
    "beam_gap",
    "beam_gap_jacobian",
    "incidence_cos",
    "surface_gradient",
    "MIN_INCIDENCE_COS",
]

# Returns more than ~73° from grazing incidence (at the current model) are used. Closer to grazing the
# model's range varies as the square root of the radius change: its derivative is unbounded, and
# those returns carry little (σ_eff ≫ σ_ρ) that the tangent beams do not already give.
MIN_INCIDENCE_COS = 0.3


@dataclass(frozen=True)
class Returns:
    """Range returns with their beams.

    origin : (3,) the beams' origin (world). dirs : (N, 3) unit beam directions as commanded.
    range_m : (N,) measured ranges. e_pan, e_tilt : (N, 3) derivatives of the direction with
    respect to pan and tilt (world). sigma_range_m : float. sigma_pan_rad, sigma_tilt_rad : (N,).
    """

    origin: np.ndarray
    dirs: np.ndarray
    range_m: np.ndarray
    e_pan: np.ndarray
    e_tilt: np.ndarray
    sigma_range_m: float
    sigma_pan_rad: np.ndarray
    sigma_tilt_rad: np.ndarray

    def __len__(self) -> int:
        return len(self.range_m)

    def points(self) -> np.ndarray:
        """The returns as world points (N, 3)."""
        return self.origin + self.range_m[:, None] * self.dirs

    def subset(self, m: np.ndarray) -> Returns:
        return Returns(
            self.origin,
            self.dirs[m],
            self.range_m[m],
            self.e_pan[m],
            self.e_tilt[m],
            self.sigma_range_m,
            self.sigma_pan_rad[m],
            self.sigma_tilt_rad[m],
        )


def make_returns(
    T_world_turret: np.ndarray, pan_rad, tilt_rad, range_m, sigma_range_m: float, sigma_angle_rad: float
) -> Returns:
    """Returns from turret angles (N,) and ranges (N,) (all finite) for a turret at ``T_world_turret``."""
    T = np.asarray(T_world_turret, dtype=float)
    R = T[:3, :3]
    p = np.asarray(pan_rad, dtype=float)
    t = np.asarray(tilt_rad, dtype=float)
    ct, st, cp, sp = np.cos(t), np.sin(t), np.cos(p), np.sin(p)
    d = np.stack([ct * cp, ct * sp, st], axis=-1) @ R.T
    ep = np.stack([-ct * sp, ct * cp, np.zeros_like(p)], axis=-1) @ R.T
    et = np.stack([-st * cp, -st * sp, ct], axis=-1) @ R.T
    n = len(p)
    return Returns(
        T[:3, 3].copy(),
        d,
        np.asarray(range_m, dtype=float),
        ep,
        et,
        float(sigma_range_m),
        np.full(n, sigma_angle_rad),
        np.full(n, sigma_angle_rad),
    )


def concat_returns(parts: list[Returns]) -> Returns:
    """One Returns from several (same origin), in order."""
    if not parts:
        raise ValueError("no returns to join")
    return Returns(
        parts[0].origin,
        np.vstack([r.dirs for r in parts]),
        np.concatenate([r.range_m for r in parts]),
        np.vstack([r.e_pan for r in parts]),
        np.vstack([r.e_tilt for r in parts]),
        parts[0].sigma_range_m,
        np.concatenate([r.sigma_pan_rad for r in parts]),
        np.concatenate([r.sigma_tilt_rad for r in parts]),
    )


def _geometry(O, D, p0, a, r0, k):
    w = O - p0
    t0 = float(w @ a)
    wp = w - t0 * a
    tau = D @ a
    Dp = D - tau[:, None] * a
    rb = r0 + k * t0
    A = np.einsum("ij,ij->i", Dp, Dp) - (k * tau) ** 2
    B = Dp @ wp - k * tau * rb
    C = wp @ wp - rb**2
    return w, t0, wp, tau, Dp, A, B, C


def surface_gradient(
    X: np.ndarray, p0: np.ndarray, a: np.ndarray, r0: float, k: float
) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives of F(X) = ρ(X) − r0 − k t(X) at points X (N, 3) (ρ: distance to the axis).

    Returns ∇_X F (N, 3) and ∂F/∂(p0, a, r0, k) (N, 8) (a treated as a free 3-vector; the caller
    keeps it unit through its own parameters).
    """
    w = X - p0
    t = w @ a
    radial = w - t[:, None] * a
    e = radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
    grad_x = e - k * a
    J = np.empty((len(X), 8))
    J[:, :3] = -grad_x
    J[:, 3:6] = -t[:, None] * e - k * w
    J[:, 6] = -1.0
    J[:, 7] = -t
    return grad_x, J


def beam_gap_jacobian(O: np.ndarray, D: np.ndarray, p0: np.ndarray, a: np.ndarray, r0: float, k: float) -> np.ndarray:
    """∂(beam_gap)/∂(p0, a, r0, k), shape (M, 8): the gap is F at its minimum along the beam, so
    (envelope theorem) its derivative is F's at that point, over the same √(1 + k²)."""
    _, X = beam_gap(O, D, p0, a, r0, k)
    _, J = surface_gradient(X, p0, a, r0, k)
    g = np.linalg.norm((X - p0) - ((X - p0) @ a)[:, None] * a, axis=1) - r0 - k * ((X - p0) @ a)
    J[:, 7] = J[:, 7] / np.sqrt(1 + k * k) - g * k / (1 + k * k) ** 1.5
    J[:, :7] /= np.sqrt(1 + k * k)
    return J


def beam_gap_direction_jacobian(
    O: np.ndarray, D: np.ndarray, p0: np.ndarray, a: np.ndarray, r0: float, k: float
) -> np.ndarray:
    """∂(beam_gap)/∂D, shape (M, 3), for unit directions D (M, 3): at the beam's point X = O + s D
    nearest the surface the gap is stationary along the beam, so (envelope theorem) moving D moves
    X by s dD and the gap by s ∇F(X)·dD, over √(1 + k²)."""
    _, X = beam_gap(O, D, p0, a, r0, k)
    grad_x, _ = surface_gradient(X, p0, a, r0, k)
    s = np.einsum("ij,ij->i", X - O, D)
    return s[:, None] * grad_x / np.sqrt(1.0 + k * k)


def beam_gap(
    O: np.ndarray, D: np.ndarray, p0: np.ndarray, a: np.ndarray, r0: float, k: float
) -> tuple[np.ndarray, np.ndarray]:
    """Least signed distance (M,) from the lateral surface along each beam line, and where (M, 3).

    Surface: axis through p0 along unit a, radius r0 + k t (t = (X − p0)·a). Zero for a beam
    tangent to it, negative when the beam enters. For a cylinder: beam–axis distance − r0.
    """
    w, t0, wp, tau, Dp, _, _, _ = _geometry(O, D, p0, a, r0, k)
    A = np.einsum("ij,ij->i", Dp, Dp)
    B = Dp @ wp
    Cq = wp @ wp
    den = np.maximum(A - (k * tau) ** 2, 1e-12)
    u = np.sign(k * tau) * np.sqrt(np.maximum((k * tau) ** 2 * (A * Cq - B**2) / den, 0.0))
    s = (u - B) / np.maximum(A, 1e-12)
    t = t0 + s * tau
    rho = np.sqrt(np.maximum(A * s * s + 2 * B * s + Cq, 0.0))
    return (rho - r0 - k * t) / np.sqrt(1.0 + k * k), O + s[:, None] * D


def incidence_cos(ret: Returns, p0: np.ndarray, a: np.ndarray, r0: float, k: float) -> np.ndarray:
    """|cos| of each beam's incidence where it meets the model (N,), 0 for a beam that misses it."""
    O, D = ret.origin, ret.dirs
    w, t0, wp, tau, Dp, A, B, C = _geometry(O, D, p0, a, r0, k)
    disc = B * B - A * C
    Aok = np.where(np.abs(A) > 1e-12, A, 1e-12)
    s = (-B - np.sqrt(np.maximum(disc, 0.0))) / Aok
    P = O + s[:, None] * D - p0
    radial = P - (P @ a)[:, None] * a
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
    n = (radial - k * a) / np.sqrt(1 + k * k)
    return np.where((disc > 0) & (s > 0), np.minimum(np.abs(np.einsum("ij,ij->i", n, D)), 1.0), 0.0)


def range_residuals(ret: Returns, p0: np.ndarray, a: np.ndarray, r0: float, k: float, jac: bool = False):
    """Normalised residuals (N,) of returns against a surface of revolution (module docstring).

    With ``jac``, also their derivatives (N, 8) with respect to (p0, a, r0, k), σ_eff held
    fixed: the model range s moves by −(∂F/∂θ)/(∇F·d) along the beam (implicit function).
    """
    O, D = ret.origin, ret.dirs
    w, t0, wp, tau, Dp, A, B, C = _geometry(O, D, p0, a, r0, k)
    disc = B * B - A * C
    Aok = np.where(np.abs(A) > 1e-12, A, 1e-12)
    s = (-B - np.sqrt(np.maximum(disc, 0.0))) / Aok
    hit = (disc > 0) & (s > 0)
    P = O + s[:, None] * D - p0
    radial = P - (P @ a)[:, None] * a
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
    n = (radial - k * a) / np.sqrt(1 + k * k)
    cos = np.minimum(np.abs(np.einsum("ij,ij->i", n, D)), 1.0)
    lat2 = (np.einsum("ij,ij->i", n, ret.e_pan) * ret.sigma_pan_rad) ** 2 + (
        np.einsum("ij,ij->i", n, ret.e_tilt) * ret.sigma_tilt_rad
    ) ** 2
    sig_eff = np.sqrt(ret.sigma_range_m**2 + s * s * lat2 / np.maximum(cos * cos, 1e-12))
    res = (ret.range_m - s) / sig_eff
    if jac:
        X = O + s[:, None] * D
        grad_x, JF = surface_gradient(X, p0, a, r0, k)
        gd = np.einsum("ij,ij->i", grad_x, D)
        gd = np.where(np.abs(gd) > 1e-9, gd, np.copysign(1e-9, gd))
        Jres = JF / (gd * sig_eff)[:, None]
    if not np.all(hit):
        # Select returns with ``incidence_cos`` first; one whose beam still misses the model at
        # some iterate is pulled back by its gap over the pointing noise.
        m = ~hit
        g, Pg = beam_gap(O, D[m], p0, a, r0, k)
        Q = Pg - p0
        rg = Q - (Q @ a)[:, None] * a
        rg /= np.maximum(np.linalg.norm(rg, axis=1, keepdims=True), 1e-12)
        lat = ret.range_m[m] * np.sqrt(
            (np.einsum("ij,ij->i", rg, ret.e_pan[m]) * ret.sigma_pan_rad[m]) ** 2
            + (np.einsum("ij,ij->i", rg, ret.e_tilt[m]) * ret.sigma_tilt_rad[m]) ** 2
        )
        res = res.copy()
        lat = np.maximum(lat, 1e-6)
        res[m] = g / lat
        if jac:
            Jres[m] = beam_gap_jacobian(O, D[m], p0, a, r0, k) / lat[:, None]
    return (res, Jres) if jac else res
