"""The camera calibration's share of a refined pose's covariance.

``refine`` states the pose's covariance from the clicks for a given C. C is an estimate too (its
DLT covariance, ``core.calibration.calibrate_dlt(...).cov``); its error shifts the pose the same
way whatever the clicks. ``with_camera_uncertainty`` refines again from the solution with C moved
±1σ along each principal axis of its covariance (2 × 11 refinements, a few milliseconds each) and
adds the spread of the pose: ``cov = cov_clicks + Σ_k δ_k δ_kᵀ``, δ_k the central difference of
(δt, δr) in refine's convention (world frame, about the object's origin). With clicks in several cameras
(``with_views_camera_uncertainty``) each camera's calibration is moved in turn, the others held: their
errors are independent, and their shares add.

Issue 27: the σ covers what mcit did not measure too. Every pose's covariance is the measurements'
share plus, by first order, two stated priors (``Priors``):

* the camera's: its calibration's covariance where mcit calibrated it (the DLT's, stored with the
  calibration), else a prior on the intrinsics a camera file states without one (ViSP ``.xml``, OpenCV
  or ROS ``.yml``): σ(fx)/fx = σ(fy)/fy = ``CAMERA_PRIOR_F_REL`` (0.3 %) and σ(u0) = σ(v0) =
  ``CAMERA_PRIOR_C_PX`` (1 px), independent (``intrinsics_prior_cov``, as a covariance of C's entries);
* the model's: each model edge (and clicked model point) lies ``model_sigma_m`` (default ``MODEL_PRIOR_M``,
  0.3 mm, tuned on bench/sigma_coverage.py's rendered box) from where the model puts it, an independent 3D
  offset per edge: a model measured with a ruler or a CAD file that the object does not follow exactly.
  An edge's samples move together, so the share does not average away over an edge's hundreds of samples.
  And a per-dimension scale (``model_scale_share``): each of the model's extents (its bounds along its own
  axes) off by ``MODEL_EXTENT_PER_EDGE`` × ``model_sigma_m`` (√2: an extent is read between two edges, each
  placed to ``model_sigma_m``), every point moving with it in proportion to its distance from the bounds'
  centre. A ruler's error moves every edge along one dimension together; as independent offsets it would
  average away over a model's many edges (ViSP's castle: depth 84 % within 2σ without it, docs/pose.md).

The camera prior is a stated assumption (a checkerboard calibration's typical error); the model prior was
tuned on one sequence (the rendered box of ``bench/sigma_coverage.py``, its sides measured to 0.5 mm) and
checked on the others (docs/pose.md, "What σ covers"); its extents' √2 follows from it (two readings of a
ruler per length), not tuned — 0.42 mm at the default, within ISO 2768-m's general tolerances of a machined
length (± 0.3 mm to 120 mm, ± 0.5 mm to 400 mm). ``first_order_share`` is the one propagation: a
weighted least-squares solution moves with a parameter p by ``dθ = −A⁻¹ Jᵀ W ∂r/∂p`` (A = Jᵀ W J); its
share is ``D Σ_p Dᵀ``. ``edge_covariance`` is the measurements' share for edges found on an image (the
tracker's, the one-click search's): a noise of each sample plus an offset and a tilt shared by each edge's
samples.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..calibration import check_covariance, perturbed_camera, principal_steps
from ..camera import Camera
from ..transforms import log_so3
from .refine import RefineResult, ViewClicks, click_sigmas, refine_views
from .residuals import as_clicks, residuals

__all__ = [
    "with_camera_uncertainty",
    "with_views_camera_uncertainty",
    "pose_delta",
    "Priors",
    "CAMERA_PRIOR_F_REL",
    "CAMERA_PRIOR_C_PX",
    "MODEL_PRIOR_M",
    "intrinsics_prior_cov",
    "first_order_share",
    "first_order_moves",
    "grouped_share",
    "edge_covariance",
    "clicks_model_share",
    "model_sigma_of",
    "MODEL_EXTENT_PER_EDGE",
    "model_scale_share",
    "EDGE_BIAS_PX",
    "CURVED_EDGE_BIAS_PX",
]

# The stated priors (module docstring; measured in bench/sigma_coverage.py, docs/pose.md).
CAMERA_PRIOR_F_REL = 0.003  # σ of fx and fy, relative, for a camera file that states no covariance
CAMERA_PRIOR_C_PX = 1.0  # σ of u0 and v0 (pixels), idem
MODEL_PRIOR_M = 0.0003  # σ of each model edge's position (metres), unless the object says its own
# σ of each of the model's extents, per model_sigma_m: the distance between two edges, each placed to
# model_sigma_m, is known to √2 of it (one stated number, the model's; not tuned on any sequence).
MODEL_EXTENT_PER_EDGE = float(np.sqrt(2.0))
# An edge found on an image may sit a fraction of a pixel off along its whole length: ``edge_covariance``
# counts each edge's offset as one error of at least this (pixels), straight and curved (measured for the
# one-click search: app/vision/search.py).
EDGE_BIAS_PX, CURVED_EDGE_BIAS_PX = 0.1, 0.2


def model_sigma_of(sigmas) -> float:
    """An object's model prior (metres) from its stored σs (a mapping name → metres): ``sigmas["model"]`` where
    the operator said it (``mcit db import --model-sigma-mm``), else ``MODEL_PRIOR_M``."""
    return float(sigmas.get("model", MODEL_PRIOR_M)) if sigmas else MODEL_PRIOR_M


@dataclass(frozen=True)
class Priors:
    """What a pose's σ adds to its measurements' share. camera_cov : (12, 12) covariance of C's entries
    (a calibration's, or ``intrinsics_prior_cov``'s), or None: no camera share. model_sigma_m : σ of each
    model edge's position (metres), and ``MODEL_EXTENT_PER_EDGE`` of it for each of the model's extents
    (``model_scale_share``); 0: no model share."""

    camera_cov: np.ndarray | None = None
    model_sigma_m: float = MODEL_PRIOR_M


def intrinsics_prior_cov(
    camera: Camera, f_rel: float = CAMERA_PRIOR_F_REL, c_px: float = CAMERA_PRIOR_C_PX
) -> np.ndarray:
    """(12, 12) covariance of ``camera.C.ravel()`` when fx, fy are known to ``f_rel`` (relative) and u0, v0
    to ``c_px`` pixels, independently, the pose of the camera exact: C = K [R | t] moves with fx by
    [R | t]'s row 0 in C's row 0, with u0 by row 2 in row 0, with fy and v0 likewise in row 1."""
    K, T = camera.decompose()
    P = T[:3, :] * float(np.sign(camera.C[2, :3] @ T[2, :3]))  # C = K P exactly (C is normalised so)
    D = np.zeros((12, 4))
    D[0:4, 0], D[0:4, 2] = P[0], P[2]  # ∂C₀/∂fx, ∂C₀/∂u0
    D[4:8, 1], D[4:8, 3] = P[1], P[2]  # ∂C₁/∂fy, ∂C₁/∂v0
    s = np.array([f_rel * abs(K[0, 0]), f_rel * abs(K[1, 1]), c_px, c_px])
    return (D * s**2) @ D.T


def first_order_share(
    J: np.ndarray, w: np.ndarray, residual_of: Callable[[np.ndarray], np.ndarray], cov_p: np.ndarray
) -> np.ndarray:
    """(k, k) share of a parameter p's uncertainty ``cov_p`` (n, n) in a weighted least-squares solution
    (Jacobian J (m, k), weights w (m,)): ``D cov_p Dᵀ`` with D = −A⁻¹ Jᵀ W ∂r/∂p, ∂r/∂p by central
    differences of ``residual_of(δp)`` (the residuals (m,) at the solution with p moved by δp) along the
    principal axes of ``cov_p``."""
    _, moves = first_order_moves(J, w, residual_of, cov_p)
    return moves.T @ moves


def first_order_moves(
    J: np.ndarray, w: np.ndarray, residual_of: Callable[[np.ndarray], np.ndarray], cov_p: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``first_order_share``'s pieces: the ±1σ steps of p along the principal axes of ``cov_p`` (K, n) and the
    solution's move for each (K, k), for a caller that needs the joint covariance of the solution and p."""
    A = (J * w[:, None]).T @ J
    Ai = np.linalg.pinv(A)
    steps = principal_steps(cov_p)
    moves = np.array([-Ai @ (J * w[:, None]).T @ (0.5 * (residual_of(d) - residual_of(-d))) for d in steps])
    return steps, moves.reshape(len(steps), J.shape[1])


