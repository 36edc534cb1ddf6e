"""Fused maximum-likelihood fit of a cylinder or cone: every measurement, each with its noise.

The paper's conclusion proposes "the fusion of multisensor redundant data, in order to reduce the
uncertainty". Here one least-squares problem holds, each residual divided by its standard
deviation (so the minimum is the maximum-likelihood estimate under Gaussian noise):

* every scan return on the object: its range against the model's range along the same beam,
  over the range noise and the pointing noise seen through the surface's slope
  (``returns.range_residuals``: the likelihood of a return is along its beam);
* every tangent beam (between the last hit and the first miss of a scan): how far the beam
  passes from the surface, over (distance × angular σ) — the misses carry information;
* both silhouettes' clicked ends: pixel offsets from the projected ends of the model's contour
  generators (σ_px), which fix the silhouettes and the height;
* the support (the object stands on it): built into the parameters (axis = its normal, base on it).

A Huber loss at 3σ keeps a stray return from pulling the fit. The covariance is the inverse
Gauss–Newton information at the solution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..brep import Revolution
from ..robust import huber_weights
from .cylinder import CylinderData, build_result, solve_paper
from .lm import levenberg_marquardt
from .profile import axis_basis
from .returns import (
    MIN_INCIDENCE_COS,
    beam_gap,
    beam_gap_direction_jacobian,
    beam_gap_jacobian,
    incidence_cos,
    range_residuals,
)

__all__ = ["fit_fused", "silhouette_ends"]

_I3 = np.eye(3)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def silhouette_ends(p0: np.ndarray, a: np.ndarray, r0: float, r1: float, h: float, c: np.ndarray):
    """The contour generators' ends seen from the optical centre c, and their derivatives.

    The solid: base centre p0, unit axis a, radii r0 (base) and r1 (top), height h
    (``Revolution(p0, p0 + h a, r0, r1).silhouette(c)``, same order). Returns (ends (2, 2, 3):
    generator, end (base, top), xyz; J (2, 2, 3, 9): their derivatives with respect to
    (p0, a, r0, r1, h), a's along any direction — the caller's map keeps it unit), or (None, None)
    when c is inside the surface's extension.
    """
    q = c - p0
    q_a = float(q @ a)
    w = q - q_a * a
    D = float(np.linalg.norm(w))
    k = r0 - (r0 - r1) * q_a / h
    if D <= abs(k) or D < 1e-12:
        return None, None
    w_hat = w / D
    b_hat = np.cross(a, w_hat)
    cc = k / D
    s = np.sqrt(max(0.0, 1.0 - cc * cc))
    # differentials (3, 9) or (9,) with respect to x = (p0, a, r0, r1, h)
    dp0 = np.zeros((3, 9))
    dp0[:, 0:3] = _I3
    da = np.zeros((3, 9))
    da[:, 3:6] = _I3
    e_r0, e_r1, e_h = np.eye(9)[6], np.eye(9)[7], np.eye(9)[8]
    dq_a = -a @ dp0 + q @ da
    dw = -dp0 - np.outer(a, dq_a) - q_a * da
    dD = w_hat @ dw
    dw_hat = (dw - np.outer(w_hat, dD)) / D
    db = _skew(a) @ dw_hat - _skew(w_hat) @ da
    dk = e_r0 - (e_r0 - e_r1) * q_a / h - (r0 - r1) * (dq_a / h - q_a * e_h / h**2)
    dcc = dk / D - k * dD / D**2
    ds = -cc * dcc / s
    ends = np.empty((2, 2, 3))
    J = np.empty((2, 2, 3, 9))
    top = p0 + h * a
    d_top = dp0 + np.outer(a, e_h) + h * da
    for g, sign in enumerate((1.0, -1.0)):
        e = cc * w_hat + sign * s * b_hat
        de = np.outer(w_hat, dcc) + cc * dw_hat + sign * (np.outer(b_hat, ds) + s * db)
        ends[g, 0] = p0 + r0 * e
        ends[g, 1] = top + r1 * e
        J[g, 0] = dp0 + np.outer(e, e_r0) + r0 * de
        J[g, 1] = d_top + np.outer(e, e_r1) + r1 * de
    return ends, J


def fit_fused(data: CylinderData, *, sigma_px: float = 1.0):
    """The fused maximum-likelihood fit (method "fused" of ``model_cylinder``)."""
    if data.silhouettes_uv is None:
        raise ValueError("the fused fit needs the two silhouettes (their clicked ends give the height)")
    init_method, init = _starting_model(data)
    e1, e2 = axis_basis(init["a"])
    par = _Parameters(init["a"], init["p0"], e1, e2, data.cone, data.axis_hint is None, data.support is not None)
    radii0 = [init["r0"], init["r1"]] if par.cone else [0.5 * (init["r0"] + init["r1"])]
    th0 = np.concatenate(
        [np.zeros(2) if par.free_axis else [], np.zeros(2), [] if par.on_support else [0.0], radii0, [init["h"]]]
    )
    problem = _Problem(data, par, th0, sigma_px)
    th, n_iter = problem.fit(th0)
    r = problem.residuals(th)
    J = problem.jacobian(th)
    H = J.T @ (huber_weights(r, 3.0)[:, None] * J)
    cov_th = np.linalg.pinv(H, rcond=1e-14, hermitian=True)
    p0, a, r0, r1, h = par.unpack(th)

    # (radii, h, mid-point p0 + h a / 2, a): their derivatives with respect to θ, analytic.
    dp0, da, dr0, dr1, dh = par.unpack_jacobian(th)
    G = np.vstack([dr0, *([dr1] if par.cone else []), dh, dp0 + 0.5 * (np.outer(a, dh) + h * da), da])
    cov_q = G @ cov_th @ G.T
    n_h = len(problem.ret)
    n_b = len(problem.beams)
    resid = {
        "scan_returns_sigma": r[:n_h],
        "tangent_beams_m": r[n_h : n_h + n_b] * problem.sig_gap,
        "silhouette_ends_px": r[n_h + n_b :] * sigma_px,
    }
    details = {
        "init_method": init_method,
        "init": init,
        "optimizer": {"cost": float(0.5 * r @ r), "iterations": int(n_iter)},
        "outliers": int(np.count_nonzero(np.abs(r) > 3.0)),
        "segments": data.segments,
    }
    solid = {"p0": p0, "a": a, "r0": float(r0), "r1": float(r1), "h": float(h)}
    return build_result(data, "fused", solid, cov_q, resid, details)


def _starting_model(data: CylinderData) -> tuple[str, dict]:
    """The first of the paper's methods that gives a solid, and that solid."""
    errors = []
    for init_method in ("tangential", "bisecting", "rf_tangential"):
        try:
            return init_method, solve_paper(data, init_method)
        except ValueError as exc:
            errors.append(f"{init_method}: {exc}")
    raise ValueError("no starting model for the fused fit (" + "; ".join(errors) + ")")


