"""Pixel residuals of the operator's clicks against a posed model, and their Jacobians.

The one residual model shared by the pose solvers (ranking of P3L candidates, refinement, the
Cramér–Rao bound in ``bench/pose.py``):

* a clicked **segment** (two pixels the operator put on an image edge) matched to a model edge
  (two 3D endpoints in the object frame) gives two residuals: the signed distances, in pixels, of
  the two clicked pixels to the infinite image line of the projected model edge. The operator
  clicks two points *on* an edge, not its endpoints, so only the distance across the line is
  measured; under isotropic pixel noise this is the maximum-likelihood cost.
* a clicked **point** matched to a model point gives the 2D reprojection error (u, v), pixels.

The projected model line is ``l = (C Ã) × (C B̃)`` (homogeneous pixels of the posed endpoints A, B
in the world), scaled so that ``l·(u, v, 1)`` is a signed pixel distance: positive to the right of
π(A) → π(B) on the screen (u right, v down) when both endpoints are in front of the camera, the
convention of ``Camera.image_line``. Everything is written on C, never on K, R, t.

Pose perturbation (the convention of every Jacobian and covariance in ``core.pose``): a 6-vector
``δ = (δt, δr)``, δt a translation of the object's origin in the world frame (metres), δr a rotation
vector in world axes about the object's origin (radians)::

    R ← exp([δr]×) R,    t ← t + δt,    so a posed point X' = R X + t moves by  δt + δr × (X' − t).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..camera import Camera
from ..checks import MAX_M, MAX_PX, finite_array
from ._lazy import frozen, kernels

_k = kernels()  # core.pose._kernels, imported on first use (numba is not loaded before mcit serve's first page)

__all__ = [
    "Clicks",
    "as_clicks",
    "stack_views",
    "view_matrices",
    "interpretation_planes",
    "residuals",
    "perturb",
    "distance_cost",
    "pose_distance_cost",
]


@dataclass(frozen=True)
class Clicks:
    """The operator's clicks and the model features they are matched to.

    segs_uv : array, shape (S, 2, 2), pixels: two clicked points on each image edge.
    edges_obj : array, shape (S, 2, 3), metres, object frame: the matched model edges' endpoints.
    points_uv : array, shape (P, 2), pixels: clicked points (e.g. vertices).
    points_obj : array, shape (P, 3), metres, object frame: the matched model points.
    """

    segs_uv: np.ndarray
    edges_obj: np.ndarray
    points_uv: np.ndarray
    points_obj: np.ndarray
    seg_view: np.ndarray | None = None  # (S,) int64: the view each segment was clicked in (None: one view)
    pt_view: np.ndarray | None = None  # (P,) int64: the view of each point
    view_count: int = 1

    @property
    def n_views(self) -> int:
        """The views the clicks were made in (``stack_views``); 1 unless stacked."""
        return self.view_count

    @property
    def view_index(self) -> tuple[np.ndarray, np.ndarray]:
        """(seg_view (S,), pt_view (P,)), int64: the view of each clicked segment and point."""
        if self.seg_view is None:  # one view: the shared zeros (the kernels only read them)
            S, P = len(self.segs_uv), len(self.points_uv)
            zeros = _ZEROS if max(S, P) <= len(_ZEROS) else np.zeros(max(S, P), np.int64)
            return zeros[:S], zeros[:P]
        return self.seg_view, self.pt_view

    @property
    def views(self) -> tuple[int, ...]:
        """The view of each click, as ``kinds`` orders them (segments first)."""
        if self.seg_view is None:
            return (0,) * (len(self.segs_uv) + len(self.points_uv))
        return tuple(self.seg_view.tolist()) + tuple(self.pt_view.tolist())

    @cached_property
    def segs_h(self) -> np.ndarray:
        """Homogeneous clicked pixels (u, v, 1), shape (S, 2, 3)."""
        return np.concatenate([self.segs_uv, np.ones(self.segs_uv.shape[:2] + (1,))], axis=-1)

    @property
    def n_segments(self) -> int:
        return len(self.segs_uv)

    @property
    def n_points(self) -> int:
        return len(self.points_uv)

    @property
    def n_residuals(self) -> int:
        """2 per segment (one per clicked pixel) + 2 per point (u, v)."""
        return 2 * (len(self.segs_uv) + len(self.points_uv))

    @property
    def kinds(self) -> tuple[str, ...]:
        """One entry per click, segments first: "segment" or "point"."""
        return ("segment",) * len(self.segs_uv) + ("point",) * len(self.points_uv)


_ZEROS = np.zeros(256, np.int64)  # Clicks.view_index of one view
_NO_SEGS, _NO_EDGES, _NO_UV, _NO_X = (np.zeros(shape) for shape in ((0, 2, 2), (0, 2, 3), (0, 2), (0, 3)))
for _a in (_NO_SEGS, _NO_EDGES, _NO_UV, _NO_X):
    _a.setflags(write=False)


def as_clicks(segs_uv=None, edges_obj=None, points_uv=None, points_obj=None) -> Clicks:
    """Validate clicks and matched model features; ValueError saying what is wrong.

    Accepts a single segment (2, 2) / edge (2, 3) or a point (2,) / (3,) as a batch of one.
    """
    if segs_uv is not None and edges_obj is not None:  # the common case, checked in one compiled call
        segs, edges = np.asarray(segs_uv, dtype=float), np.asarray(edges_obj, dtype=float)
        puv = _NO_UV if points_uv is None else np.asarray(points_uv, dtype=float)
        pobj = _NO_X if points_obj is None else np.asarray(points_obj, dtype=float)
        if (
            (points_uv is None) == (points_obj is None)
            and segs.ndim == 3
            and segs.shape[1:] == (2, 2)
            and edges.ndim == 3
            and edges.shape[1:] == (2, 3)
            and len(segs) == len(edges)
            and puv.ndim == 2
            and puv.shape[1] == 2
            and pobj.ndim == 2
            and pobj.shape[1] == 3
            and len(puv) == len(pobj)
            and _k.clicks_ok(frozen(segs), frozen(edges), frozen(puv), frozen(pobj), MAX_PX, MAX_M)
        ):
            return Clicks(segs, edges, puv, pobj)
    if (segs_uv is None) != (edges_obj is None):
        raise ValueError("segs_uv and edges_obj go together: give both (one model edge per clicked segment) or neither")
    if (points_uv is None) != (points_obj is None):
        raise ValueError(
            "points_uv and points_obj go together: give both (one model point per clicked point) or neither"
        )
    if segs_uv is None:
        segs, edges = _NO_SEGS, _NO_EDGES
    else:
        segs = np.asarray(segs_uv, dtype=float)
        edges = np.asarray(edges_obj, dtype=float)
        if segs.shape == (2, 2):
            segs = segs[None]
        if edges.shape == (2, 3):
            edges = edges[None]
        if segs.ndim != 3 or segs.shape[1:] != (2, 2):
            raise ValueError(f"segs_uv must have shape (N, 2, 2) (two clicked pixels per edge), got {segs.shape}")
        if edges.ndim != 3 or edges.shape[1:] != (2, 3):
            raise ValueError(f"edges_obj must have shape (N, 2, 3) (two 3D endpoints per edge), got {edges.shape}")
        if len(segs) != len(edges):
            raise ValueError(
                f"got {len(segs)} clicked segments but {len(edges)} model edges: match each segment to one edge"
            )
        if not (np.abs(segs).max(initial=0.0) <= MAX_PX and np.abs(edges).max(initial=0.0) <= MAX_M):
            finite_array(segs, (None, 2, 2), "segs_uv", max_abs=MAX_PX, unit=" px")
            finite_array(edges, (None, 2, 3), "edges_obj", max_abs=MAX_M, unit=" m")
        d = segs[:, 1] - segs[:, 0]
        short = (d * d).sum(axis=1) < (1e-9 * max(1.0, float(np.abs(segs).max()))) ** 2
        if short.any():
            raise ValueError(
                f"clicked segment(s) {np.flatnonzero(short).tolist()} have two coinciding pixels and "
                "define no line; click two distinct points along each edge"
            )
        d = edges[:, 1] - edges[:, 0]
        short = (d * d).sum(axis=1) < (1e-12 * max(1.0, float(np.abs(edges).max()))) ** 2
        if short.any():
            raise ValueError(
                f"model edge(s) {np.flatnonzero(short).tolist()} have coinciding endpoints: an edge "
                "needs two distinct 3D points"
            )
    if points_uv is None:
        puv, pobj = _NO_UV, _NO_X
    else:
        puv = np.asarray(points_uv, dtype=float)
        pobj = np.asarray(points_obj, dtype=float)
        if puv.shape == (2,):
            puv = puv[None]
        if pobj.shape == (3,):
            pobj = pobj[None]
        if puv.ndim != 2 or puv.shape[1] != 2:
            raise ValueError(f"points_uv must have shape (N, 2), got {puv.shape}")
        if pobj.ndim != 2 or pobj.shape[1] != 3:
            raise ValueError(f"points_obj must have shape (N, 3), got {pobj.shape}")
        if len(puv) != len(pobj):
            raise ValueError(
                f"got {len(puv)} clicked points but {len(pobj)} model points: match each click to one point"
            )
        if not (np.abs(puv).max(initial=0.0) <= MAX_PX and np.abs(pobj).max(initial=0.0) <= MAX_M):
            finite_array(puv, (None, 2), "points_uv", max_abs=MAX_PX, unit=" px")
            finite_array(pobj, (None, 3), "points_obj", max_abs=MAX_M, unit=" m")
    return Clicks(segs, edges, puv, pobj)


def stack_views(
    per_view: Sequence[Clicks], order: Sequence[tuple[Sequence[int], Sequence[int]]] | None = None
) -> Clicks:
    """One Clicks of the clicks made in several views (each validated by ``as_clicks``), each click
    keeping the view it came from.

    order : per view, (the positions of its segments, the positions of its points) among all the
    views' segments and among all their points: the caller's click order, whatever the view each click
    was made in. Default: every view's segments, in view order, then every view's points. ValueError
    when the positions are not each click's exactly once."""
    if not per_view:
        raise ValueError("no view's clicks: give the clicks of at least one view")
    if order is None:
        seg_at = np.arange(sum(c.n_segments for c in per_view))
        pt_at = np.arange(sum(c.n_points for c in per_view))
    else:
        if len(order) != len(per_view):
            raise ValueError(f"order gives the positions of {len(order)} view(s)' clicks for {len(per_view)} view(s)")
        seg_at = np.concatenate([np.asarray(o[0], np.int64).reshape(-1) for o in order])
        pt_at = np.concatenate([np.asarray(o[1], np.int64).reshape(-1) for o in order])
    views = np.arange(len(per_view))
    seg_view = np.repeat(views, [c.n_segments for c in per_view])
    pt_view = np.repeat(views, [c.n_points for c in per_view])
    S, P = len(seg_view), len(pt_view)
    if not (np.array_equal(np.sort(seg_at), np.arange(S)) and np.array_equal(np.sort(pt_at), np.arange(P))):
        raise ValueError(
            f"order must place each of the {S} segment(s) and {P} point(s) exactly once (positions 0..{S - 1} "
            f"and 0..{P - 1})"
        )
    segs, edges = np.empty((S, 2, 2)), np.empty((S, 2, 3))
    puv, pobj = np.empty((P, 2)), np.empty((P, 3))
    seg_out, pt_out = np.empty(S, np.int64), np.empty(P, np.int64)
    segs[seg_at] = np.concatenate([c.segs_uv for c in per_view])
    edges[seg_at] = np.concatenate([c.edges_obj for c in per_view])
    puv[pt_at] = np.concatenate([c.points_uv for c in per_view])
    pobj[pt_at] = np.concatenate([c.points_obj for c in per_view])
    seg_out[seg_at], pt_out[pt_at] = seg_view, pt_view
    return Clicks(segs, edges, puv, pobj, seg_out, pt_out, len(per_view))


