"""Small-motion pose refinement: the paper's linearised least squares, iterated to the ML estimate.

The paper (§IV.2, eqs. 6–10) linearises the rotation, ``R ≈ I + [r]×``, writes for each clicked
point the two plane equations of eq. (4) at the moved model point, ``m_u·(P + dP) + a_u = 0`` with
``dP = T + r × P``, and solves ``A X = B`` for X = (T, r) by least squares in one step (valid up to
~18° and 5 cm). Here that step is iterated (Gauss–Newton, with Levenberg–Marquardt damping so
that it also converges from far away) and every algebraic row is divided by its depth s: the row
``m_u·P + a_u = s (u(P) − u_clicked)`` becomes a pixel residual, so the cost is the reprojection
error in pixels, the maximum-likelihood estimate under isotropic pixel noise on the clicks.

Residuals (``core.pose.residuals``): a clicked point gives (u, v) projected minus clicked; a clicked
segment gives the signed distances of its two clicked pixels to the projected infinite model line
(the operator clicks two points along an edge, not its endpoints: only the distance across the
line is measured). Points and segments mix freely; the clicks must fix the 6 degrees of freedom.

Click noise: ``sigma_px`` is one σ for every click, or one per click (segments first, then
points, as ``kinds``): each residual is weighted by 1/σ² (a click snapped to the image's edge at
0.15 px counts 44 times as much as a raw click at 1 px), and the covariance is ``(Jᵀ W J)⁻¹``.

Robust loss: ``loss="huber"`` weights each clicked pixel (a segment's two pixels separately, a
point's 2D distance) by ``min(1, huber_px / distance)`` (iteratively reweighted; ``core.robust``'s Huber
weight, compiled), so a wrong click pulls with a bounded force; the result names the down-weighted clicks.

Pose parametrisation of the steps and of the covariance: δ = (δt, δr), δt the translation of the
object's origin in the world frame (metres), δr a rotation vector in world axes about the object's
origin (radians): ``R ← exp([δr]×) R``, ``t ← t + δt`` (perturbation on the left, in the world frame).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..camera import Camera
from ..checks import MAX_M, MAX_SCALE, MIN_SCALE, finite_array, positive_scale
from ..transforms import check_T
from ._lazy import frozen, kernels
from .residuals import Clicks, as_clicks, stack_views, view_matrices

_k = kernels()  # core.pose._kernels, imported on first use (numba is not loaded before mcit serve's first page)

__all__ = [
    "RefineResult",
    "ViewClicks",
    "PosePrior",
    "refine",
    "refine_views",
    "refine_many",
    "refine_with_prior",
    "click_sigmas",
]

_LOSSES = ("l2", "huber")
_NO_PRIOR = (np.eye(4), np.zeros((6, 6)))  # the kernel's prior pose and information when there is none (only read)


@dataclass(frozen=True)
class RefineResult:
    """A refined pose with its uncertainty and per-click diagnostics.

    T_world_obj : array, shape (4, 4), the refined pose.
    cov : array, shape (6, 6), covariance of (δt (m), δr (rad)) at the solution (module
        docstring), ``(Jᵀ W J)⁻¹`` with W the 1/σ² and robust weights; translation block first.
    rms_px : RMS of all residuals, pixels (unweighted).
    residuals_px : array, shape (2 S + 2 P,), pixels: for each segment the signed distances of its
        two clicked pixels to the projected model line, then (u, v) of each point.
    iterations : accepted Gauss–Newton/LM steps.
    converged : the step or the cost decrease fell below tolerance (False: iteration limit hit).
    kinds : tuple of str, one per click, segments first: "segment" or "point".
    click_residuals_px : array, shape (S + P,), per click: a segment's larger |distance| of its two
        pixels, a point's reprojection distance (pixels).
    weights : array, shape (S + P,), the final robust weight of each click (its smallest pixel
        weight; all 1 with ``loss="l2"``).
    downweighted : tuple of int, indices (into ``kinds``) of clicks with weight < 1.
    sigma_px : the click noise the covariance assumes (pixels): a float, or an array (S + P,).
    sigma_est_px : a-posteriori noise estimate sqrt(Σ w r² / (m − 6)), NaN without redundancy.
    loss : "l2" or "huber".
    cov_parts : dict, name → (6, 6): what ``cov`` is made of when more than the clicks went in
        ("clicks", "camera calibration": ``core.pose.uncertainty.with_camera_uncertainty``);
        empty when ``cov`` is the clicks' alone.
    views : tuple of int, one per click as ``kinds``: the view it was clicked in (``refine_views``;
        all 0 for one view).
    """

    T_world_obj: np.ndarray
    cov: np.ndarray
    rms_px: float
    residuals_px: np.ndarray
    iterations: int
    converged: bool
    kinds: tuple[str, ...] = field(default=())
    click_residuals_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    downweighted: tuple[int, ...] = ()
    sigma_px: float | np.ndarray = 1.0
    sigma_est_px: float = float("nan")
    loss: str = "l2"
    cov_parts: dict = field(default_factory=dict)
    views: tuple[int, ...] = ()

    @property
    def n_segments(self) -> int:
        return self.kinds.count("segment")

    @property
    def segment_residuals_px(self) -> np.ndarray:
        """array, shape (S, 2): signed distances of each segment's two clicked pixels (pixels)."""
        return self.residuals_px[: 2 * self.n_segments].reshape(-1, 2)

    @property
    def point_residuals_px(self) -> np.ndarray:
        """array, shape (P, 2): (u, v) reprojection error of each clicked point (pixels)."""
        return self.residuals_px[2 * self.n_segments :].reshape(-1, 2)

    @property
    def std_t_m(self) -> np.ndarray:
        """Standard deviations (3,) of the translation, metres (world axes)."""
        return np.sqrt(np.diag(self.cov)[:3])

    @property
    def std_r_deg(self) -> np.ndarray:
        """Standard deviations (3,) of the rotation about world axes, degrees."""
        return np.degrees(np.sqrt(np.diag(self.cov)[3:]))


