"""Pose of a known object from clicked image edges and points (source paper §IV).

``p3l`` (large motion: the paper's geometric three-line solver on the global camera model C),
``refine`` (small motion: the paper's linearised least squares, iterated to the pixel maximum-
likelihood estimate, with covariance and per-click residuals), ``estimate_pose`` (both, as the
operator uses them), ``p3l_batch`` (P3L vectorised over many triples), ``p3l_candidates`` (P3L on
the clicks' triples, ranked by all the clicks), ``plausibility`` (can a fitted pose be the answer),
``edge_symmetries`` / ``nearest_twin`` (poses that draw the same picture, and the one nearest a
reference), ``refine_many`` (refinement from many starts in one call), ``refine_views`` (one pose
from clicks in several views, with a ``PosePrior`` if a pose is measured already), ``PoseClicks`` (the
operator's clicks per view and their assignment), ``warm_up`` (load the compiled kernels,
``core.pose._kernels``: call it in a background thread at start-up).

One pipeline (``core.pose.pipeline``): candidate poses from any source (P3L on edge triples, the one-click
search, automatic matching, a prior) → one ranking → one refinement over lines and points from any number
of views, with σ. Conventions: DESIGN.md §Frames; perturbations and covariances are (δt, δr) in the world
frame about the object's origin (``core.pose.residuals``).
"""

from ._lazy import warm_up
from .candidates import P3LCandidates, p3l_candidates
from .clicks import PoseClicks
from .estimate import PoseCandidate, PoseEstimate, estimate_pose
from .p3l import ConcurrentEdgesError, p3l, p3l_batch
from .pipeline import Estimates, Refined, Refused, Start, rank, refine_starts
from .plausibility import plausibility
from .refine import PosePrior, RefineResult, ViewClicks, refine, refine_many, refine_views, refine_with_prior
from .symmetry import edge_symmetries, nearest_twin, symmetry_transforms

__all__ = [
    "p3l",
    "p3l_batch",
    "p3l_candidates",
    "P3LCandidates",
    "refine",
    "refine_many",
    "refine_with_prior",
    "refine_views",
    "ViewClicks",
    "PosePrior",
    "PoseClicks",
    "Refused",
    "Estimates",
    "Start",
    "Refined",
    "rank",
    "refine_starts",
    "warm_up",
    "estimate_pose",
    "RefineResult",
    "PoseCandidate",
    "PoseEstimate",
    "ConcurrentEdgesError",
    "plausibility",
    "edge_symmetries",
    "symmetry_transforms",
    "nearest_twin",
]
