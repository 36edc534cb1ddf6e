"""Poses scored on a frame's edges, many at once: the one-click search's scoring (``search.search_pose``),
shared with the tracker's first-frame capture (``track.EdgeTracker``), which cannot import the search (it
settles its poses with the tracker).

``EdgeField``: a frame's Canny edges as capped distance transforms, one per orientation bin.
``_ModelSamples``: a model's edge samples, posed in batches. ``_score``: each pose's mean capped oriented
distance of its visible samples to the image's edges. ``_distinct`` and ``_descend``: the best distinct
poses of a grid, and their batched coordinate descent.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from core.brep import BRep
from core.camera import Camera

from .profiles import to_gray_f32

N_BINS = 8  # orientation bins of the distance transforms (22.5° each; an edge pixel joins its two nearest bins)


class EdgeField:
    """A frame's Canny edges as capped distance transforms, one per orientation bin (computed once).

    ``lookup(uv, normal_angle_rad, tau)`` reads, for image points (…, 2) with their edge normals'
    angles, the distance (pixels) to the nearest edge pixel whose gradient is within 22.5° of the
    normal (either sign), capped at tau; points outside the image read tau.
    """

    def __init__(self, image: np.ndarray, *, sigma_px: float = 1.0, canny_low: float = 10.0, canny_high: float = 30.0):
        gray = to_gray_f32(image)
        blur = cv2.GaussianBlur(gray, (0, 0), sigma_px) if sigma_px > 0 else gray
        g8 = np.clip(np.round(blur), 0, 255).astype(np.uint8)
        edges = cv2.Canny(g8, canny_low, canny_high, L2gradient=True)
        gx = cv2.Sobel(blur, cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(blur, cv2.CV_32F, 0, 1, ksize=3)
        ys, xs = np.nonzero(edges)
        theta = np.arctan2(gy[ys, xs], gx[ys, xs]) % np.pi  # gradient = edge normal, modulo π
        pos = theta / (np.pi / N_BINS)
        lo = np.floor(pos).astype(int) % N_BINS
        hi = (lo + 1) % N_BINS
        H, W = gray.shape
        self.shape = (H, W)
        self.n_edges = len(xs)
        dist = np.empty((N_BINS, H, W), np.float32)
        for b in range(N_BINS):
            sel = (lo == b) | (hi == b)
            src = np.full((H, W), 255, np.uint8)
            src[ys[sel], xs[sel]] = 0
            dist[b] = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_5) if sel.any() else np.float32(1e4)
        self.dist = dist.reshape(-1)

    def lookup(self, uv: np.ndarray, normal_angle: np.ndarray, tau: float, bilinear: bool = False) -> np.ndarray:
        return self.lookup_uv(uv[..., 0], uv[..., 1], normal_angle, tau, bilinear)

    def lookup_uv(self, u: np.ndarray, v: np.ndarray, normal_angle: np.ndarray, tau: float, bilinear: bool = False):
        """``lookup`` with the points' u and v apart (each the shape of ``normal_angle``)."""
        H, W = self.shape
        # the bin of the angle modulo π (a multiple of π is a multiple of N_BINS bins); a NaN or infinite u or v
        # fails the comparisons below, so reads tau
        b = np.rint(normal_angle * (N_BINS / np.pi)).astype(np.int32) % N_BINS  # int32: the index is < 2³¹
        if bilinear:
            inside = (u >= 0) & (u < W - 1) & (v >= 0) & (v < H - 1)
            u = np.where(inside, u, 0.0)
            v = np.where(inside, v, 0.0)
            x0, y0 = np.floor(u).astype(np.int32), np.floor(v).astype(np.int32)
            fx, fy = u - x0, v - y0
            i = (b * H + y0) * W + x0
            dd = self.dist
            top = dd[i] + fx * (dd[i + 1] - dd[i])
            bot = dd[i + W] + fx * (dd[i + W + 1] - dd[i + W])
            d = top + fy * (bot - top)
            return np.where(inside, np.minimum(d, tau), tau)
        u = np.rint(u)
        v = np.rint(v)
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        ui = np.where(inside, u, 0).astype(np.int32)
        vi = np.where(inside, v, 0).astype(np.int32)
        d = self.dist[(b * H + vi) * W + ui]
        return np.where(inside, np.minimum(d, tau), tau)


class _ModelSamples:
    """The model as points to score: each primitive's edge samples (``Primitive.edge_samples``:
    polyhedral edges, rims, silhouette generators), all poses of a batch at once.

    A polyhedral part of more than ``max_edges`` edges is scored on ``max_edges`` of them, spread over
    the part and favouring the long ones (``_edge_subset``): the scores only rank poses for the
    refinement, which uses every edge, and their cost grows with the samples (bench/search.py (e): a
    rack of 384 edges took 2.3-2.9 s a click, 0.2 s at 12 edges)."""

    def __init__(self, model: BRep, per_edge: int, n_rim: int = 24, max_edges: int | None = None):
        self.model = model
        self.per_edge = per_edge
        self.n_rim = n_rim
        self.parts = [_edge_subset(p, max_edges) for p in model.parts] if max_edges else list(model.parts)

    def groups(self, R: np.ndarray, t: np.ndarray, center: np.ndarray):
        """Per group of samples: object-frame points X ((M, 3) shared, or (N, M, 3)), tangents D
        (same shape) and visibility (N, M) at poses (R, t)."""
        c_obj = np.einsum("nji,nj->ni", R, center[None] - t)  # optical centre in each object frame
        return [g for p in self.parts for g in p.edge_samples(c_obj, self.per_edge, self.n_rim)]