def check_options(camera, loss: str, huber_px: float, sigma_px) -> None:
    """ValueError for a camera that is not a Camera, an unknown loss or a non-positive scale."""
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    if loss not in _LOSSES:
        raise ValueError(f"loss must be one of {_LOSSES}, got {loss!r}")
    positive_scale(huber_px, "huber_px", " px")
    if type(sigma_px) is float and MIN_SCALE <= sigma_px <= MAX_SCALE:
        return
    try:
        sigma = np.asarray(sigma_px, dtype=float)
    except (TypeError, ValueError):
        sigma = np.array(np.nan)
    if not (sigma.ndim <= 1 and sigma.size > 0 and np.all(sigma >= MIN_SCALE) and np.all(sigma <= MAX_SCALE)):
        raise ValueError(
            f"sigma_px must be one value or one per click, each a positive finite number between {MIN_SCALE:g} "
            f"and {MAX_SCALE:g} px, got {sigma_px!r:.120}"
        )


def click_sigmas(sigma_px, clicks: Clicks) -> np.ndarray:
    """σ of each residual row (2 S + 2 P,) from one σ or one per click (S + P,); ValueError if
    the count does not match the clicks."""
    sigma = np.asarray(sigma_px, dtype=float)
    n = clicks.n_segments + clicks.n_points
    if sigma.ndim == 0:
        return np.full(2 * n, float(sigma))
    if sigma.shape != (n,):
        raise ValueError(
            f"sigma_px has {sigma.size} values for {clicks.n_segments} segment(s) and {clicks.n_points} point(s): "
            "give one σ, or one per click (segments first, then points)"
        )
    return np.repeat(sigma, 2)


def _unobservable(v: np.ndarray, extent_m: float) -> str:
    """The message naming the motion v (δt in m, δr in rad) that the clicks leave free: the
    eigenvector of JᵀJ (columns scaled to unit diagonal, so the test does not depend on the units)
    whose eigenvalue is below 1e-16 of the largest (singular values of J below 1e-8)."""
    part = "translation" if np.linalg.norm(v[:3]) > np.linalg.norm(v[3:]) * extent_m else "rotation"
    direction = v[:3] if part == "translation" else v[3:]
    direction = direction / np.linalg.norm(direction)
    return (
        f"the clicks do not fix the pose: a {part} along {np.round(direction, 3).tolist()} (world) "
        "changes no residual; click more edges with other directions, an edge not through the "
        "common vertex of the others, or a vertex"
    )


def _as_pose(T_world_obj) -> np.ndarray:
    """A float copy of a rigid transform; ``check_T`` judges (and explains) anything that is not
    plainly one (the fast test accepts a subset of what check_T accepts)."""
    T = np.array(T_world_obj, dtype=float)
    if T.shape == (4, 4) and _k.pose_ok(T, MAX_M):
        return T
    T = check_T(T, "T_world_obj").copy()
    finite_array(T[:3, 3], (3,), "T_world_obj's translation", max_abs=MAX_M, unit=" m")
    return T


