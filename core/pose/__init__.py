"""Pose of a known object from clicked image edges and points (source paper §IV).

``p3l`` (large motion: the paper's geometric three-line solver on the global camera model C),
``refine`` (small motion: the paper's linearised least squares, iterated to the pixel
maximum-likelihood estimate, with covariance and per-click residuals), ``estimate_pose`` (both, as
the operator uses them), ``p3l_batch`` (P3L vectorised over many triples). Conventions: DESIGN.md §Frames; perturbations and covariances are
(δt, δr) in the world frame about the object's origin (``core.pose.residuals``).
"""

from .estimate import PoseCandidate, PoseEstimate, estimate_pose
from .p3l import ConcurrentEdgesError, p3l, p3l_batch
from .refine import RefineResult, refine

__all__ = [
    "p3l",
    "p3l_batch",
    "refine",
    "estimate_pose",
    "RefineResult",
    "PoseCandidate",
    "PoseEstimate",
    "ConcurrentEdgesError",
]