@dataclass(frozen=True)
class _Parameters:
    """The fit's parameters θ about the starting solid (base centre p0_init, axis a0 with basis e1, e2):
    the axis tilt along (e1, e2) when the axis is free; the base's shift along (e1, e2), and along a0
    unless the solid stands on the support; the radius (a cone: the base's and the top's); the height."""

    a0: np.ndarray
    p0_init: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    cone: bool
    free_axis: bool
    on_support: bool

    def unpack(self, th: np.ndarray):
        """(p0 (3,), a (3,), r0, r1, h) at θ."""
        e1, e2 = self.e1, self.e2
        i = 0
        a = self.a0
        if self.free_axis:
            a = self.a0 + th[0] * e1 + th[1] * e2
            a = a / np.linalg.norm(a)
            i = 2
        p0 = self.p0_init + th[i] * e1 + th[i + 1] * e2
        i += 2
        if not self.on_support:
            p0 = p0 + th[i] * self.a0
            i += 1
        if self.cone:
            r0, r1 = th[i], th[i + 1]
            i += 2
        else:
            r0 = r1 = th[i]
            i += 1
        h = th[i]
        return p0, a, r0, r1, h

    def unpack_jacobian(self, th: np.ndarray):
        """Derivatives of (p0 (3, n), a (3, n), r0 (n,), r1 (n,), h (n,)) with respect to th (analytic)."""
        e1, e2 = self.e1, self.e2
        n = len(th)
        dp0, da, dr0, dr1, dh = np.zeros((3, n)), np.zeros((3, n)), np.zeros(n), np.zeros(n), np.zeros(n)
        i = 0
        if self.free_axis:
            a_raw = self.a0 + th[0] * e1 + th[1] * e2
            norm = np.linalg.norm(a_raw)
            a = a_raw / norm
            P = (np.eye(3) - np.outer(a, a)) / norm
            da[:, 0], da[:, 1] = P @ e1, P @ e2
            i = 2
        dp0[:, i], dp0[:, i + 1] = e1, e2
        i += 2
        if not self.on_support:
            dp0[:, i] = self.a0
            i += 1
        dr0[i] = 1.0
        dr1[i + 1 if self.cone else i] = 1.0
        i += 2 if self.cone else 1
        dh[i] = 1.0
        return dp0, da, dr0, dr1, dh