def refine(
    camera: Camera,
    T_world_obj: np.ndarray,
    *,
    segs_uv: np.ndarray | None = None,
    edges_obj: np.ndarray | None = None,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
    loss: str = "l2",
    huber_px: float = 3.0,
    sigma_px: float = 1.0,
    max_iterations: int = 100,
) -> RefineResult:
    """Refine an object's pose from clicked edges and points: minimise the pixel reprojection error.

    Parameters
    ----------
    camera : Camera
        The global model C.
    T_world_obj : array, shape (4, 4)
        Starting pose (the database pose for a small motion, or a P3L candidate).
    segs_uv : array, shape (S, 2, 2), pixels, optional
        Two clicked points along each image edge.
    edges_obj : array, shape (S, 2, 3), metres, object frame, optional
        The matched model edges.
    points_uv : array, shape (P, 2), pixels, optional
    points_obj : array, shape (P, 3), metres, object frame, optional
        Clicked points and the matched model points.
    loss : "l2" (maximum likelihood under Gaussian click noise) or "huber" (a wrong click pulls
        with at most ``huber_px``).
    huber_px : float
        Huber threshold in pixels: clicked pixels farther than this from the model are down-weighted.
    sigma_px : float or array, shape (S + P,)
        Click noise (standard deviation, pixels): one for every click, or one per click (segments
        first, then points); weights the residuals by 1/σ² and scales the covariance.
    max_iterations : int

    Returns
    -------
    RefineResult

    Raises
    ------
    ValueError
        Bad shapes; fewer than 6 residuals or clicks that leave a direction of motion free (the
        message names it); a starting pose with a clicked model feature behind the camera.
    """
    check_options(camera, loss, huber_px, sigma_px)
    T = _as_pose(T_world_obj)
    clicks = as_clicks(segs_uv, edges_obj, points_uv, points_obj)
    return _refine(camera, T, clicks, loss, float(huber_px), sigma_px, int(max_iterations))


@dataclass(frozen=True)
class ViewClicks:
    """The clicks made in one view (``refine_views``): its camera, the clicked segments and points with
    their matched model features (as ``refine`` takes them) and their noise σ (one, or one per click of
    this view, segments first).

    seg_index, point_index : optional, where each of this view's segments (points) stands among all the
    views' segments (points): the caller's click order, which ``refine_views``' result then follows. Give
    them for every view or for none (then every view's segments in view order, then every view's points)."""

    camera: Camera
    segs_uv: np.ndarray | None = None
    edges_obj: np.ndarray | None = None
    points_uv: np.ndarray | None = None
    points_obj: np.ndarray | None = None
    sigma_px: float | np.ndarray = 1.0
    seg_index: Sequence[int] | None = None
    point_index: Sequence[int] | None = None


@dataclass(frozen=True)
class PosePrior:
    """A pose measured already, refined together with the clicks (``refine_views``' ``prior``): the
    maximum a posteriori pose of the clicks and the prior.

    T_world_obj : (4, 4) the measured pose (e.g. the one-click search's). cov : (6, 6) its covariance of
    (δt, δr) (module docstring); directions it leaves at zero variance (a pose held on the table: its
    height and tilt) are held at ``fixed_std`` (metres, radians). shared_cov : (6, 6), optional, the share
    of ``cov`` the clicks have too (the camera calibration's, both being measured through one C): the two
    are combined without it, and it is added to the result. name : what the result's ``cov_parts`` calls
    the prior ("found pose": "found pose and clicks"); shared_name what it calls ``shared_cov`` ("camera
    calibration", or "model" for a found pose's σ that holds the model's prior alone)."""

    T_world_obj: np.ndarray
    cov: np.ndarray
    fixed_std: tuple[float, float] = (1e-4, 1e-4)
    shared_cov: np.ndarray | None = None
    name: str = "prior"
    shared_name: str = "camera calibration"

    def information(self) -> np.ndarray:
        """Λ (6, 6): pinv of (cov − shared_cov) on its range, 1/fixed_std² along the directions it
        leaves at zero variance. ValueError when a covariance is not a finite PSD (6, 6) matrix."""
        P = np.asarray(self.cov, dtype=float)
        if P.shape != (6, 6) or not np.all(np.isfinite(P)):
            raise ValueError(f"cov_prior must be a finite (6, 6) covariance of (δt, δr), got shape {P.shape}")
        if self.shared_cov is not None:
            Q = np.asarray(self.shared_cov, dtype=float)
            if Q.shape != (6, 6) or not np.all(np.isfinite(Q)):
                raise ValueError(f"the prior's shared_cov must be a finite (6, 6) covariance, got shape {Q.shape}")
            P = P - Q
        return _prior_information(P, self.fixed_std)