def model_scale_share(
    J: np.ndarray,
    w: np.ndarray,
    residual_of: Callable[[Callable[[np.ndarray], np.ndarray]], np.ndarray],
    bounds_m: np.ndarray,
    sigma_m: float,
) -> np.ndarray:
    """(k, k) share of the model's per-dimension scale in a weighted least-squares solution (J (m, k), weights
    w (m,)): each of the model's extents (its bounds ``bounds_m`` (2, 3), metres, in the frame of the points it
    scales: ``BRep.bounds()`` in the object's) off by ``MODEL_EXTENT_PER_EDGE`` × ``sigma_m``, independently, the
    points moving about the bounds' centre (not the frame's origin, which may lie anywhere: a mesh exported in
    site coordinates). ``residual_of(scale)`` gives the residuals (m,) with the model's points X (…, 3) moved to
    ``scale(X)``. An axis with no extent (under 1 mm: a flat model's thickness) has no scale to be off."""
    b = np.asarray(bounds_m, float).reshape(2, 3)
    ext, centre = b[1] - b[0], 0.5 * (b[0] + b[1])
    var = np.where(ext > 1e-3, (MODEL_EXTENT_PER_EDGE * float(sigma_m) / np.maximum(ext, 1e-3)) ** 2, 0.0)
    if not (sigma_m > 0 and var.max() > 0):
        return np.zeros((J.shape[1], J.shape[1]))
    return first_order_share(J, w, lambda s: residual_of(lambda X: centre + (X - centre) * (1.0 + s)), np.diag(var))