def _gap_sigmas(beams, T: np.ndarray, O: np.ndarray, Dm: np.ndarray, p0, a, r0, r1, h) -> np.ndarray:
    """σ (m) of each tangent beam's gap to the solid (p0, a, r0, r1, h), from its pan and tilt noise
    through the gap's derivatives with respect to the beam's direction (analytic)."""
    sig_gap = np.zeros(len(beams))
    if len(beams):
        pan = np.array([tb.pan_rad for tb in beams])
        tilt = np.array([tb.tilt_rad for tb in beams])
        cp, sp, ct, st = np.cos(pan), np.sin(pan), np.cos(tilt), np.sin(tilt)
        dD_pan = np.column_stack([-ct * sp, ct * cp, np.zeros_like(pan)]) @ T[:3, :3].T
        dD_tilt = np.column_stack([-st * cp, -st * sp, ct]) @ T[:3, :3].T
        dg_dD = beam_gap_direction_jacobian(O, Dm, p0, a, r0, (r1 - r0) / h)
        sig_gap = np.hypot(
            np.einsum("ij,ij->i", dg_dD, dD_pan) * [tb.sigma_pan_rad for tb in beams],
            np.einsum("ij,ij->i", dg_dD, dD_tilt) * [tb.sigma_tilt_rad for tb in beams],
        )
    return np.maximum(sig_gap, 1e-9)


def _match_silhouettes(cam, sil: np.ndarray, p0, a, r0, r1, h) -> tuple[np.ndarray, list[int]]:
    """Which contour generator of the solid, and which of its ends, each clicked silhouette end is.

    Returns the clicked ends (4, 2) in the order (generator, base end, top end) and the generator
    (0 or 1) of each silhouette.
    """
    gens0 = Revolution(p0, p0 + h * a, r0, r1).silhouette(cam.center)
    if len(gens0) != 2:
        raise ValueError("the camera is inside the modelled solid: the silhouettes do not bound a cylinder")
    match = []
    for seg in sil:
        best = None
        for g in range(2):
            uvg = cam.project(gens0[g])
            for order in ((0, 1), (1, 0)):
                e = np.linalg.norm(seg - uvg[list(order)], axis=1).sum()
                if best is None or e < best[0]:
                    best = (e, g, order)
        match.append(best[1:])
    if match[0][0] == match[1][0]:
        raise ValueError("both silhouettes were matched to the same contour: click the left and the right contour")
    clicks = np.concatenate([sil[s][list(order)] for s, (_, order) in enumerate(match)])  # (4, 2)
    return clicks, [g for g, _ in match]