def refine_views(
    views: Sequence[ViewClicks],
    T_world_obj: np.ndarray,
    *,
    loss: str = "l2",
    huber_px: float = 3.0,
    max_iterations: int = 100,
    prior: PosePrior | None = None,
) -> RefineResult:
    """``refine`` from clicks made in several views at once: one pose fits them all (its residuals in
    each view's pixels, weighted by that view's σ). A second view sees along the first view's line of
    sight, where one view's clicks fix the pose worst (``bench/views.py`` measures it).

    The result's per-click arrays (``kinds``, ``views``, residuals, weights, σ) follow the clicks' order:
    the views' ``seg_index`` / ``point_index`` when given, else every view's segments in view order, then
    every view's points. ``prior``: a pose measured already (``PosePrior``), fitted together with the
    clicks (any number of them: none returns the prior); ``cov`` is then ``(Jᵀ W J + Λ)⁻¹`` plus the
    prior's ``shared_cov``. ValueError as ``refine``, naming the view whose clicks are wrong."""
    views = list(views)
    if not views:
        raise ValueError("no view's clicks: give the clicks of at least one view")
    per_view, order = [], []
    for i, v in enumerate(views):
        if not isinstance(v, ViewClicks):
            raise ValueError(f"view {i + 1} must be a ViewClicks, got {type(v).__name__}")
        try:
            check_options(v.camera, loss, huber_px, v.sigma_px)
            c = as_clicks(v.segs_uv, v.edges_obj, v.points_uv, v.points_obj)
            click_sigmas(v.sigma_px, c)  # one σ, or one per click of this view
        except ValueError as exc:
            raise ValueError(f"view {i + 1}: {exc}") from None
        per_view.append(c)
        order.append((v.seg_index, v.point_index))
    given = [o[0] is not None or o[1] is not None for o in order]
    if any(given) and not all(given):
        raise ValueError("give seg_index / point_index for every view or for none")
    if all(given):  # a view without segments (points) places none
        order = [(() if si is None else si, () if pi is None else pi) for si, pi in order]
    clicks = stack_views(per_view, order if all(given) else None)
    sigma_px = _sigma_in_order(views, per_view, clicks)
    out = refine_many(
        [v.camera for v in views],
        _as_pose(T_world_obj)[None],
        clicks,
        loss,
        float(huber_px),
        sigma_px,
        int(max_iterations),
        prior=prior,
    )[0][0]
    if isinstance(out, str):
        raise ValueError(out)
    return out


def _sigma_in_order(views: list[ViewClicks], per_view: list[Clicks], clicks: Clicks):
    """σ of each click of the stacked ``clicks`` (segments, then points, in their order): one float when
    all are equal, else an array."""
    seg_sigma = np.empty(clicks.n_segments)
    pt_sigma = np.empty(clicks.n_points)
    seg_view, pt_view = clicks.view_index
    for i, (v, c) in enumerate(zip(views, per_view)):
        sigma = click_sigmas(v.sigma_px, c)[::2]  # one per click of this view, segments first
        seg_sigma[seg_view == i] = sigma[: c.n_segments]
        pt_sigma[pt_view == i] = sigma[c.n_segments :]
    sigma_px = np.concatenate([seg_sigma, pt_sigma])
    if not len(sigma_px):
        return 1.0
    return float(sigma_px[0]) if np.all(sigma_px == sigma_px[0]) else sigma_px


def _refine(
    camera: Camera, T: np.ndarray, clicks: Clicks, loss: str, huber_px: float, sigma_px, max_iterations: int
) -> RefineResult:
    out = refine_many(camera, T[None], clicks, loss, huber_px, sigma_px, max_iterations)[0][0]
    if isinstance(out, str):
        raise ValueError(out)
    return out


