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

import numpy as np

from ..brep import Revolution
from .cylinder import CylinderData, build_result, solve_paper
from .lm import huber_weights, levenberg_marquardt
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
    init, errors = None, []
    for init_method in ("tangential", "bisecting", "rf_tangential"):
        try:
            init = solve_paper(data, init_method)
            break
        except ValueError as exc:
            errors.append(f"{init_method}: {exc}")
    if init is None:
        raise ValueError("no starting model for the fused fit (" + "; ".join(errors) + ")")
    cone = data.cone
    a0 = init["a"]
    p0_init = init["p0"]
    e1, e2 = axis_basis(a0)
    radii0 = [init["r0"], init["r1"]] if cone else [0.5 * (init["r0"] + init["r1"])]
    free_axis = data.axis_hint is None
    on_support = data.support is not None
    cam = data.camera
    c = cam.center

    def unpack(th):
        i = 0
        a = a0
        if free_axis:
            a = a0 + th[0] * e1 + th[1] * e2
            a = a / np.linalg.norm(a)
            i = 2
        p0 = p0_init + th[i] * e1 + th[i + 1] * e2
        i += 2
        if not on_support:
            p0 = p0 + th[i] * a0
            i += 1
        if cone:
            r0, r1 = th[i], th[i + 1]
            i += 2
        else:
            r0 = r1 = th[i]
            i += 1
        h = th[i]
        return p0, a, r0, r1, h

    def unpack_jacobian(th):
        """Derivatives of (p0 (3, n), a (3, n), r0 (n,), r1 (n,), h (n,)) with respect to th (analytic)."""
        n = len(th)
        dp0, da, dr0, dr1, dh = np.zeros((3, n)), np.zeros((3, n)), np.zeros(n), np.zeros(n), np.zeros(n)
        i = 0
        if free_axis:
            a_raw = a0 + th[0] * e1 + th[1] * e2
            norm = np.linalg.norm(a_raw)
            a = a_raw / norm
            P = (np.eye(3) - np.outer(a, a)) / norm
            da[:, 0], da[:, 1] = P @ e1, P @ e2
            i = 2
        dp0[:, i], dp0[:, i + 1] = e1, e2
        i += 2
        if not on_support:
            dp0[:, i] = a0
            i += 1
        dr0[i] = 1.0
        dr1[i + 1 if cone else i] = 1.0
        i += 2 if cone else 1
        dh[i] = 1.0
        return dp0, da, dr0, dr1, dh

    th0 = np.concatenate(
        [np.zeros(2) if free_axis else [], np.zeros(2), [] if on_support else [0.0], radii0, [init["h"]]]
    )
    ret_all = data.returns
    beams = data.tangents
    T = data.T_world_turret
    O = data.rf_origin
    Dm = np.array([tb.direction(T) for tb in beams]).reshape(-1, 3)

    # Returns away from grazing, and per-beam σ of the gap, from the initial model.
    p0i, ai, r0i, r1i, hi = unpack(th0)
    sig_gap = np.zeros(len(beams))
    if len(beams):  # the gap's derivatives with respect to each beam's pan and tilt (analytic)
        pan = np.array([tb.pan_rad for tb in beams])
        tilt = np.array([tb.tilt_rad for tb in beams])
        cp, sp, ct, st = np.cos(pan), np.sin(pan), np.cos(tilt), np.sin(tilt)
        dD_pan = np.column_stack([-ct * sp, ct * cp, np.zeros_like(pan)]) @ T[:3, :3].T
        dD_tilt = np.column_stack([-st * cp, -st * sp, ct]) @ T[:3, :3].T
        dg_dD = beam_gap_direction_jacobian(O, Dm, p0i, ai, r0i, (r1i - r0i) / hi)
        sig_gap = np.hypot(
            np.einsum("ij,ij->i", dg_dD, dD_pan) * [tb.sigma_pan_rad for tb in beams],
            np.einsum("ij,ij->i", dg_dD, dD_tilt) * [tb.sigma_tilt_rad for tb in beams],
        )
    sig_gap = np.maximum(sig_gap, 1e-9)

    # Which generator and which end each clicked silhouette end is (fixed from the start).
    sil = data.silhouettes_uv
    gens0 = Revolution(p0i, p0i + hi * ai, r0i, r1i).silhouette(c)
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
    gen_idx = [g for g, _ in match]

    def residuals(th):
        p0, a, r0, r1, h = unpack(th)
        n_res = len(ret) + len(beams) + 8
        if h <= 1e-6 or min(r0, r1) < 0 or r0 + r1 <= 1e-6:
            return np.full(n_res, 1e6)
        k = (r1 - r0) / h
        out = [range_residuals(ret, p0, a, r0, k)]
        if len(beams):
            out.append(beam_gap(O, Dm, p0, a, r0, k)[0] / sig_gap)
        gens = Revolution(p0, p0 + h * a, r0, r1).silhouette(c)
        if len(gens) != 2:
            return np.full(n_res, 1e6)
        pred = np.concatenate([cam.project(gens[g]) for g in gen_idx])
        out.append(((clicks - pred) / sigma_px).reshape(-1))
        return np.concatenate(out)

    C = cam.C

    def silhouette_jacobian(th, dp0, da, dr0, dr1, dh):
        """d(clicked-end residuals)/dθ (8, n): the generators' ends through the camera (analytic)."""
        p0, a, r0, r1, h = unpack(th)
        ends, dX = silhouette_ends(p0, a, r0, r1, h, c)
        if ends is None:  # no silhouette at this θ (the residuals are the flat penalty there)
            return np.zeros((8, len(th)))
        X, dX = ends[gen_idx].reshape(4, 3), dX[gen_idx].reshape(4, 3, 9) @ np.vstack([dp0, da, dr0, dr1, dh])
        P = X @ C[:, :3].T + C[:, 3]
        uv = P[:, :2] / P[:, 2:3]
        duv_dX = (C[None, :2, :3] - uv[:, :, None] * C[None, 2:3, :3]) / P[:, 2, None, None]  # (4, 2, 3)
        return -(duv_dX @ dX).reshape(8, -1) / sigma_px

    def jacobian(th):
        """Analytic: the returns and tangent beams through (p0, a, r0, k), the clicked ends through
        the contour generators' ends (``silhouette_ends``) and the camera."""
        p0, a, r0, r1, h = unpack(th)
        k = (r1 - r0) / h
        dp0, da, dr0, dr1, dh = unpack_jacobian(th)
        M = np.vstack([dp0, da, dr0, (dr1 - dr0) / h - (r1 - r0) / h**2 * dh])  # d(p0, a, r0, k)/dθ
        S = silhouette_jacobian(th, dp0, da, dr0, dr1, dh)
        blocks = [range_residuals(ret, p0, a, r0, k, jac=True)[1] @ M]
        if len(beams):
            blocks.append((beam_gap_jacobian(O, Dm, p0, a, r0, k) / sig_gap[:, None]) @ M)
        blocks.append(S)
        return np.vstack(blocks)

    # Two passes: the returns used are those away from grazing at the start, then at the first fit.
    th = th0
    used = None
    for _ in range(2):
        p0c, ac, r0c, r1c, hc = unpack(th)
        now = incidence_cos(ret_all, p0c, ac, r0c, (r1c - r0c) / hc) >= MIN_INCIDENCE_COS
        if used is not None and np.array_equal(now, used):
            break
        used = now
        ret = ret_all.subset(used)
        th, n_iter = levenberg_marquardt(residuals, jacobian, th)
    r = residuals(th)
    J = jacobian(th)
    H = J.T @ (huber_weights(r, 3.0)[:, None] * J)
    cov_th = np.linalg.pinv(H, rcond=1e-14, hermitian=True)
    p0, a, r0, r1, h = unpack(th)

    # (radii, h, mid-point p0 + h a / 2, a): their derivatives with respect to θ, analytic.
    dp0, da, dr0, dr1, dh = unpack_jacobian(th)
    G = np.vstack([dr0, *([dr1] if cone else []), dh, dp0 + 0.5 * (np.outer(a, dh) + h * da), da])
    cov_q = G @ cov_th @ G.T
    n_h = len(ret)
    resid = {
        "scan_returns_sigma": r[:n_h],
        "tangent_beams_m": r[n_h : n_h + len(beams)] * sig_gap,
        "silhouette_ends_px": r[n_h + len(beams) :] * sigma_px,
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