def grouped_share(
    J: np.ndarray,
    w: np.ndarray,
    residual_of: Callable[[np.ndarray], np.ndarray],
    groups: np.ndarray,
    sigma: float,
) -> np.ndarray:
    """(k, k) share of independent 3D offsets of σ ``sigma`` (metres), one per group of residuals (a model
    edge's samples move together): ``residual_of(d)`` gives the residuals with every group moved by d (3,)
    — each residual depends on its own group's offset only, so three central differences give them all."""
    if not sigma > 0:
        return np.zeros((J.shape[1], J.shape[1]))
    A = (J * w[:, None]).T @ J
    Ai = np.linalg.pinv(A)
    _, inv = np.unique(np.asarray(groups), return_inverse=True)
    share = np.zeros((J.shape[1], J.shape[1]))
    for e in np.eye(3) * float(sigma):
        dr = 0.5 * (residual_of(e) - residual_of(-e))
        G = np.zeros((inv.max() + 1, J.shape[1]))  # per group: Σ_i∈group w_i dr_i J_i
        np.add.at(G, inv, J * (w * dr)[:, None])
        dq = G @ Ai  # one row per group: its pose shift (A symmetric)
        share += dq.T @ dq
    return share


def pose_delta(T: np.ndarray, T0: np.ndarray) -> np.ndarray:
    """(δt, δr) with ``T = (exp([δr]×) R0, t0 + δt)`` — refine's perturbation (world frame)."""
    return np.concatenate([T[:3, 3] - T0[:3, 3], log_so3(T[:3, :3] @ T0[:3, :3].T)])


def with_camera_uncertainty(
    result: RefineResult,
    camera: Camera,
    camera_cov: np.ndarray | None,
    *,
    segs_uv: np.ndarray | None = None,
    edges_obj: np.ndarray | None = None,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
    huber_px: float = 3.0,
) -> RefineResult:
    """``result`` (refined with ``camera`` on these clicks) with the camera calibration's share
    added to its ``cov``; ``cov_parts`` holds "clicks" and "camera calibration". Unchanged when
    ``camera_cov`` is None.

    camera_cov : array (12, 12), covariance of ``camera.C.ravel()``.
    """
    view = ViewClicks(camera, segs_uv, edges_obj, points_uv, points_obj, sigma_px=result.sigma_px)
    return with_views_camera_uncertainty(result, [view], [camera_cov], huber_px=huber_px)


