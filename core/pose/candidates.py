"""Candidate poses from clicked edges: P3L on the triples of the clicks (the pipeline's P3L source,
``core.pose.pipeline``), one ranking.

``p3l_triples`` yields each triple's solutions, or why it has none. ``p3l_candidates`` runs the
three-line solver (``core.pose.p3l``) on the triples of clicked edges in click order (at most
``max_triples``) and ranks every solution by how far all the clicks — every edge and point, not only
the triple's — lie from the projected finite model (``residuals.pose_distance_cost``, the pipeline's
``rank``), near-duplicates merged (the better ranked kept). With ``first_only`` it stops at the first
triple that gives a solution and keeps that triple's solutions in P3L's own order (the paper's
large-motion step, as the demo reports it). The triples that gave nothing are returned with the
reason, for the operator.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from .p3l import ConcurrentEdgesError, p3l
from .pipeline import rank, within
from .residuals import Clicks, as_clicks, pose_distance_cost

__all__ = ["P3LCandidates", "p3l_candidates", "p3l_triples"]


@dataclass(frozen=True)
class P3LCandidates:
    """poses : list of (4, 4), best first. triples : the triples (indices into the clicked segments)
    that gave solutions. skipped : (triple, kind, reason) of those that did not: kind "concurrent"
    (the three edges meet at one corner), "none" (no solution in front of the camera) or "degenerate"."""

    poses: list[np.ndarray]
    triples: list[tuple[int, int, int]]
    skipped: list[tuple[tuple[int, int, int], str, str]]


def p3l_triples(camera: Camera, clicks: Clicks, max_triples: int):
    """P3L's source of starting poses: for each triple of clicked edges in click order ((0, 1, 2),
    (0, 1, 3), ..., at most ``max_triples``), yields (triple, poses, kind, reason): its solutions (each
    (4, 4), P3L's order), or none and why — kind "concurrent" (the three edges meet at one corner),
    "degenerate" (P3L refused the triple) or "none" (no pose in front of the camera)."""
    pts = (clicks.points_uv, clicks.points_obj) if clicks.n_points else (None, None)
    for tri in itertools.islice(itertools.combinations(range(clicks.n_segments), 3), max_triples):
        idx = list(tri)
        try:
            sols = p3l(camera, clicks.segs_uv[idx], clicks.edges_obj[idx], *pts)
        except ConcurrentEdgesError as exc:
            yield tri, [], "concurrent", str(exc)
            continue
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:  # a degenerate triple: the next one
            yield tri, [], "degenerate", str(exc)
            continue
        if not sols:
            yield tri, [], "none", "no pose puts the object in front of the camera"
            continue
        yield tri, [np.asarray(T, float) for T in sols], "", ""


def p3l_candidates(
    camera: Camera,
    segs_uv: np.ndarray,
    edges_obj: np.ndarray,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
    *,
    max_triples: int = 20,
    max_candidates: int = 8,
    merge: tuple[float, float] = (0.5, 0.005),
    first_only: bool = False,
) -> P3LCandidates:
    """Every pose P3L finds on the clicks' triples, ranked by all the clicks (module docstring).

    segs_uv (S, 2, 2), edges_obj (S, 2, 3), points (P, 2) / (P, 3) as ``core.pose.refine`` takes them;
    merge : (degrees, metres) under which two poses are one. ValueError for bad clicks."""
    clicks = as_clicks(segs_uv, edges_obj, points_uv, points_obj)
    found: list[np.ndarray] = []
    triples: list[tuple[int, int, int]] = []
    skipped: list[tuple[tuple[int, int, int], str, str]] = []
    for tri, sols, kind, reason in p3l_triples(camera, clicks, max_triples):
        if not sols:
            skipped.append((tri, kind, reason))
            continue
        triples.append(tri)
        found += sols
        if first_only:
            return P3LCandidates(found, triples, skipped)
    cost = [pose_distance_cost(camera, T, clicks) for T in found]
    order = rank(found, cost, within(*merge), limit=max_candidates)
    return P3LCandidates([found[i] for i in order], triples if found else [], skipped)
