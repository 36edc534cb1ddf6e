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
from ..rangefinder import beam_direction
from .cylinder import CylinderData, build_result, solve_paper
from .lm import huber_weights, levenberg_marquardt, numeric_jacobian
from .profile import axis_basis
from .returns import MIN_INCIDENCE_COS, beam_gap, beam_gap_jacobian, incidence_cos, range_residuals

__all__ = ["fit_fused"]


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

    th0 = np.concatenate([np.zeros(2) if free_axis else [], np.zeros(2), [] if on_support else [0.0], radii0, [init["h"]]])
    ret_all = data.returns
    beams = data.tangents
    T = data.T_world_turret
    O = data.rf_origin
    Dm = np.array([tb.direction(T) for tb in beams]).reshape(-1, 3)

    # Returns away from grazing, and per-beam σ of the gap, from the initial model.
    p0i, ai, r0i, r1i, hi = unpack(th0)
    sig_gap = np.zeros(len(beams))
    for j, tb in enumerate(beams):
        def gap(angles):
            D = (beam_direction(angles[0], angles[1]) @ T[:3, :3].T)[None]
            return beam_gap(O, D, p0i, ai, r0i, (r1i - r0i) / hi)[0]

        g0 = beam_gap(O, Dm[j : j + 1], p0i, ai, r0i, (r1i - r0i) / hi)[0]
        dg = numeric_jacobian(gap, np.array([tb.pan_rad, tb.tilt_rad]), 1e-6, f0=g0)[0]
        sig_gap[j] = np.hypot(dg[0] * tb.sigma_pan_rad, dg[1] * tb.sigma_tilt_rad)
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

    def silhouette_residuals(th):
        p0, a, r0, r1, h = unpack(th)
        gens = Revolution(p0, p0 + h * a, r0, r1).silhouette(c)
        pred = np.concatenate([cam.project(gens[g]) for g in gen_idx])
        return ((clicks - pred) / sigma_px).reshape(-1)

    def jacobian(th):
        """Analytic for the returns and tangent beams (through (p0, a, r0, k)), numeric for the clicks."""
        p0, a, r0, r1, h = unpack(th)
        k = (r1 - r0) / h
        dp0, da, dr0, dr1, dh = unpack_jacobian(th)
        M = np.vstack([dp0, da, dr0, (dr1 - dr0) / h - (r1 - r0) / h**2 * dh])  # d(p0, a, r0, k)/dθ
        S = numeric_jacobian(silhouette_residuals, th, 1e-7)
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
