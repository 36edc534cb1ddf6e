"""The two-step pose update as the operator uses it (source paper §IV): P3L, then refinement — the
single-view case of the pose pipeline (``core.pose.pipeline``: P3L's starts and the prior, each
refined with every click, one ranking).

The operator clicks N ≥ 3 image edges (and possibly vertices) of a known object and matches each to
a model edge (point). ``estimate_pose`` runs the geometric three-line solver on the first triple of
clicked edges that is not degenerate, refines every candidate with all the clicks (and, when the
database pose is given, also refines from it: the paper's small-motion case). When every candidate
of a triple refines to a poor fit (RMS above 3 σ: local minima, which noisy P3L solutions far from
the truth can fall into), the next triple's candidates are added. The refined candidates are ranked
by the RMS pixel distance of the clicks to the projected *finite* model segments and points
(``residuals.pose_distance_cost``: equal to the measurement RMS when the clicks fall on the
projected edges, larger when a pose slides an edge along its line away from the clicks). Every
candidate is returned for display; the first is the estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from ..checks import MAX_M, finite_array, positive_scale
from ..transforms import check_T, pose_error
from .candidates import p3l_triples
from .pipeline import rank
from .refine import RefineResult, check_options, click_sigmas, refine_many
from .residuals import as_clicks

__all__ = ["PoseCandidate", "PoseEstimate", "estimate_pose"]


@dataclass(frozen=True)
class PoseCandidate:
    """One candidate pose, before and after refinement.

    source : "p3l" (a solution of the three-line solver) or "prior" (refined from ``T_prior``).
    T_start : array, shape (4, 4), the P3L solution or the prior.
    refined : the refinement from T_start with every click, or None when it failed (``error``).
    score_px : RMS pixel distance of the clicks to the projected finite model features at the
        refined pose (inf when refinement failed): the ranking key.
    p3l_rank : the candidate's rank in ``p3l``'s output (0 = best by distance), −1 for the prior.
    error : why refinement failed (e.g. a clicked edge behind the camera at that candidate), or None.
    triple : the clicked edges (indices) whose P3L gave this candidate, None for the prior.
    """

    source: str
    T_start: np.ndarray
    refined: RefineResult | None
    score_px: float
    p3l_rank: int
    error: str | None = None
    triple: tuple[int, int, int] | None = None

    @property
    def T_world_obj(self) -> np.ndarray:
        """The refined pose (4, 4), or the start pose when refinement failed."""
        return self.refined.T_world_obj if self.refined is not None else self.T_start


@dataclass(frozen=True)
class PoseEstimate:
    """Result of ``estimate_pose``.

    candidates : list of PoseCandidate, best first (refined ones by ``score_px``; distinct poses
        only: candidates that refine to the same pose are merged into the best ranked).
    triple : indices (into the clicked segments) of the first triple whose P3L candidates were
        refined, or None when P3L was not run (fewer than 3 segments: the prior only).
    skipped_triples : (triple, reason) for the triples P3L could not use, and for those whose
        candidates all refined to a poor fit (the next triple's were then added).
    """

    candidates: list[PoseCandidate]
    triple: tuple[int, int, int] | None
    skipped_triples: tuple[tuple[tuple[int, int, int], str], ...] = ()

    @property
    def best(self) -> PoseCandidate:
        return self.candidates[0]

    @property
    def result(self) -> RefineResult:
        """The refinement result of the best candidate (pose, covariance, residuals)."""
        assert self.candidates[0].refined is not None
        return self.candidates[0].refined

    @property
    def T_world_obj(self) -> np.ndarray:
        """The estimated pose (4, 4)."""
        return self.result.T_world_obj

    @property
    def cov(self) -> np.ndarray:
        return self.result.cov

    @property
    def rms_px(self) -> float:
        return self.result.rms_px


def estimate_pose(
    camera: Camera,
    segs_uv: np.ndarray,
    edges_obj: np.ndarray,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
    *,
    T_prior: np.ndarray | None = None,
    loss: str = "l2",
    huber_px: float = 3.0,
    sigma_px: float | np.ndarray = 1.0,
    max_triples: int = 50,
    fit_rms_px: float | None = None,
) -> PoseEstimate:
    """Pose of a known object from N clicked edges (and points): P3L, then refinement with all.

    Parameters
    ----------
    camera : Camera
    segs_uv : array, shape (N, 2, 2), pixels
        Two clicked points on each image edge, in click order.
    edges_obj : array, shape (N, 2, 3), metres, object frame
        The model edge matched to each clicked segment.
    points_uv : array, shape (P, 2), pixels, optional
    points_obj : array, shape (P, 3), metres, object frame, optional
        Clicked vertices and the matched model points.
    T_prior : array, shape (4, 4), optional
        The database pose: also refined from, as a candidate (the paper's small-motion step).
    loss, huber_px, sigma_px : passed to ``refine`` (sigma_px: one σ, or one per click).
    max_triples : int
        How many triples (in click order: (0, 1, 2), (0, 1, 3), ...) to try at most. A triple is
        skipped when P3L rejects it (degenerate) or none of its candidates can be refined (e.g. no
        solution in front of the camera); when its candidates all refine to an RMS above
        ``fit_rms_px`` (local minima), the next triple's candidates are added to them.
    fit_rms_px : float, optional
        The RMS (pixels) under which a refined candidate fits the clicks; default 3 × the RMS of sigma_px.

    Returns
    -------
    PoseEstimate
        ``.T_world_obj`` the best refined pose, ``.result`` its RefineResult, ``.candidates`` all.

    Raises
    ------
    ValueError
        Bad input; fewer than 3 segments without ``T_prior``; no triple whose P3L candidates can be
        refined, and no prior (the message gives the reason for the first triple); the prior
        alone could not be refined.
    """
    check_options(camera, loss, huber_px, sigma_px)
    if not (isinstance(max_triples, (int, np.integer)) and max_triples >= 1):
        raise ValueError(f"max_triples must be an integer of at least 1, got {max_triples!r}")
    if fit_rms_px is not None:
        fit_rms_px = positive_scale(fit_rms_px, "fit_rms_px", " px")
    clicks = as_clicks(segs_uv, edges_obj, points_uv, points_obj)
    prior = None if T_prior is None else check_T(T_prior, "T_prior")
    if prior is not None:
        finite_array(prior[:3, 3], (3,), "T_prior's translation", max_abs=MAX_M, unit=" m")
    S = clicks.n_segments
    if S < 3 and prior is None:
        raise ValueError(
            f"got {S} clicked segment(s): the large-motion solver needs 3 edges; click more edges, "
            "or give the database pose (T_prior) to refine from"
        )
    triple = None
    skipped: list[tuple[tuple[int, int, int], str]] = []
    candidates: list[PoseCandidate] = []
    sigma = click_sigmas(sigma_px, clicks)  # one σ per residual row (checks a per-click array's length)
    refine_args = (
        loss,
        float(huber_px),
        float(sigma_px) if np.ndim(sigma_px) == 0 else np.asarray(sigma_px, float),
        100,
    )
    if S >= 3:
        fit_px = 3.0 * float(np.sqrt(np.mean(sigma**2))) if fit_rms_px is None else float(fit_rms_px)
        triple, skipped, candidates = _p3l_candidates(camera, clicks, refine_args, max_triples, fit_px)
        if triple is None and prior is None:
            raise ValueError(f"no triple of clicked edges gives a pose: {skipped[0][1]}")
    if prior is not None:
        candidates += _refined_all(camera, clicks, "prior", [prior], refine_args)
    if not any(c.refined is not None for c in candidates):
        reasons = "; ".join(sorted({c.error for c in candidates if c.error}))
        raise ValueError(f"no candidate pose could be refined: {reasons}")
    return PoseEstimate(_ranked(candidates, clicks), triple, tuple(skipped))


def _p3l_candidates(camera, clicks, refine_args, max_triples: int, fit_px: float):
    """P3L's starts (``p3l_triples``), each triple's refined with every click, until a triple's best
    candidate fits (RMS ≤ fit_px).

    Returns (the first triple whose candidates were refined, or None; the triples skipped and why;
    the refined candidates of every triple tried).
    """
    triple = None
    skipped: list[tuple[tuple[int, int, int], str]] = []
    candidates: list[PoseCandidate] = []
    for tri, sols, _, reason in p3l_triples(camera, clicks, max_triples):
        if not sols:
            skipped.append((tri, reason))
            continue
        found = _refined_all(camera, clicks, "p3l", sols, refine_args, tri)
        refined = [c.refined for c in found if c.refined is not None]
        if not refined:
            reason = "; ".join(sorted({c.error for c in found if c.error})) or "no solution in front of the camera"
            skipped.append((tri, reason))
            continue
        candidates += found
        triple = triple or tri
        if min(r.rms_px for r in refined) <= fit_px:
            break
        # Every candidate of this triple refined to a poor fit (a local minimum): add the next
        # triple's candidates too.
        skipped.append((tri, f"its candidates refine to RMS ≥ {min(r.rms_px for r in refined):.2f} px"))
    return triple, skipped, candidates


def _refined_all(camera, clicks, source: str, starts: list, refine_args, triple=None) -> list[PoseCandidate]:
    """Every start refined with every click (one compiled call), or with the reason it could not be;
    p3l_rank is the start's index (−1 for the prior)."""
    T0 = np.array(starts, dtype=float)
    try:
        results = refine_many(camera, T0, clicks, *refine_args)
    except ValueError as exc:  # too few clicks for any start
        results = [(str(exc), float("inf"))] * len(starts)
    out = []
    for k, (res, score) in enumerate(results):
        p3l_rank = -1 if source == "prior" else k
        if isinstance(res, str):
            out.append(PoseCandidate(source, starts[k], None, float("inf"), p3l_rank, res, triple))
        else:
            out.append(PoseCandidate(source, starts[k], res, score, p3l_rank, None, triple))
    return out


def _ranked(candidates: list[PoseCandidate], clicks) -> list[PoseCandidate]:
    """The pipeline's ranking of the refined candidates: by score (equal to 1e-6 px: a tie, the better
    P3L rank first, so a merged candidate keeps the start closest to it), those that refined to the
    pose of a better ranked one (1e-6 rad, 1e-6 of the clicked features' extent) merged into it."""
    extent = max(1e-3, float(np.abs(clicks.edges_obj).max()) if clicks.n_segments else 0.0)

    def same(T1: np.ndarray, T2: np.ndarray) -> bool:
        rot_deg, trans_m = pose_error(T1, T2)
        return np.radians(rot_deg) < 1e-6 and trans_m < 1e-6 * extent

    poses = [c.T_world_obj for c in candidates]
    scores = [round(c.score_px, 6) for c in candidates]
    tiebreak = [c.p3l_rank if c.p3l_rank >= 0 else np.inf for c in candidates]
    return [candidates[i] for i in rank(poses, scores, same, tiebreak=tiebreak)]
