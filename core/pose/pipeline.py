"""The one pose pipeline: candidate poses from any source → one ranking → one refinement.

After PoseLib's estimator interface (generate models, score them, refine the best), written once for
every way mcit finds a known object's pose:

* **sources** give the poses to start from (``Start``): P3L on the clicked edges' triples
  (``candidates.p3l_triples``, ``p3l_candidates``); the one-click search's poses, each with its
  covariance, so that it is also a measurement (``Start.prior``, a ``PosePrior``); automatic matching's
  assignments (``app.vision.matching``, through ``refine_many``); the database pose, and the last refined
  one;
* **one ranking** (``rank``): by how far every click — each edge and point, not only the ones a source
  used — lies from the projected *finite* model at the pose (``residuals.pose_distance_cost``), poses
  that are one merged into the better ranked;
* **one refinement** (``refine.refine_views``, compiled): the clicks of any number of views, each with
  its σ, robust (Huber) weights if asked (``core.robust``'s, compiled), a prior if the start has one;
  the pose's covariance with it. ``refine_starts`` refines from the starts in turn and offers the first
  result that can be the answer (``plausibility``), saying why the others were not.

``Estimates`` holds an operator's session's candidates, chosen and refined poses. ``estimate_pose`` is
the single-view case (P3L starts and the prior, each refined, ranked);
``app.workflows.update_pose`` drives it step by step for the operator (Solve ranks P3L's starts, Refine
refines from the chosen one), ``app.vision.pnp`` refines a camera's pose with it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..brep import BRep
from ..camera import Camera
from ..transforms import pose_error
from .plausibility import plausibility
from .refine import PosePrior, RefineResult, ViewClicks, refine_views
from .uncertainty import MODEL_PRIOR_M, with_views_camera_uncertainty

__all__ = ["Refused", "Start", "Refined", "Estimates", "rank", "within", "refine_starts", "operator_starts"]


class Refused(ValueError):
    """An operator's click or choice a session cannot take (``PoseClicks``, ``Estimates``); the message says
    why and what to do instead."""


@dataclass(frozen=True)
class Start:
    """A pose to refine from. T_world_obj : (4, 4). label : what the operator calls it ("candidate 2",
    "the database pose"), in messages. index : its place in its source (a candidate's number), or None.
    prior : when the start is a measurement itself (a found pose with its σ), fitted together with the
    clicks (``PosePrior``); None: a start only."""

    T_world_obj: np.ndarray
    label: str
    index: int | None = None
    prior: PosePrior | None = None


@dataclass(frozen=True)
class Refined:
    """``refine_starts``' answer. result : the first plausible refinement, or None. start : the index
    (into the starts) it came from, or None. failures : (start label, why) of each start tried before it
    (or of all, when none is plausible)."""

    result: RefineResult | None
    start: int | None
    failures: tuple[tuple[str, str], ...]


def rank(
    poses: Sequence[np.ndarray],
    scores: Sequence[float],
    same: Callable[[np.ndarray, np.ndarray], bool],
    *,
    tiebreak: Sequence[float] | None = None,
    limit: int | None = None,
) -> list[int]:
    """The one ranking: indices of ``poses`` (each (4, 4)) best first by ``scores`` (lower is better:
    ``residuals.pose_distance_cost`` of every click, or ``refine_many``'s score, the same distance at the
    refined pose), ties broken by ``tiebreak``; a pose with a finite score for which ``same(pose, kept)``
    holds for a better kept one is merged into it (dropped). At most ``limit`` indices."""
    key = [(float(s), 0.0 if tiebreak is None else float(tiebreak[i])) for i, s in enumerate(scores)]
    kept: list[int] = []
    for i in sorted(range(len(poses)), key=key.__getitem__):
        if np.isfinite(key[i][0]) and any(np.isfinite(key[j][0]) and same(poses[i], poses[j]) for j in kept):
            continue
        kept.append(i)
        if limit is not None and len(kept) == limit:
            break
    return kept


def within(deg: float, m: float) -> Callable[[np.ndarray, np.ndarray], bool]:
    """``rank``'s ``same``: two poses within ``deg`` degrees and ``m`` metres of each other are one."""

    def same(T1: np.ndarray, T2: np.ndarray) -> bool:
        e_deg, e_m = pose_error(T1, T2)
        return e_deg <= deg and e_m <= m

    return same


def refine_starts(
    views: Sequence[ViewClicks],
    starts: Sequence[Start],
    *,
    model: BRep,
    camera: Camera,
    max_rms_px: float,
    loss: str = "l2",
    huber_px: float = 3.0,
    camera_covs: Sequence[np.ndarray | None] | None = None,
    model_sigma_m: float = MODEL_PRIOR_M,
) -> Refined:
    """Refine the clicks of every view (``refine_views``) from each start in turn (with its prior, if
    it has one) and return the first result that can be the answer: finite, its RMS at most
    ``max_rms_px`` (e.g. 3 σ), ``model`` in front of ``camera`` and in its image (``plausibility``).
    The starts it could not use say why (a refinement refused, diverged, or not plausible).

    camera_covs : optional, per view of ``views``, the covariance (12, 12) of its camera's C (or None; a camera
    file's prior: ``uncertainty.intrinsics_prior_cov``); model_sigma_m : σ of each model edge's position
    (metres, ``uncertainty.Priors``; with it, ``model``'s extents each to √2 of it). When the start is no prior,
    every camera's and the model's share join the result's σ (``uncertainty.with_views_camera_uncertainty``; a
    prior measured through C holds them already)."""
    failures: list[tuple[str, str]] = []
    for i, start in enumerate(starts):
        try:
            res = refine_views(views, start.T_world_obj, loss=loss, huber_px=huber_px, prior=start.prior)
        except ValueError as exc:
            failures.append((start.label, str(exc)))
            continue
        if not np.all(np.isfinite(res.T_world_obj)):
            failures.append((start.label, "the refinement diverged"))
            continue
        why = plausibility(camera, model, res.T_world_obj, res.rms_px, max_rms_px)
        if why:
            failures.append((start.label, why))
            continue
        if start.prior is None:
            covs = [None] * len(views) if camera_covs is None else camera_covs
            res = with_views_camera_uncertainty(
                res,
                views,
                covs,
                huber_px=huber_px,
                model_sigma_m=model_sigma_m,
                model_bounds_m=model.bounds(),
            )
        return Refined(res, i, tuple(failures))
    return Refined(None, None, tuple(failures))


def operator_starts(
    candidates: Sequence[np.ndarray],
    chosen: int | None,
    last_refined: np.ndarray | None,
    T_db: np.ndarray,
    measured: Start | None = None,
) -> list[Start]:
    """Where an operator's Refine starts, in order: a measured pose (a found one with its σ, ``Start.prior``)
    alone; else the last refined pose (clicks were added since; index −1), the chosen candidate, then the
    other candidates (index: theirs), or without a chosen one the database pose ``T_db`` (index None)."""
    if measured is not None:
        return [measured]
    order = [] if chosen is None else [chosen] + [i for i in range(len(candidates)) if i != chosen]
    starts = [Start(candidates[i], f"candidate {i + 1}", i) for i in order] or [Start(T_db, "from the database pose")]
    if last_refined is not None:
        starts.insert(0, Start(last_refined, "from the last refined pose", -1))
    return starts


class Estimates:
    """The poses an operator's pose update holds (pure data): the candidates a source offered, best first
    (P3L's, the one-click search's, automatic matching's), the one chosen, the refined pose (a
    ``RefineResult``) and, once the clicks changed since, the last refined pose. ``generation`` counts the
    changes: a computation made outside the session's lock commits only if it is unchanged. ``T_db``: the
    pose the session started from (the database's)."""

    def __init__(self, T_db: np.ndarray) -> None:
        self.T_db = np.asarray(T_db, dtype=float)
        self.candidates: list[np.ndarray] = []
        self.chosen: int | None = None
        self.refined: RefineResult | None = None
        self.last_refined: np.ndarray | None = None
        self.generation = 0

    @property
    def current(self) -> np.ndarray:
        """The pose in use: refined, else the last refined one, else the chosen candidate, else ``T_db``."""
        if self.refined is not None:
            return self.refined.T_world_obj
        if self.last_refined is not None:
            return self.last_refined
        return self.candidates[self.chosen] if self.chosen is not None else self.T_db

    def offer(self, candidates: list | None = None, chosen: int | None = None) -> None:
        """New candidates (``[]``: none; None: the same) with the best chosen, or candidate ``chosen``: the
        refined poses go."""
        if candidates is not None:
            self.candidates, self.chosen = list(candidates), (0 if len(candidates) else None)
        self.chosen = self.chosen if chosen is None else int(chosen)
        self.refined = self.last_refined = None
        self.generation += 1

    def choose(self, index: int) -> None:
        """Candidate ``index`` (0 = best) is the estimate; Refused when there is no such candidate."""
        if not self.candidates:
            raise Refused("no candidates: Solve first")
        if not 0 <= index < len(self.candidates):
            raise Refused(f"there are candidates 1..{len(self.candidates)}, not {index + 1}")
        self.offer(chosen=index)

    def clicks_changed(self) -> None:
        """The clicks changed: the refined pose goes, kept as the last refined one (the estimate new
        clicks are assigned on, and the next refinement's start)."""
        if self.refined is not None:
            self.last_refined = self.refined.T_world_obj.copy()
        self.refined = None
        self.generation += 1

    def starts(self, measured: Start | None = None) -> list[Start]:
        """Where the next refinement starts (``operator_starts``)."""
        return operator_starts(self.candidates, self.chosen, self.last_refined, self.T_db, measured)

    def adopt(self, result: RefineResult, start: Start) -> None:
        """The refinement from ``start`` is the pose in use (and its candidate the chosen one)."""
        self.refined = result
        if start.index is not None and start.index >= 0:
            self.chosen = start.index