def refine_many(
    camera: Camera | Sequence[Camera],
    T_starts: np.ndarray,
    clicks: Clicks,
    loss: str = "l2",
    huber_px: float = 3.0,
    sigma_px=1.0,
    max_iterations: int = 100,
    edges_obj: np.ndarray | None = None,
    prior: PosePrior | None = None,
) -> list[tuple[RefineResult | str, float]]:
    """``refine`` from many starts at once (one compiled call): the P3L candidates of a triple,
    or the assignments the matcher tries. ``camera``: one, or one per view of stacked clicks
    (``residuals.stack_views``).

    T_starts (K, 4, 4) rigid transforms (validated by the caller); clicks as ``as_clicks`` made
    them; edges_obj (K, S, 2, 3): each start's own model edges (default: the clicks' for every
    start). prior : a pose measured already, fitted together with the clicks (``refine_views``).
    Returns per start (RefineResult, or the reason it could not be refined, and score): the RMS pixel
    distance of the clicks to the projected finite model features at the refined pose
    (``residuals.pose_distance_cost``), inf when refinement failed.
    """
    m = clicks.n_residuals
    if len(T_starts) == 0:
        return []
    Lam = None if prior is None else prior.information()
    if prior is not None and m == 0:
        return [(_prior_alone(prior, Lam, clicks), 0.0) for _ in range(len(T_starts))]
    if m < 6 and prior is None:
        raise ValueError(
            f"{clicks.n_segments} segment(s) and {clicks.n_points} point(s) give {m} residuals; "
            "a pose has 6 degrees of freedom: click at least 3 edges (or 2 edges and a vertex)"
        )
    S, P = clicks.n_segments, clicks.n_points
    T0 = np.ascontiguousarray(T_starts, dtype=float)
    K = len(T0)
    edges = np.ascontiguousarray(
        np.broadcast_to(clicks.edges_obj, (K, S, 2, 3)) if edges_obj is None else edges_obj, dtype=float
    )
    # Scale of the problem for the step test: the clicked features' extent about the origin.
    extent = np.full(K, max(1e-3, float(np.abs(clicks.points_obj).max()) if P else 0.0))
    if S:
        extent = np.maximum(extent, np.abs(edges).reshape(K, -1).max(axis=1))
    b = 1.0 / click_sigmas(sigma_px, clicks) ** 2  # ML weight of each residual row
    n = S + P
    T, r, w_unit, cov, free = (
        np.empty((K, 4, 4)),
        np.empty((K, m)),
        np.empty((K, 2 * S + P)),
        np.empty((K, 6, 6)),
        np.empty((K, 6)),
    )
    status, iterations, converged = np.empty(K, np.int64), np.empty(K, np.int64), np.empty(K, np.bool_)
    score, summary = np.empty(K), np.empty((K, 2 * n + 2))
    seg_view, pt_view = clicks.view_index
    _k.refine_many(
        view_matrices(camera, clicks),
        seg_view,
        pt_view,
        T0,
        frozen(edges),
        frozen(clicks.segs_uv),
        frozen(clicks.points_obj),
        frozen(clicks.points_uv),
        b,
        loss == "huber",
        float(huber_px),
        prior is not None,
        _NO_PRIOR[0] if prior is None else _as_pose(prior.T_world_obj),
        _NO_PRIOR[1] if Lam is None else Lam,
        int(max_iterations),
        extent,
        T,
        r,
        w_unit,
        cov,
        free,
        status,
        iterations,
        converged,
        score,
        summary,
    )
    out = _start_results(
        status, free, extent, summary, (T, cov, r, iterations, converged, score), clicks, sigma_px, loss
    )
    if prior is None or prior.shared_cov is None:
        return out
    return [(res, sc) if isinstance(res, str) else (_with_shared(res, prior), sc) for res, sc in out]


def _with_shared(res: RefineResult, prior: PosePrior) -> RefineResult:
    """``res`` with the prior's shared covariance added back (``PosePrior.shared_cov``)."""
    shared = np.asarray(prior.shared_cov, dtype=float)
    parts = {f"{prior.name} and clicks": res.cov, prior.shared_name: shared}
    return replace(res, cov=res.cov + shared, cov_parts=parts)


def _prior_alone(prior: PosePrior, Lam: np.ndarray, clicks: Clicks) -> RefineResult:
    """The prior with no click: its pose, cov = Λ⁻¹ (+ its shared share)."""
    cov = np.linalg.inv(Lam)
    res = RefineResult(
        T_world_obj=_as_pose(prior.T_world_obj),
        cov=0.5 * (cov + cov.T),
        rms_px=0.0,
        residuals_px=np.zeros(0),
        iterations=0,
        converged=True,
    )
    return res if prior.shared_cov is None else _with_shared(res, prior)