def with_views_camera_uncertainty(
    result: RefineResult,
    views: Sequence[ViewClicks],
    camera_covs: Sequence[np.ndarray | None],
    huber_px: float = 3.0,
    model_sigma_m: float = 0.0,
    model_bounds_m: np.ndarray | None = None,
) -> RefineResult:
    """``result`` (refined by ``refine_views`` on ``views``) with every camera calibration's share added to its
    ``cov``: each view's C moved ±1σ along the principal axes of its covariance (``camera_covs``, one (12, 12)
    or None per view), the other views held; and the model's share (``model_sigma_m`` per model edge or
    point, and its extents from its bounds ``model_bounds_m`` (2, 3), object frame: ``clicks_model_share``).
    ``cov_parts`` holds "clicks", "camera calibration" and "model". Unchanged when no view has a covariance and
    ``model_sigma_m`` is 0."""
    model = clicks_model_share(result, views, model_sigma_m, model_bounds_m)
    if all(c is None for c in camera_covs) and model is None:
        return result
    T0, share = result.T_world_obj, np.zeros((6, 6))
    for i, cov in enumerate(camera_covs):
        if cov is None:
            continue
        for d in principal_steps(check_covariance(cov, 12, "camera_cov (of C's entries)")):
            moved = []
            for step in (d, -d):
                vs = list(views)
                vs[i] = replace(views[i], camera=perturbed_camera(views[i].camera, step))
                moved.append(refine_views(vs, T0, loss=result.loss, huber_px=huber_px).T_world_obj)
            dq = 0.5 * (pose_delta(moved[0], T0) - pose_delta(moved[1], T0))
            share += np.outer(dq, dq)
    parts = {"clicks": result.cov}
    if any(c is not None for c in camera_covs):
        parts["camera calibration"] = share
    if model is not None:
        parts["model"] = model
    return replace(result, cov=result.cov + share + (0.0 if model is None else model), cov_parts=parts)


def clicks_model_share(
    result: RefineResult, views: Sequence[ViewClicks], model_sigma_m: float, bounds_m: np.ndarray | None = None
) -> np.ndarray | None:
    """(6, 6) share of the model's uncertainty in a pose refined from clicks (``refine_views`` on ``views``):
    each clicked model edge (point) off by an independent 3D offset of σ ``model_sigma_m`` (one per model
    feature, whichever view clicked it, ``grouped_share``), and the model's extents (its bounds ``bounds_m``
    (2, 3), object frame; None: the clicked features' own) each off by √2 of it (``model_scale_share``),
    propagated by first order with the clicks' weights 1/σ². None when ``model_sigma_m`` is 0."""
    if not model_sigma_m > 0:
        return None
    R, t = result.T_world_obj[:3, :3], result.T_world_obj[:3, 3]
    Js, ws, keys, fns, pts = [], [], [], [], []
    for v in views:
        c = as_clicks(v.segs_uv, v.edges_obj, v.points_uv, v.points_obj)
        _, J, _ = residuals(v.camera, R, t, c, jacobian=True)
        Js.append(J)
        ws.append(1.0 / click_sigmas(v.sigma_px, c) ** 2)
        feats = [np.round(e, 6).tobytes() for e in c.edges_obj] + [np.round(p, 6).tobytes() for p in c.points_obj]
        keys += [k for k in feats for _ in (0, 1)]  # two residual rows per click

        def moved(d, v=v, c=c):  # every clicked model point moved by d (3,), or to d(X) (model_scale_share)
            move = d if callable(d) else lambda X, d=d: X + d
            e = None if c.n_segments == 0 else move(c.edges_obj)
            p = None if c.n_points == 0 else move(c.points_obj)
            s = None if c.n_segments == 0 else c.segs_uv
            u = None if c.n_points == 0 else c.points_uv
            return residuals(v.camera, R, t, as_clicks(s, e, u, p))[0]

        fns.append(moved)
        pts.append(np.vstack([c.edges_obj.reshape(-1, 3), c.points_obj.reshape(-1, 3)]))
    groups = np.unique(np.array(keys, dtype=object), return_inverse=True)[1]
    J, w = np.vstack(Js), np.concatenate(ws)
    share = grouped_share(J, w, lambda d: np.concatenate([f(d) for f in fns]), groups, model_sigma_m)
    if bounds_m is None:
        P = np.vstack(pts)
        bounds_m = np.array([P.min(axis=0), P.max(axis=0)])
    scaled = lambda scale: np.concatenate([f(scale) for f in fns])  # noqa: E731
    return share + model_scale_share(J, w, scaled, bounds_m, model_sigma_m)


