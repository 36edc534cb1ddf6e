"""Profile scans across a box: returns as face points, edge transitions as the turret's tangent planes.

A pan sweep at a fixed tilt (a ``RangeScan``, misses kept) crosses a box. Its returns on the box
are points of the faces the turret sees. At each end of the box's run, the last beam on the box
and the next one (a miss, or a jump to the background: the split of ``scans.segment_scan``, as
for cylinders) bracket the box's silhouette edge seen from the turret: one of its vertical edges.
Every beam at one pan lies in the turret's vertical plane at that azimuth (the plane holding the
pan axis), so the transition puts that edge on the *tangent plane* at the mid pan, to within the
step: the edge's signed distance to that plane has σ = ρ_h σ_pan, with ρ_h the edge's horizontal
distance from the pan axis and σ_pan = √(gap²/12 + σ_angle²) (``TangentBeam.sigma_pan_rad``; at
the finest step ≈ 0.0514°/√6, i.e. 0.55 mm at 1.5 m).

Which box edge each transition belongs to, and which face each return lies on, is decided from
the current box (the caller re-decides after a fit): the transitions at the low- and high-pan ends
of a run go to the vertical edges of least and greatest azimuth seen from the turret; a return
goes to the face its beam enters, unless it enters within ``edge_margin_m`` of that face's border.

Box convention (``BRep.box``, ``box.box_corner_signs``): frame at the centre of the bottom face,
corner index = (x > 0) + 2 (y > 0) + 4 (z > 0), faces keyed (axis, ±1).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..rangefinder import RangeFinderSpec, RangeScan
from .scans import ScanSegment, TangentBeam, segment_scan

__all__ = [
    "BoxScans",
    "EdgeTangent",
    "reduce_box_scans",
    "associate_tangents",
    "tangent_distances",
    "assign_returns",
    "box_entry",
    "distance_to_box",
]

# A tangent must fall within this lateral distance of the box's predicted silhouette edge (the
# starting box is good to a few millimetres): farther, the scan crossed something else.
MAX_EDGE_OFFSET_M = 0.03
# The box's vertical edges must lie within this angle of the turret's pan axis.
MAX_EDGE_TILT_DEG = 30.0


@dataclass(frozen=True)
class BoxScans:
    """The box's part of each profile scan.

    segments : list of ScanSegment (the object's run in each scan, its two tangent beams).
    points_world : array, shape (N, 3), every scan's returns on the box, metres.
    covs : array, shape (N, 3, 3), their covariance (m²), ``core.rangefinder.beam_point_cov``.
    dirs_world : array, shape (N, 3), each return's commanded unit beam direction.
    origin : array, shape (3,), the beams' origin (the turret's), world.
    pan_axis : array, shape (3,), the turret's pan axis (its z) in the world.
    """

    segments: list
    points_world: np.ndarray
    covs: np.ndarray
    dirs_world: np.ndarray
    origin: np.ndarray
    pan_axis: np.ndarray

    @property
    def tangents(self) -> list[TangentBeam]:
        return [tb for s in self.segments for tb in s.tangents]


@dataclass(frozen=True)
class EdgeTangent:
    """A scan transition tied to the box edge it brackets.

    tangent : the TangentBeam (mid-angle beam between the last hit and the next beam).
    edge : (i, j) corner indices of the vertical box edge.
    normal : array, shape (3,), unit normal of the tangent plane (the turret's vertical plane at the
        mid pan; it holds the turret origin), pointing towards increasing pan.
    beam : array, shape (3,), unit world direction of the mid-angle beam.
    sigma_m : σ of the edge's signed distance to the plane, metres (ρ_h σ_pan at the starting box).
    """

    tangent: TangentBeam
    edge: tuple
    normal: np.ndarray
    beam: np.ndarray
    sigma_m: float


def box_entry(origin: np.ndarray, dirs: np.ndarray, R: np.ndarray, t: np.ndarray, dims) -> tuple[np.ndarray, ...]:
    """Where unit rays enter a box (``BRep.box(*dims)`` at rotation R (3, 3), bottom-centre t (3,)).

    origin : (3,) world; dirs : (N, 3) unit world directions.
    Returns s (N,) the distance along each ray (NaN for a miss or a box behind the origin), axis
    (N,) and side (N,) ±1 of the face entered (int; meaningless for a miss), and border (N,) the
    entry point's distance to that face's border, metres (inside the face: ≥ 0).
    """
    o = R.T @ (np.asarray(origin, dtype=float) - t)
    D = np.asarray(dirs, dtype=float) @ R
    lo = np.array([-dims[0] / 2, -dims[1] / 2, 0.0])
    hi = np.array([dims[0] / 2, dims[1] / 2, dims[2]])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - o) / D
        t2 = (hi - o) / D
    near = np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2))
    far = np.where(np.isnan(t1), np.inf, np.maximum(t1, t2))
    axis = np.argmax(near, axis=1)
    rows = np.arange(len(D))
    s_in = near[rows, axis]
    s_out = far.min(axis=1)
    ok = (s_out >= s_in) & (s_in > 1e-9)
    side = np.where(D[rows, axis] < 0, 1, -1)  # moving towards −axis: it enters through the + face
    with np.errstate(invalid="ignore"):
        P = o + np.where(ok, s_in, 0.0)[:, None] * D
        inside = np.minimum(P - lo, hi - P)
    inside[rows, axis] = np.inf
    return np.where(ok, s_in, np.nan), axis, side, inside.min(axis=1)


def distance_to_box(X: np.ndarray, R: np.ndarray, t: np.ndarray, dims) -> np.ndarray:
    """Distance (N,) of world points X (N, 3) from a box (0 inside), metres."""
    q = (np.asarray(X, dtype=float) - t) @ R
    lo = np.array([-dims[0] / 2, -dims[1] / 2, 0.0])
    hi = np.array([dims[0] / 2, dims[1] / 2, dims[2]])
    return np.linalg.norm(np.maximum(np.maximum(lo - q, q - hi), 0.0), axis=1)


def reduce_box_scans(
    scans: Sequence[RangeScan],
    T_world_turret: np.ndarray,
    spec: RangeFinderSpec,
    R: np.ndarray,
    t: np.ndarray,
    dims: np.ndarray,
    *,
    jump_m: float = 0.05,
    near_m: float = 0.02,
) -> BoxScans:
    """Find the box in each scan (the run with most returns within ``near_m`` of the box R, t, dims).

    ValueError for a scan that is not a RangeScan, has fewer than 3 returns on the box, does not
    pass the box on both sides (its box run reaches the scan's first or last beam), is not a pan
    sweep at a fixed tilt, whose run ends on a nearer surface (an occluded edge: the beam after
    the box must miss or reach the background, farther), or whose run is mostly off the box.
    """
    T = np.asarray(T_world_turret, dtype=float)
    keep = lambda X: distance_to_box(X, R, t, dims) < near_m  # noqa: E731
    segs: list[ScanSegment] = []
    for k, scan in enumerate(scans):
        seg = segment_scan(scan, T, spec, jump_m=jump_m, scan_index=k, keep=keep)
        a, b = seg.run
        if len(seg.tangents) < 2:
            end = "first" if a == 0 else "last"
            raise ValueError(
                f"scan {k} does not pass the box on both sides: its run of returns on the box reaches the scan's "
                f"{end} beam; sweep from beyond one side of the box to beyond the other"
            )
        for tb in seg.tangents:
            last = a if tb.side < 0 else b - 1
            nxt = last + tb.side
            dpan = abs(scan.pan_rad[nxt] - scan.pan_rad[last])
            dtilt = abs(scan.tilt_rad[nxt] - scan.tilt_rad[last])
            if not dpan > 0 or dtilt > 1e-9:
                raise ValueError(
                    f"scan {k} is not a pan sweep at a fixed tilt across the box's side (between beams {last} and "
                    f"{nxt}: Δpan = {np.degrees(dpan):.4f}°, Δtilt = {np.degrees(dtilt):.4f}°); a box's profile scan "
                    "sweeps the pan at one tilt"
                )
            if np.isfinite(scan.range_m[nxt]) and scan.range_m[nxt] < scan.range_m[last]:
                raise ValueError(
                    f"scan {k}: beam {nxt}, next to the box's last return (beam {last}), hits a nearer surface "
                    f"({scan.range_m[nxt]:.3f} m against {scan.range_m[last]:.3f} m): something in front hides the "
                    "box's edge from the turret, so the transition does not bracket it; scan where the turret sees "
                    "both sides of the box free"
                )
        near = keep(seg.hits_world)
        if near.mean() < 0.5:
            raise ValueError(
                f"scan {k}: only {near.mean():.0%} of its returns lie within {100 * near_m:.0f} cm of the box built "
                "from the faces and clicks: the scan is not across this box (or the clicks are on another object)"
            )
        segs.append(seg)
    if not segs:
        raise ValueError("no scans given")
    X = np.vstack([s.hits_world for s in segs])
    covs = np.concatenate([s.covs for s in segs])
    dirs = np.vstack([s.dirs_world for s in segs])
    return BoxScans(segs, X, covs, dirs, T[:3, 3].copy(), T[:3, 2].copy())


def _vertical_axis(R: np.ndarray, pan_axis: np.ndarray) -> int:
    c = np.abs(R.T @ pan_axis)
    m = int(np.argmax(c))
    if c[m] < np.cos(np.radians(MAX_EDGE_TILT_DEG)):
        raise ValueError(
            f"no edge of the box is within {MAX_EDGE_TILT_DEG:.0f}° of the turret's pan axis "
            f"({np.degrees(np.arccos(min(1.0, c[m]))):.0f}° at best): a pan sweep's edge transitions would not "
            "bracket a box edge; model it without scans"
        )
    return m


def _closest_on_edges(A: np.ndarray, B: np.ndarray, O: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (M, 3) of the lines A→B (M, 3) closest to the beams O + s D (D (M, 3) unit), and their parameter (M,)."""
    e = B - A
    w = A - O
    a = np.einsum("ij,ij->i", e, e)
    b = np.einsum("ij,ij->i", e, D)
    d_ = np.einsum("ij,ij->i", e, w)
    f = np.einsum("ij,ij->i", D, w)
    s = (b * f - d_) / np.maximum(a - b * b, 1e-300)
    return A + s[:, None] * e, s


def associate_tangents(
    data: BoxScans, T_world_turret: np.ndarray, corners: np.ndarray, R: np.ndarray
) -> list[EdgeTangent]:
    """Tie each scan's two transitions to the box's vertical edges of least and greatest azimuth.

    corners : (8, 3) the current box's corners (world), R : (3, 3) its axes.
    ValueError when no box axis is near the pan axis, when a transition lies more than
    ``MAX_EDGE_OFFSET_M`` from the edge it should bracket, or when the scan crosses that edge's
    line above or below the box (then the transition is on the top or bottom face's border).
    """
    T = np.asarray(T_world_turret, dtype=float)
    O, z = data.origin, data.pan_axis
    m = _vertical_axis(R, z)
    bit = 1 << m
    edges = [(v, v | bit) for v in range(8) if not v & bit]
    Rt = T[:3, :3]

    def azimuth(X):
        q = (X - O) @ Rt
        return np.arctan2(q[..., 1], q[..., 0])

    ref = azimuth(corners.mean(axis=0))
    wrap = lambda a: (a - ref + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    mids = np.array([0.5 * (corners[i] + corners[j]) for i, j in edges])
    az = wrap(azimuth(mids))
    out = []
    for seg in data.segments:
        k = seg.tangents[0].scan_index
        tbs = sorted(seg.tangents, key=lambda tb: wrap(tb.pan_rad))
        for tb, e_idx in zip(tbs, (int(np.argmin(az)), int(np.argmax(az)))):
            i, j = edges[e_idx]
            d = tb.direction(T)
            n = np.cross(z, d)
            n /= np.linalg.norm(n)
            Q, s = _closest_on_edges(corners[i][None], corners[j][None], O, d[None])
            rel = Q[0] - O
            rho_h = float(np.linalg.norm(rel - (rel @ z) * z))
            off = float(n @ rel)
            where = "low" if tb is tbs[0] else "high"
            if abs(off) > MAX_EDGE_OFFSET_M:
                raise ValueError(
                    f"scan {k}'s box run ends (at its {where}-pan side) {100 * abs(off):.1f} cm from the box's "
                    f"silhouette edge there: the scan is not across this box, or the box's faces and clicks are wrong"
                )
            if not 0.0 <= s[0] <= 1.0:
                raise ValueError(
                    f"scan {k} crosses the line of the box's {where}-pan vertical edge "
                    f"{'above' if (s[0] > 1.0) == bool(R[:, m] @ z > 0) else 'below'} the "
                    "box: its ends bracket the top or bottom face's border, not a vertical "
                    "edge; scan across the box's sides, between its bottom and top"
                )
            out.append(EdgeTangent(tb, (i, j), n, d, rho_h * tb.sigma_pan_rad))
    return out


def tangent_distances(assoc: Sequence[EdgeTangent], corners: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Signed distance (M,) of each associated edge to its tangent plane, metres.

    The edge's point nearest the mid-angle beam (on a vertical edge every point is as far from the
    plane; on a tilted one, this is where the beam crosses it) against the plane's normal.
    """
    if not assoc:
        return np.zeros(0)
    A = np.array([corners[a.edge[0]] for a in assoc])
    B = np.array([corners[a.edge[1]] for a in assoc])
    D = np.array([a.beam for a in assoc])
    N = np.array([a.normal for a in assoc])
    Q, _ = _closest_on_edges(A, B, origin, D)
    return np.einsum("ij,ij->i", Q - origin, N)


def tangent_distances_jacobian(
    assoc: Sequence[EdgeTangent], corners: np.ndarray, d_corners: np.ndarray, origin: np.ndarray
) -> np.ndarray:
    """Derivatives (n, M) of ``tangent_distances`` given the corners' derivatives d_corners (n, 8, 3)
    with respect to n parameters (the tangent planes are fixed: they are measured)."""
    n = len(d_corners)
    if not assoc:
        return np.zeros((n, 0))
    i0 = [a.edge[0] for a in assoc]
    i1 = [a.edge[1] for a in assoc]
    A, B, dA, dB = corners[i0], corners[i1], d_corners[:, i0], d_corners[:, i1]
    D = np.array([a.beam for a in assoc])
    N = np.array([a.normal for a in assoc])
    e, de = B - A, dB - dA
    w = A - origin
    a_ = np.einsum("ij,ij->i", e, e)
    b = np.einsum("ij,ij->i", e, D)
    d_ = np.einsum("ij,ij->i", e, w)
    f = np.einsum("ij,ij->i", D, w)
    den = np.maximum(a_ - b * b, 1e-300)
    num = b * f - d_
    s = num / den
    da = 2 * np.einsum("mi,nmi->nm", e, de)
    db = np.einsum("mi,nmi->nm", D, de)
    dd = np.einsum("nmi,mi->nm", de, w) + np.einsum("mi,nmi->nm", e, dA)
    df = np.einsum("mi,nmi->nm", D, dA)
    ds = ((db * f + b * df - dd) * den - num * (da - 2 * b * db)) / den**2
    dQ = dA + ds[:, :, None] * e + s[:, None] * de
    return np.einsum("nmi,mi->nm", dQ, N)


def assign_returns(
    data: BoxScans, R: np.ndarray, t: np.ndarray, dims: np.ndarray, *, edge_margin_m: float = 0.005
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which face of the current box each scan return lies on.

    Returns used (N,) bool — the beam enters the box at least ``edge_margin_m`` inside a face's
    border (returns nearer an edge could belong to either face) —, and axis (N,), side (N,) of the
    face entered (valid where used).
    """
    _, axis, side, border = box_entry(data.origin, data.dirs_world, R, t, dims)
    return border >= edge_margin_m, axis, side