def _edge_subset(part, max_edges: int):
    """``part`` itself, or for a polyhedron of more than ``max_edges`` edges the same polyhedron with
    ``max_edges`` of its edges: taken at even steps along the edges' cumulated lengths (in the model's
    order, so spread over it; a long edge is taken before a short one)."""
    from core.primitives.polyhedron import Polyhedron

    if not isinstance(part, Polyhedron) or len(part.edges) <= max_edges:
        return part
    V, E = part.vertices, part.edges
    length = np.linalg.norm(V[E[:, 1]] - V[E[:, 0]], axis=1)
    cum = np.cumsum(length)
    at = (np.arange(max_edges) + 0.5) * cum[-1] / max_edges
    keep = np.unique(np.searchsorted(cum, at))
    return Polyhedron(V, E[keep], part.faces)


def _score(
    field_: EdgeField,
    camera: Camera,
    ms: _ModelSamples,
    R: np.ndarray,
    t: np.ndarray,
    tau: float,
    chunk: int = 4096,
    bilinear: bool = False,
) -> np.ndarray:
    """Mean capped oriented distance (pixels) of each pose's visible samples; inf with fewer than 8."""
    out = np.empty(len(R))
    C = camera.C
    for a in range(0, len(R), chunk):
        Rb, tb = R[a : a + chunk], t[a : a + chunk]
        P = (C[:, :3][None] @ Rb).astype(np.float32)  # (N, 3, 3): C·R
        q = (tb @ C[:, :3].T + C[:, 3]).astype(np.float32)  # (N, 3)
        total = np.zeros(len(Rb))
        count = np.zeros(len(Rb))
        for X, D, V in ms.groups(Rb, tb, camera.center):
            h, hd = _rows(P, X) + q[:, :, None], _rows(P, D)  # (N, 3, M): C·R·X + q, and C·R·D
            z = h[:, 2]
            front = z > 1e-6
            zs = np.where(front, z, 1.0)
            u, v = h[:, 0] / zs, h[:, 1] / zs
            # the edge's normal: the tangent's image direction (times z), turned a quarter
            ang = np.arctan2(hd[:, 1] - v * hd[:, 2], hd[:, 0] - u * hd[:, 2]) + 0.5 * np.pi
            d = field_.lookup_uv(u, v, ang, tau, bilinear)
            V = V & front
            total += (d * V).sum(axis=1)
            count += V.sum(axis=1)
        out[a : a + chunk] = np.where(count >= 8, total / np.maximum(count, 1), np.inf)
    return out


def _rows(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(N, 3, M) float32: P[n] · X[m] for matrices P (N, 3, 3) and points X (M, 3) shared by the N poses (one
    matrix product; each row a contiguous (N, M) array) or (N, M, 3) one set per pose."""
    X = X.astype(np.float32)
    if X.ndim == 2:
        return (P.reshape(-1, 3) @ X.T).reshape(len(P), 3, len(X))
    return np.matmul(P, np.transpose(X, (0, 2, 1)))


def _distinct(
    p: np.ndarray, score: np.ndarray, scale: np.ndarray, k: int, period: np.ndarray | None = None
) -> np.ndarray:
    """Indices of up to k best-scoring parameter vectors at least one step (``scale``) apart."""
    order = np.argsort(score, kind="stable")
    order = order[np.isfinite(score[order])]
    kept: list[int] = []
    for i in order:
        if kept:
            d = (p[kept] - p[i]) / scale
            if period is not None:
                per = period / scale
                d = np.where(per > 0, (d + per / 2) % np.where(per > 0, per, 1) - per / 2, d)
            if np.min(np.max(np.abs(d), axis=1)) < 1.0:
                continue
        kept.append(int(i))
        if len(kept) == k:
            break
    return np.array(kept, dtype=int)


def _descend(evaluate: Callable, p: np.ndarray, step: np.ndarray, taus, iters_per_level: int = 3):
    """Batched coordinate descent: each level tries ±step along each parameter from every seed,
    moves to the best; then the step halves. Returns (p, scores at the last τ).

    A seed that did not move would try the same steps again: it is not scored again within its level (the
    same result), nor is a level's start when its τ is the last one's (bench/search.py (e): 4-14 % fewer
    poses scored in a search, the coarse grid's included)."""
    k = p.shape[1]
    p = p.copy()
    best, last_tau = None, None
    for tau in taus:
        if best is None or tau != last_tau:
            best = np.array(evaluate(p, tau), float)
        last_tau = tau
        moving = np.arange(len(p))
        for _ in range(iters_per_level):
            if not len(moving):
                break
            trial = np.concatenate(
                [p[moving, None] + sgn * np.diag(step)[None] for sgn in (1.0, -1.0)], axis=1
            )  # (S, 2k, k)
            sc = evaluate(trial.reshape(-1, k), tau).reshape(len(moving), 2 * k)
            rows = np.arange(len(moving))
            j = np.argmin(sc, axis=1)
            better = sc[rows, j] < best[moving]
            p[moving[better]] = trial[rows, j][better]
            best[moving[better]] = sc[rows, j][better]
            moving = moving[better]
        step = step / 2.0
    return p, best