def view_matrices(cameras: Camera | Sequence[Camera], clicks: Clicks) -> np.ndarray:
    """The views' matrices C, (V, 3, 4), read-only as ``Camera.C`` is (the kernels are compiled for that
    type), one camera per view of the clicks; ValueError otherwise."""
    if isinstance(cameras, Camera) and clicks.seg_view is None:
        return cameras.C[None]
    cams = [cameras] if isinstance(cameras, Camera) else list(cameras)
    if not all(isinstance(c, Camera) for c in cams):
        raise ValueError("each view needs a core.camera.Camera")
    if len(cams) != clicks.n_views:
        raise ValueError(f"{len(cams)} camera(s) for clicks in {clicks.n_views} view(s): give one camera per view")
    Cs = np.ascontiguousarray(np.stack([c.C for c in cams]), dtype=float)
    Cs.setflags(write=False)
    return Cs


def interpretation_planes(camera: Camera, segs_uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interpretation planes ``Cᵀ l`` of clicked segments, vectorised ``Camera.interpretation_plane``.

    segs_uv : array, shape (N, 2, 2), pixels (validated by the caller).
    Returns n : array, shape (N, 3), unit normals (world), and d : array, shape (N,), metres,
    with ``n·X + d = 0`` for every world point X whose image lies on the segment's line, oriented
    as ``Camera.interpretation_plane``.
    """
    u1, v1, u2, v2 = segs_uv.reshape(-1, 4).T
    l = np.stack([v1 - v2, u2 - u1, u1 * v2 - u2 * v1], axis=1)  # (u1, v1, 1) × (u2, v2, 1)
    pi = l @ camera.C
    pi /= np.sqrt(np.sum(pi[:, :3] * pi[:, :3], axis=1))[:, None]
    return pi[:, :3], pi[:, 3]


def perturb(T_world_obj: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Apply a perturbation δ = (δt (m), δr (rad)) in the module's convention: ``R ← exp([δr]×) R``,
    ``t ← t + δt``. T_world_obj (4, 4), delta (6,) → (4, 4)."""
    T = np.array(T_world_obj, dtype=float)
    T[:3, :3] = _exp_so3(delta[3:]) @ T[:3, :3]
    T[:3, 3] += delta[:3]
    return T


def _exp_so3(r: np.ndarray) -> np.ndarray:
    """Rodrigues' formula in plain Python (``core.transforms.exp_so3`` costs ~4× more per call,
    and refinement calls it once per step)."""
    x, y, z = r.tolist()
    th2 = x * x + y * y + z * z
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = th2**0.5
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    xx, yy, zz, xy, xz, yz = x * x, y * y, z * z, x * y, x * z, y * z
    return np.array(
        [
            [1.0 - b * (yy + zz), b * xy - a * z, b * xz + a * y],
            [b * xy + a * z, 1.0 - b * (xx + zz), b * yz - a * x],
            [b * xz - a * y, b * yz + a * x, 1.0 - b * (xx + yy)],
        ]
    )


_I1, _I2 = np.array([1, 2, 0]), np.array([2, 0, 1])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis, broadcasting (np.cross is several times slower on small arrays)."""
    return a.take(_I1, -1) * b.take(_I2, -1) - a.take(_I2, -1) * b.take(_I1, -1)


def residuals(
    camera: Camera,
    R_world_obj: np.ndarray,
    t_world_obj: np.ndarray,
    clicks: Clicks,
    jacobian: bool = False,
) -> tuple[np.ndarray, np.ndarray | None, bool]:
    """Pixel residuals of the clicks at one pose, and optionally their Jacobian.

    Parameters
    ----------
    camera : Camera
    R_world_obj : array, shape (3, 3)
    t_world_obj : array, shape (3,), metres
    clicks : Clicks
    jacobian : bool
        Also return d(residuals)/dδ in the module's perturbation convention.

    Returns
    -------
    r : array, shape (m,), pixels. Order: for each segment the signed distances of its two
        clicked pixels to the projected model line, then for each point (u, v) projected minus
        clicked. m = 2 S + 2 P.
    J : array, shape (m, 6), pixels per (m, rad), or None.
    feasible : bool: every clicked model edge has an endpoint in front of the camera (depth > 0)
        and projects to a line (it does not pass through the optical centre), every clicked model
        point is in front. Residuals of infeasible features are NaN.
    """
    C = camera.C
    M = C[:, :3]
    MR = M @ R_world_obj
    b = M @ t_world_obj + C[:, 3]
    S, P = clicks.n_segments, clicks.n_points
    r = np.empty(2 * (S + P))
    J = np.empty((2 * (S + P), 6)) if jacobian else None
    feasible = True
    if S:
        h = clicks.edges_obj @ MR.T + b  # (S, 2, 3): homogeneous pixels C X̃ of the posed endpoints
        hA, hB = h[:, 0], h[:, 1]
        l = _cross(hA, hB)  # (S, 3) projected model line
        g = np.hypot(l[:, 0], l[:, 1])
        if not (np.maximum(hA[:, 2], hB[:, 2]).min() > 0 and g.min() > 1e-12 * np.abs(l).max()):
            ok = (g > 1e-12 * np.abs(l).max(axis=1)) & ((hA[:, 2] > 0) | (hB[:, 2] > 0))
            feasible = False
            g = np.where(ok, g, np.nan)
        q = clicks.segs_h  # (S, 2, 3) homogeneous clicked pixels
        lhat = l / g[:, None]
        r_seg = (lhat[:, None, :] * q).sum(axis=-1)  # (S, 2) signed distances, pixels
        r[: 2 * S] = r_seg.reshape(-1)
        if jacobian:
            # r = (hA × hB)·q / g with g = |l_xy|: dr/dhA = hB × p, dr/dhB = p × hA = −hA × p, where
            # p = (q − r l̂_xy) / g; dh/dδ = [M, −M [X − t]×] for the posed endpoints X = A, B, so
            # dr/dδt = Σ_X a_X and dr/dδr = Σ_X (X − t) × a_X with a_X = Mᵀ dr/dhX.
            lxy = lhat.copy()
            lxy[:, 2] = 0.0
            p = (q - r_seg[..., None] * lxy[:, None, :]) / g[:, None, None]  # (S, 2 clicks, 3)
            h_swap = np.stack([hB, -hA], axis=1)  # (S, 2 endpoints, 3)
            a = _cross(h_swap[:, None], p[:, :, None]) @ M  # (S, 2 clicks, 2 endpoints, 3)
            X = clicks.edges_obj @ R_world_obj.T  # posed endpoints relative to the object's origin
            J_seg = J[: 2 * S]
            J_seg[:, :3] = a.sum(axis=2).reshape(-1, 3)
            J_seg[:, 3:] = _cross(X[:, None], a).sum(axis=2).reshape(-1, 3)
    if P:
        h = clicks.points_obj @ MR.T + b  # (P, 3)
        s = h[:, 2]
        if not (s > 0).all():
            feasible = False
            s = np.where(s > 0, s, np.nan)
        uv = h[:, :2] / s[:, None]
        r[2 * S :] = (uv - clicks.points_uv).reshape(-1)
        if jacobian:
            # d(u, v)/dh = [[1, 0, −u], [0, 1, −v]] / s; dh/dδ = [M, −M [X − t]×].
            G = (M[None, :2, :] - uv[:, :, None] * M[None, 2:3, :]) / s[:, None, None]  # (P, 2, 3)
            X = clicks.points_obj @ R_world_obj.T
            J_pt = J[2 * S :]
            J_pt[:, :3] = G.reshape(-1, 3)
            J_pt[:, 3:] = _cross(X[:, None, :], G).reshape(-1, 3)
    return r, J, feasible


def distance_cost(C, R, t, edges, segs, points_obj, points_uv) -> float | None:
    """Σ of squared pixel distances of the clicks to the projected *finite* model segments and
    points at pose (R, t), or None when a clicked model edge (both endpoints) or point is behind
    the camera. Arrays or nested lists (C (3, 4), R (3, 3), t (3,), edges (S, 2, 3),
    segs (S, 2, 2), points_obj (P, 3), points_uv (P, 2)): the compiled kernel ``_kernels.distance_cost`` computes it.

    Unlike the measurement model (distance across the infinite projected line), beyond a
    segment's ends the distance is to the nearer end: poses that put the edges on the right lines
    but elsewhere along them (the other P3L solutions) score worse. This is the paper's "test of
    distances between 2D points of image obtained and initial image" that picks the solution. An
    edge with one endpoint behind the camera is measured to its infinite image line.
    """
    f = lambda x, *shape: frozen(np.asarray(x, dtype=float).reshape(shape))  # noqa: E731
    cost = _k.distance_cost(
        f(C, 3, 4),
        f(R, 3, 3),
        f(t, 3),
        f(edges, -1, 2, 3),
        f(segs, -1, 2, 2),
        f(points_obj, -1, 3),
        f(points_uv, -1, 2),
    )
    return None if cost < 0.0 else float(cost)  # the kernel's −1: a clicked feature behind the camera


def pose_distance_cost(camera: Camera, T_world_obj: np.ndarray, clicks: Clicks) -> float:
    """RMS pixel distance of the clicks to the projected finite model segments and points at a
    pose (``distance_cost``), inf when a clicked feature is behind the camera."""
    T = np.asarray(T_world_obj, dtype=float)
    cost = distance_cost(
        camera.C, T[:3, :3], T[:3, 3], clicks.edges_obj, clicks.segs_uv, clicks.points_obj, clicks.points_uv
    )
    n = 2 * clicks.n_segments + clicks.n_points
    return float("inf") if cost is None else float(np.sqrt(cost / max(n, 1)))
