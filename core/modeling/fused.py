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
from .lm import huber_weights, levenberg_marquardt
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
        dg = []
        for dpan, dtilt in ((1e-6, 0.0), (0.0, 1e-6)):
            Dp = (beam_direction(tb.pan_rad + dpan, tb.tilt_rad + dtilt) @ T[:3, :3].T)[None]
            dg.append((beam_gap(O, Dp, p0i, ai, r0i, (r1i - r0i) / hi)[0][0] - beam_gap(O, Dm[j : j + 1], p0i, ai, r0i, (r1i - r0i) / hi)[0][0]) / 1e-6)
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

    def model8(th):
        p0, a, r0, r1, h = unpack(th)
        return np.concatenate([p0, a, [r0, (r1 - r0) / h]])

    def jacobian(th):
        """Analytic for the returns and tangent beams (through (p0, a, r0, k)), numeric for the clicks."""
        p0, a, r0, r1, h = unpack(th)
        k = (r1 - r0) / h
        n = len(th)
        M = np.zeros((8, n))
        S = np.zeros((8, n))
        m0, s0 = model8(th), silhouette_residuals(th)
        for j in range(n):
            e = np.zeros(n)
            e[j] = 1e-7
            M[:, j] = (model8(th + e) - m0) / 1e-7
            S[:, j] = (silhouette_residuals(th + e) - s0) / 1e-7
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

    def qvec(t):
        p, aa, q0, q1, hh = unpack(t)
        radii = [q0, q1] if cone else [q0]
        return np.concatenate([radii, [hh], p + 0.5 * hh * aa, aa])

    G = np.zeros((len(qvec(th)), len(th)))
    for j in range(len(th)):
        e = np.zeros(len(th))
        e[j] = 1e-7
        G[:, j] = (qvec(th + e) - qvec(th - e)) / 2e-7
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