def edge_covariance(
    J: np.ndarray,
    r: np.ndarray,
    w: np.ndarray,
    groups: np.ndarray,
    floor: np.ndarray,
    k: int,
    uv: np.ndarray,
    normals: np.ndarray,
) -> np.ndarray:
    """(k, k) covariance of a weighted least-squares step's parameters when the samples' errors are a
    noise of their own plus, per edge, an offset and a tilt shared by its samples (an edge found a
    fraction of a pixel off, or turned a little, is so along its length):
    A⁻¹ Jᵀ W Σ W J A⁻¹ with Σ = s² I + Σ_edges (σ_o² 1 1ᵀ + σ_θ² ℓ ℓᵀ), ℓ the samples' positions along
    their edge (pixels). s² is the residuals' weighted variance about their edge's line, σ_o² and σ_θ²
    the edges' mean squared offset and tilt, each edge's at least its floor (``floor`` pixels; its ends
    moved by ``floor`` for the tilt)."""
    A = (J * w[:, None]).T @ J
    Ai = np.linalg.pinv(A)
    ug, inv = np.unique(groups, return_inverse=True)
    G = len(ug)
    sw = np.maximum(np.bincount(inv, weights=w, minlength=G), 1e-12)
    # each edge's position coordinate: along its mean tangent, about its weighted centre
    nm = np.zeros((G, 2))
    np.add.at(nm, inv, normals * w[:, None])
    nm /= np.maximum(np.linalg.norm(nm, axis=1), 1e-12)[:, None]
    tang = np.column_stack([-nm[:, 1], nm[:, 0]])
    c = np.zeros((G, 2))
    np.add.at(c, inv, uv * w[:, None])
    c /= sw[:, None]
    ell = np.einsum("ni,ni->n", uv - c[inv], tang[inv])
    # each edge's line fitted to its residuals: offset + tilt · ell
    mean = np.bincount(inv, weights=w * r, minlength=G) / sw
    sll = np.bincount(inv, weights=w * ell * ell, minlength=G)
    tilt = np.bincount(inv, weights=w * ell * r, minlength=G) / np.maximum(sll, 1e-9)
    fit = mean[inv] + tilt[inv] * ell
    dof = max(float(w.sum()) - 2 * G, 1.0)
    s2 = float(np.sum(w * (r - fit) ** 2) / dof)
    fl = np.zeros(G)
    fl[inv] = np.asarray(floor, float)
    o2 = np.maximum(float(np.sum(sw * mean**2) / float(sw.sum())), fl**2)
    long_ = sll > 1e-6
    t2 = float(np.sum(sw[long_] * tilt[long_] ** 2) / max(float(sw[long_].sum()), 1e-12)) if long_.any() else 0.0
    half = np.sqrt(3.0 * sll / sw)  # an edge's half length (pixels), from the spread of its samples along it
    t2 = np.maximum(t2, (fl / np.maximum(half, 1.0)) ** 2)  # at least its ends moved by its floor
    Go = np.zeros((G, k))  # Σ_i∈edge w_i J_i
    np.add.at(Go, inv, J * w[:, None])
    Gt = np.zeros((G, k))  # Σ_i∈edge w_i ℓ_i J_i
    np.add.at(Gt, inv, J * (w * ell)[:, None])
    M = s2 * ((J * (w**2)[:, None]).T @ J) + (Go * o2[:, None]).T @ Go + (Gt * t2[:, None]).T @ Gt
    return Ai @ M @ Ai