class _Problem:
    """The fused fit's residuals (each over its σ) and their Jacobian at θ: the scan returns in use
    (``ret``), the tangent beams, the clicked silhouette ends."""

    def __init__(self, data: CylinderData, par: _Parameters, th0: np.ndarray, sigma_px: float):
        self.par = par
        self.cam = data.camera
        self.c = self.cam.center
        self.C = self.cam.C
        self.sigma_px = sigma_px
        self.ret_all = data.returns
        self.beams = data.tangents
        T = data.T_world_turret
        self.O = data.rf_origin
        self.Dm = np.array([tb.direction(T) for tb in self.beams]).reshape(-1, 3)
        # The tangent beams' σ and the silhouettes' matching, from the starting solid.
        p0i, ai, r0i, r1i, hi = par.unpack(th0)
        self.sig_gap = _gap_sigmas(self.beams, T, self.O, self.Dm, p0i, ai, r0i, r1i, hi)
        self.clicks, self.gen_idx = _match_silhouettes(self.cam, data.silhouettes_uv, p0i, ai, r0i, r1i, hi)
        self.ret = self.ret_all  # the returns in use: those away from grazing, chosen by ``fit``

    def fit(self, th0: np.ndarray) -> tuple[np.ndarray, int]:
        """Two passes: the returns used are those away from grazing at the start, then at the first fit.
        Returns θ and the last pass's iterations."""
        th = th0
        used = None
        for _ in range(2):
            p0c, ac, r0c, r1c, hc = self.par.unpack(th)
            now = incidence_cos(self.ret_all, p0c, ac, r0c, (r1c - r0c) / hc) >= MIN_INCIDENCE_COS
            if used is not None and np.array_equal(now, used):
                break
            used = now
            self.ret = self.ret_all.subset(used)
            th, n_iter = levenberg_marquardt(self.residuals, self.jacobian, th)
        return th, n_iter

    def residuals(self, th: np.ndarray) -> np.ndarray:
        p0, a, r0, r1, h = self.par.unpack(th)
        n_res = len(self.ret) + len(self.beams) + 8
        if h <= 1e-6 or min(r0, r1) < 0 or r0 + r1 <= 1e-6:
            return np.full(n_res, 1e6)
        k = (r1 - r0) / h
        out = [range_residuals(self.ret, p0, a, r0, k)]
        if len(self.beams):
            out.append(beam_gap(self.O, self.Dm, p0, a, r0, k)[0] / self.sig_gap)
        gens = Revolution(p0, p0 + h * a, r0, r1).silhouette(self.c)
        if len(gens) != 2:
            return np.full(n_res, 1e6)
        pred = np.concatenate([self.cam.project(gens[g]) for g in self.gen_idx])
        out.append(((self.clicks - pred) / self.sigma_px).reshape(-1))
        return np.concatenate(out)

    def silhouette_jacobian(self, th, dp0, da, dr0, dr1, dh) -> np.ndarray:
        """d(clicked-end residuals)/dθ (8, n): the generators' ends through the camera (analytic)."""
        p0, a, r0, r1, h = self.par.unpack(th)
        ends, dX = silhouette_ends(p0, a, r0, r1, h, self.c)
        if ends is None:  # no silhouette at this θ (the residuals are the flat penalty there)
            return np.zeros((8, len(th)))
        C = self.C
        X = ends[self.gen_idx].reshape(4, 3)
        dX = dX[self.gen_idx].reshape(4, 3, 9) @ np.vstack([dp0, da, dr0, dr1, dh])
        P = X @ C[:, :3].T + C[:, 3]
        uv = P[:, :2] / P[:, 2:3]
        duv_dX = (C[None, :2, :3] - uv[:, :, None] * C[None, 2:3, :3]) / P[:, 2, None, None]  # (4, 2, 3)
        return -(duv_dX @ dX).reshape(8, -1) / self.sigma_px

    def jacobian(self, th: np.ndarray) -> np.ndarray:
        """Analytic: the returns and tangent beams through (p0, a, r0, k), the clicked ends through
        the contour generators' ends (``silhouette_ends``) and the camera."""
        p0, a, r0, r1, h = self.par.unpack(th)
        k = (r1 - r0) / h
        dp0, da, dr0, dr1, dh = self.par.unpack_jacobian(th)
        M = np.vstack([dp0, da, dr0, (dr1 - dr0) / h - (r1 - r0) / h**2 * dh])  # d(p0, a, r0, k)/dθ
        S = self.silhouette_jacobian(th, dp0, da, dr0, dr1, dh)
        blocks = [range_residuals(self.ret, p0, a, r0, k, jac=True)[1] @ M]
        if len(self.beams):
            blocks.append((beam_gap_jacobian(self.O, self.Dm, p0, a, r0, k) / self.sig_gap[:, None]) @ M)
        blocks.append(S)
        return np.vstack(blocks)