def _start_results(status, free, extent, summary, outputs, clicks: Clicks, sigma_px, loss: str):
    """``refine_many``'s answer per start from the compiled call's outputs: a RefineResult and its score,
    or the reason the start could not be refined and inf."""
    T, cov, r, iterations, converged, score = outputs
    n = clicks.n_segments + clicks.n_points
    sigma_out = float(sigma_px) if np.ndim(sigma_px) == 0 else np.asarray(sigma_px, dtype=float).copy()
    kinds = clicks.kinds
    out: list[tuple[RefineResult | str, float]] = []
    for k, st in enumerate(status.tolist()):
        if st == _k.BEHIND:
            out.append(
                (
                    "the starting pose puts a clicked model edge or point behind the camera; start from a "
                    "pose that shows the object in the image",
                    np.inf,
                )
            )
            continue
        if st == _k.SINGULAR:
            out.append(
                (
                    "the clicks do not fix the pose at the refined pose (singular normal equations); click more "
                    "edges with other directions, or a vertex",
                    np.inf,
                )
            )
            continue
        if st == _k.UNOBSERVABLE:
            out.append((_unobservable(free[k], float(extent[k])), np.inf))
            continue
        sk = summary[k]
        click_w = sk[n : 2 * n]
        res = RefineResult(
            T_world_obj=T[k],
            cov=cov[k],
            rms_px=float(sk[2 * n]),
            residuals_px=r[k],
            iterations=int(iterations[k]),
            converged=bool(converged[k]),
            kinds=kinds,
            click_residuals_px=sk[:n],
            weights=click_w,
            downweighted=tuple(i for i, x in enumerate(click_w.tolist()) if x < 1.0),
            sigma_px=sigma_out,
            sigma_est_px=float(sk[2 * n + 1]),
            loss=loss,
            views=clicks.views,
        )
        out.append((res, float(score[k])))
    return out


def refine_with_prior(
    camera: Camera,
    T_prior: np.ndarray,
    cov_prior: np.ndarray,
    *,
    segs_uv: np.ndarray | None = None,
    edges_obj: np.ndarray | None = None,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
    sigma_px: float | np.ndarray = 1.0,
    fixed_std: tuple[float, float] = (1e-4, 1e-4),
    max_iterations: int = 30,
) -> RefineResult:
    """Refine a pose known already (a pose found on the image, with its covariance) together with
    clicked edges and points: the maximum a posteriori pose of the clicks and the prior
    (``refine_views`` with a ``PosePrior``, in one view).

    Minimises Σ (r_click / σ)² + eᵀ Λ e, e = (t − t_prior, log(R R_priorᵀ)) (the module's δ), Λ the
    prior's information: ``pinv(cov_prior)`` on the range of ``cov_prior`` and, along the
    directions it leaves at zero variance (a pose constrained to lie on the table: its height and
    tilt), 1/``fixed_std``² (metres, radians): those stay as the prior has them. Any number of clicks
    helps (one clicked edge settles which of two near-symmetric poses it is); none returns the prior.

    Returns RefineResult: the pose, cov = (Jᵀ W J + Λ)⁻¹ (the prior included), the clicks' residuals
    and diagnostics. ValueError for bad input.
    """
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    T0 = _as_pose(T_prior)
    view = ViewClicks(camera, segs_uv, edges_obj, points_uv, points_obj, sigma_px)
    return refine_views([view], T0, prior=PosePrior(T0, cov_prior, fixed_std), max_iterations=max_iterations)


def _prior_information(P: np.ndarray, fixed_std: tuple[float, float]) -> np.ndarray:
    """The prior's information Λ (6, 6): pinv(P) on the range of the covariance P, 1/``fixed_std``² along
    the directions P leaves at zero variance. ValueError when P is not positive semi-definite."""
    P = 0.5 * (P + P.T)
    w, U = np.linalg.eigh(P)
    if w.min() < -1e-9 * max(float(w.max()), 1e-300):
        raise ValueError("cov_prior must be positive semi-definite")
    scale = np.concatenate([np.full(3, fixed_std[0]), np.full(3, fixed_std[1])])  # δ's units per direction
    big = np.array([1.0 / float(np.sum((U[:, j] * scale) ** 2)) for j in range(6)])  # 1/σ² of a fixed direction
    keep = w > 1e-12 * max(float(w.max()), 1e-300)
    lam = np.where(keep, 1.0 / np.where(keep, w, 1.0), big)
    return (U * lam) @ U.T
