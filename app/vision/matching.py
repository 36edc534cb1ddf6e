"""Automatic matching: which model edge did the operator click? Every assignment tried at once.

The paper's operator says which model edge each clicked image edge is. Here the operator only
clicks (four or more edges is best) and ``match_edges`` finds the assignment:

1. triples of the clicked segments are taken as bases, those whose image lines are the farthest
   from meeting in one point first (three concurrent lines fix no depth);
2. on each base, every ordered triple of distinct model edges is assigned to the three clicks
   (E·(E−1)·(E−2) triples, 1,320 for a box, of which one in each family related by a symmetry of
   the model: 330 for a box) and solved in one batch (``p3l_all_triples``) by core.pose's P3L
   kernel (``core.pose._kernels.p3l_many``, the one ``p3l`` runs: rotations, translations from the
   three interpretation planes, the paper's eq. 5); the base edges must come out in front of the camera;
3. each pose is scored against *all* the clicks: a base click against its own model edge, every
   other click against the visible model edge not yet taken that fits it best; the cost of a click
   is the squared distance of its two pixels to the projected *finite* edge (lengthened by a
   quarter at each end: P3L from noisy clicks slides edges along their lines), so a click must lie
   along its edge, not only on its line, and an edge hidden at that pose cannot be clicked;
4. the plausible poses (RMS ≤ ``gate_px``; those drawing the same picture once) are refined with
   every click, all in one call (``core.pose.refine_many``); a refined pose is kept when the clicks lie on their model
   lines (RMS ≤ 0.5 px + 3 σ) and within their edges (each ≤ 1 px + 3 σ from its edge lengthened
   by a tenth at each end), and ranked by that RMS; poses drawing the same picture (the model's
   symmetries) are merged, the best fitting kept;
5. with the frame given (``image=``), each candidate is scored also by how well *all* its
   visible edges lie on the image's edges (``evaluate.edge_distance``): this tells apart poses
   that fit the clicks equally, e.g. a face's outline whose box extends towards or away from the
   camera. Every candidate is first measured where the clicks put it (all at once,
   ``_image_distances``); the best of them (up to ``settle``, 4, and only those close to the best)
   are then let settle on the image's edges (one step of the edge tracker, ``track.EdgeTracker``,
   most of the call's time) and measured again there, which makes the pose as precise as the
   image allows. Settling every candidate (``settle=None``) ranks the same on bench/matching.py.

The candidates come back ranked, best first; the operator confirms one (the solver does not pick).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from core.brep import BRep
from core.camera import Camera
from core.pose import refine_many
from core.pose._kernels import MAX_SOLUTIONS, p3l_many
from core.pose.residuals import as_clicks, interpretation_planes
from core.pose.symmetry import edge_symmetries

from .evaluate import edge_distance, oriented_edges
from .track import EdgeTracker, VisibleSegments, sample_view

__all__ = [
    "MatchCandidate",
    "MatchResult",
    "TriplePoses",
    "p3l_all_triples",
    "match_edges",
    "same_drawing",
    "edge_symmetries",
]

_PARALLEL_SIN = 1e-6
_PRE_STEP_PX = 4.0  # sample spacing (px) of the first image measure of every candidate
_SETTLE_MARGIN_PX = 2.0  # candidates whose first score is within this of the best are settled (up to `settle`)
_SETTLE_STOP_PX = 1.5  # ... while their first score is less than this above the best settled score


@dataclass(frozen=True)
class MatchCandidate:
    """One way the clicks fit the model.

    T_world_obj : array, shape (4, 4), refined with every click. edges : array, shape (S,), int: the
    model edge (index into ``model.edges``) each clicked segment is on, all different. rms_px : RMS
    distance (pixels) of the clicked pixels to their projected model lines at T_world_obj (the
    maximum-likelihood cost that ``core.pose.refine`` minimises). image_px : mean distance (pixels)
    of all the candidate's visible projected edges to the image's edges (NaN without an image;
    sampled every 2 px on a candidate settled on the image, every 4 px on the others).
    score_px : what ranks the candidates: rms_px, plus image_px when there is an image (inf when
    the image measured none of its edges: ranked last).
    """

    T_world_obj: np.ndarray
    edges: np.ndarray
    rms_px: float
    image_px: float
    score_px: float


@dataclass(frozen=True)
class MatchResult:
    """Ranked candidates (best first) and what the search cost.

    candidates : list of MatchCandidate. bases : the triples of clicked segments (indices) solved
    by P3L. n_triples : model-edge triples solved (over all bases). n_poses : P3L poses in front of
    the camera. p3l_s : time in the batched P3L (rotations and translations), seconds. total_s :
    the whole call.
    """

    candidates: list
    bases: list
    n_triples: int
    n_poses: int
    p3l_s: float
    total_s: float


def _lines(segs_uv: np.ndarray, scale: float) -> np.ndarray:
    """Homogeneous image lines (S, 3) of segments, ‖l[:2]‖ = 1, offsets in units of ``scale`` pixels."""
    p1 = np.column_stack([segs_uv[:, 0] / scale, np.ones(len(segs_uv))])
    p2 = np.column_stack([segs_uv[:, 1] / scale, np.ones(len(segs_uv))])
    l = np.cross(p1, p2)
    return l / np.linalg.norm(l[:, :2], axis=1, keepdims=True)


def _base_triples(segs_uv: np.ndarray, scale: float, n_bases: int) -> list[tuple[int, int, int]]:
    """Up to n_bases triples of clicked segments, the farthest from concurrent first (|det| of
    their normalised image lines); three lines through one point fix no depth."""
    L = _lines(segs_uv, scale)
    tris = list(itertools.combinations(range(len(L)), 3))
    dets = np.array([abs(float(np.linalg.det(L[list(t)]))) for t in tris])
    order = np.argsort(-dets, kind="stable")
    good = [tris[i] for i in order if dets[i] >= 1e-3][:n_bases]
    if not good:
        raise ValueError(
            "the clicked edges' image lines all meet in one point (or are parallel): they fix no depth; "
            "click another edge that does not pass through that point"
        )
    return good


@dataclass(frozen=True)
class TriplePoses:
    """Every P3L pose of every assignment of three clicked segments to model edges.

    R : array, shape (N, 3, 3); t : array, shape (N, 3): T_world_obj's rotation and translation.
    edges : array, shape (N, 3), int: the model edges of the three clicked segments, in order.
    n_triples : ordered model-edge triples solved (those with all three edges parallel are not).
    """

    R: np.ndarray
    t: np.ndarray
    edges: np.ndarray
    n_triples: int


def _model_triples(ends: np.ndarray, symmetries: list[np.ndarray] | None) -> np.ndarray:
    """Ordered triples (B, 3) of distinct model edges, one per family related by a symmetry, but
    three parallel edges (they fix no rotation about their direction)."""
    E = len(ends)
    V_obj = ends[:, 1] - ends[:, 0]
    V_obj = V_obj / np.linalg.norm(V_obj, axis=1, keepdims=True)
    tri = np.array(list(itertools.permutations(range(E), 3)), dtype=np.int64)  # (B, 3): edges of clicks 0, 1, 2
    if symmetries is not None and len(symmetries) > 1:
        code = lambda t: (t[:, 0] * E + t[:, 1]) * E + t[:, 2]  # noqa: E731
        canonical = np.min([code(np.asarray(p)[tri]) for p in symmetries], axis=0)
        tri = tri[code(tri) == canonical]
    par = np.linalg.norm(np.cross(V_obj[:, None], V_obj[None]), axis=2) < _PARALLEL_SIN
    return tri[~(par[tri[:, 0], tri[:, 1]] & par[tri[:, 0], tri[:, 2]])]


def p3l_all_triples(
    camera: Camera,
    segs_uv: np.ndarray,
    edges_obj: np.ndarray,
    symmetries: list[np.ndarray] | None = None,
    triples: np.ndarray | None = None,
) -> TriplePoses:
    """P3L for every ordered triple of distinct model edges on three clicked segments, in one batch.

    Parameters
    ----------
    camera : Camera
    segs_uv : array, shape (3, 2, 2), pixels: three clicked segments (lines not concurrent).
    edges_obj : array, shape (E, 2, 3), metres, object frame: the model's edges.
    symmetries : list of arrays (E,), optional
        The model's symmetries as edge permutations (``edge_symmetries``): triples that one maps
        onto another give the same pictures, so one triple of each such family is solved (a box:
        a quarter of them).
    triples : array (B, 3), optional
        The model-edge triples to solve (``_model_triples(edges_obj, symmetries)``, computed once
        by ``match_edges`` for all its bases); symmetries is then not read.

    Returns
    -------
    TriplePoses
        Every real solution with the three matched edges in front of the camera, by core.pose's
        P3L kernel (``_kernels.p3l_many``, the one ``p3l`` runs): rotations, translations from the
        three interpretation planes ``N_i·T = −d_i − N_i·(R A_i)`` (paper eq. 5), front test.
    """
    segs = np.asarray(segs_uv, dtype=float)
    ends = np.asarray(edges_obj, dtype=float)
    if segs.shape != (3, 2, 2):
        raise ValueError(f"segs_uv must have shape (3, 2, 2), got {segs.shape}")
    if ends.ndim != 3 or ends.shape[1:] != (2, 3) or len(ends) < 3:
        raise ValueError(f"edges_obj must have shape (E, 2, 3) with E ≥ 3, got {ends.shape}")
    tri = _model_triples(ends, symmetries) if triples is None else triples
    n_all, _ = interpretation_planes(camera, segs)
    if abs(float(np.linalg.det(n_all))) <= 1e-12:
        raise ValueError("the three clicked lines meet in one point: their planes fix no depth")
    # core.pose's P3L kernel on every triple (ordering, rays, rotations, translation from the three
    # planes, front test); edges through one vertex too: noisy clicks make the planes solvable.
    B = len(tri)
    T = np.empty((B, MAX_SOLUTIONS, 4, 4))
    valid = np.zeros((B, MAX_SOLUTIONS), dtype=bool)
    p3l_many(
        camera.C,
        np.ascontiguousarray(np.broadcast_to(segs, (B, 3, 2, 2))),
        np.ascontiguousarray(ends[tri]),
        T,
        valid,
        True,
    )
    b_idx, k_idx = np.nonzero(valid)
    Rc, tc, edges = T[b_idx, k_idx, :3, :3], T[b_idx, k_idx, :3, 3], tri[b_idx]
    # The base edges' ends in front of the camera: the depth row of C applied to every model
    # vertex of every pose at once, (C₂R)·X + C₂·t + C₂₃, then read at the three edges' ends.
    c3 = camera.C[2, :3]
    depth = np.einsum("k,nkj->nj", c3, Rc) @ ends.reshape(-1, 3).T + (tc @ c3 + camera.C[2, 3])[:, None]  # (N, 2E)
    front = np.all(np.take_along_axis(depth, np.concatenate([2 * edges, 2 * edges + 1], axis=1), axis=1) > 1e-9, axis=1)
    return TriplePoses(Rc[front], tc[front], edges[front], len(tri))


def _click_costs(
    camera: Camera,
    model: BRep,
    R: np.ndarray,
    t: np.ndarray,
    segs_uv: np.ndarray,
    incidence: _Faces,
    extend: float = 0.0,
) -> np.ndarray:
    """Cost (N, S, E): Σ of the squared pixel distances of each click's two pixels to each projected
    finite model edge at N poses, the edge lengthened by ``extend`` (a fraction of its length) at
    each end; +inf where the edge is hidden (none of its faces faces the camera) or behind it."""
    out = np.empty((len(R), len(segs_uv), len(model.edges)))
    _click_costs_kernel(
        camera.C,
        np.ascontiguousarray(R, dtype=float),
        np.ascontiguousarray(t, dtype=float),
        incidence.vertices,
        incidence.edges,
        np.ascontiguousarray(segs_uv, dtype=float),
        incidence.face_normals,
        incidence.face_centroids,
        incidence.incidence,
        float(extend),
        camera.center,
        out,
    )
    return out


@dataclass(frozen=True)
class _Faces:
    """What the visibility test needs of a model, computed once per call of ``match_edges``."""

    vertices: np.ndarray
    edges: np.ndarray  # (E, 2) int64
    face_normals: np.ndarray
    face_centroids: np.ndarray
    incidence: np.ndarray  # (E, F): 1 where edge k borders face f

    @classmethod
    def of(cls, model: BRep) -> _Faces:
        E = len(model.edges)
        incidence = np.zeros((E, len(model.faces)))
        for k in range(E):
            incidence[k, list(model.edge_faces(k))] = 1.0
        return cls(
            np.ascontiguousarray(model.vertices, dtype=float),
            np.ascontiguousarray(model.edges, dtype=np.int64),
            np.ascontiguousarray(model.face_normals(), dtype=float).reshape(-1, 3),
            np.ascontiguousarray(model.face_centroids(), dtype=float).reshape(-1, 3),
            incidence,
        )


@njit(cache=True, nogil=True)
def _click_costs_kernel(
    C, R, t, verts, edge_idx, segs, face_n, face_c, incidence, extend, center, out
):  # pragma: no cover - compiled
    """``_click_costs`` in loops: per pose, the vertices projected once (depth ≤ 1e-9: no pixel),
    the faces facing the optical centre, then per visible edge and click the distances of the two
    clicked pixels to the (lengthened) projected segment."""
    N, V, E, S, F = R.shape[0], verts.shape[0], edge_idx.shape[0], segs.shape[0], face_n.shape[0]
    uv = np.empty((V, 2))
    front = np.empty(V, np.bool_)
    facing = np.empty(F, np.bool_)
    for n in range(N):
        Rn, tn = R[n], t[n]
        for v in range(V):
            X0 = Rn[0, 0] * verts[v, 0] + Rn[0, 1] * verts[v, 1] + Rn[0, 2] * verts[v, 2] + tn[0]
            X1 = Rn[1, 0] * verts[v, 0] + Rn[1, 1] * verts[v, 1] + Rn[1, 2] * verts[v, 2] + tn[1]
            X2 = Rn[2, 0] * verts[v, 0] + Rn[2, 1] * verts[v, 1] + Rn[2, 2] * verts[v, 2] + tn[2]
            h2 = C[2, 0] * X0 + C[2, 1] * X1 + C[2, 2] * X2 + C[2, 3]
            front[v] = h2 > 1e-9
            uv[v, 0] = (C[0, 0] * X0 + C[0, 1] * X1 + C[0, 2] * X2 + C[0, 3]) / h2
            uv[v, 1] = (C[1, 0] * X0 + C[1, 1] * X1 + C[1, 2] * X2 + C[1, 3]) / h2
        # the optical centre in the object frame: Rᵀ (c − t)
        d0, d1, d2 = center[0] - tn[0], center[1] - tn[1], center[2] - tn[2]
        c0 = Rn[0, 0] * d0 + Rn[1, 0] * d1 + Rn[2, 0] * d2
        c1 = Rn[0, 1] * d0 + Rn[1, 1] * d1 + Rn[2, 1] * d2
        c2 = Rn[0, 2] * d0 + Rn[1, 2] * d1 + Rn[2, 2] * d2
        for f in range(F):
            facing[f] = (
                face_n[f, 0] * (c0 - face_c[f, 0])
                + face_n[f, 1] * (c1 - face_c[f, 1])
                + face_n[f, 2] * (c2 - face_c[f, 2])
                > 0
            )
        for e in range(E):
            i, j = edge_idx[e, 0], edge_idx[e, 1]
            visible = F == 0
            for f in range(F):
                if facing[f] and incidence[e, f] > 0:
                    visible = True
                    break
            if not (visible and front[i] and front[j] and np.isfinite(uv[i, 0]) and np.isfinite(uv[j, 0])):
                for s in range(S):
                    out[n, s, e] = np.inf
                continue
            au, av, bu, bv = uv[i, 0], uv[i, 1], uv[j, 0], uv[j, 1]
            if extend != 0.0:
                du, dv = bu - au, bv - av
                au, av, bu, bv = au - extend * du, av - extend * dv, bu + extend * du, bv + extend * dv
            du, dv = bu - au, bv - av
            dd = max(du * du + dv * dv, 1e-300)
            for s in range(S):
                cost = 0.0
                for k in range(2):
                    qu, qv = segs[s, k, 0] - au, segs[s, k, 1] - av
                    lam = min(max((qu * du + qv * dv) / dd, 0.0), 1.0)
                    eu, ev = qu - lam * du, qv - lam * dv
                    cost += eu * eu + ev * ev
                out[n, s, e] = cost


def warm_up() -> None:
    """Load (the first time on a machine: compile) the matcher's compiled loop, and what measuring
    a pose against a frame imports (scipy.spatial's k-d tree: ~0.4 s, else paid by the first Auto
    match on a frame); ``mcit serve`` calls it in a background thread at start, with
    ``core.pose.warm_up``."""
    box = BRep.box(0.3, 0.2, 0.1)
    camera = Camera.from_intrinsics(
        np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]), np.eye(4), 640, 480
    )
    T = np.eye(4)
    T[2, 3] = 2.0
    segs = np.array([[[300.0, 200.0], [340.0, 200.0]]])
    faces = _Faces.of(box)
    _click_costs(camera, box, T[None, :3, :3], T[None, :3, 3], segs, faces, 0.1)
    frame = np.zeros((480, 640), np.uint8)
    frame[200:280, 240:400] = 200  # a bright rectangle: edges in every direction the box's take
    _image_distances(oriented_edges(frame), camera, box, faces, T[None], 4.0)


def _within_edges_many(camera, model, Ts, segs, edges, incidence, gate_px) -> list[bool]:
    """``_within_edges`` at N poses Ts (N, 4, 4) with their assignments edges (N, S), batched."""
    if len(Ts) == 0:
        return []
    c = _click_costs(camera, model, Ts[:, :3, :3], Ts[:, :3, 3], segs, incidence, extend=0.1)
    d = np.take_along_axis(c, edges[:, :, None], axis=2)[..., 0]  # (N, S)
    return np.all(np.sqrt(d / 2.0) <= gate_px, axis=1).tolist()


def _assign_many(camera, model, Ts, segs, incidence) -> list:
    """``_assign`` at N poses Ts (N, 4, 4), batched."""
    if len(Ts) == 0:
        return []
    c = _click_costs(camera, model, Ts[:, :3, :3], Ts[:, :3, 3], segs, incidence)
    e = np.argmin(c, axis=2)  # (N, S)
    finite = np.all(np.isfinite(np.take_along_axis(c, e[:, :, None], axis=2)), axis=(1, 2))
    return [row if ok and len(set(row.tolist())) == len(row) else None for row, ok in zip(e, finite)]


def _within_edges(camera, model, T, segs, edges, incidence, gate_px) -> bool:
    """Each click within gate_px of its (visible, in front) model edge lengthened by a tenth at each end."""
    c = _click_costs(camera, model, T[None, :3, :3], T[None, :3, 3], segs, incidence, extend=0.1)[0]
    return bool(np.all(np.sqrt(c[np.arange(len(segs)), edges] / 2.0) <= gate_px))


def _assign(camera, model, T, segs, incidence) -> np.ndarray | None:
    """Each click's nearest visible model edge at pose T (all different), or None if two want one."""
    c = _click_costs(camera, model, T[None, :3, :3], T[None, :3, 3], segs, incidence)[0]
    e = np.argmin(c, axis=1)
    return e if len(set(e.tolist())) == len(e) and np.all(np.isfinite(c[np.arange(len(e)), e])) else None


def _line_d2(camera: Camera, T: np.ndarray, segs: np.ndarray, edges_obj: np.ndarray) -> np.ndarray:
    """Squared distances (2S,) of the clicked pixels to the projected infinite lines of their edges."""
    a = camera.project_obj(T, edges_obj[:, 0])
    b = camera.project_obj(T, edges_obj[:, 1])
    l = np.cross(np.column_stack([a, np.ones(len(a))]), np.column_stack([b, np.ones(len(b))]))
    l /= np.linalg.norm(l[:, :2], axis=1, keepdims=True)
    q = np.concatenate([segs, np.ones(segs.shape[:2] + (1,))], axis=2)  # (S, 2, 3)
    return (np.einsum("sk,spk->sp", l, q) ** 2).ravel()


def _project_vertices(camera: Camera, model: BRep, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Pixels (N, V, 2) of the model's vertices at N poses (R (N, 3, 3), t (N, 3))."""
    Xw = np.einsum("nij,vj->nvi", R, model.vertices) + t[:, None, :]
    h = Xw @ camera.C[:, :3].T + camera.C[:, 3]
    return h[..., :2] / h[..., 2:3]


def _same_set(ua: np.ndarray, ub: np.ndarray, tol_px: float) -> bool:
    D = np.linalg.norm(ua[:, None] - ub[None], axis=2)
    return bool(D.min(axis=1).max() <= tol_px and D.min(axis=0).max() <= tol_px)


def same_drawing(camera: Camera, model: BRep, T_a: np.ndarray, T_b: np.ndarray, tol_px: float) -> bool:
    """True when the two poses project the model's vertices to the same set of pixels (within tol_px):
    the operator sees the same picture (a symmetry of the model maps one pose onto the other)."""
    return _same_set(camera.project_obj(T_a, model.vertices), camera.project_obj(T_b, model.vertices), tol_px)


def _image_distances(oe, camera: Camera, model: BRep, faces: _Faces, Ts: np.ndarray, step_px: float) -> np.ndarray:
    """``edge_distance(oe, camera, model, T, step_px=step_px).mean_px`` for every pose T in Ts (N, 4, 4).

    For a model of straight edges only, all the poses at once: the visible edges of each (those
    bordering a face that faces the camera, seen at less than 75°: ``track.visible_segments``'s
    rule on a polyhedron) placed in the world and sampled in one ``sample_view``, and each
    orientation bin's distances read once for all (the same samples and distances as one
    ``edge_distance`` per pose). Models with primitives beside their polyhedral part (solids,
    circles): one call per pose.
    """
    N = len(Ts)
    if N == 0:
        return np.zeros(0)
    if len(model.parts) > 1 or len(model.faces) == 0:
        return np.array([edge_distance(oe, camera, model, T, step_px=step_px).mean_px for T in Ts])
    E = len(model.edges)
    R, t = Ts[:, :3, :3], Ts[:, :3, 3]
    c_obj = np.einsum(
        "nj,nji->ni", camera.center[None, :] - t, R
    )  # (N, 3): (c − t) R, the optical centre seen from the object
    v = c_obj[:, None, :] - faces.face_centroids[None]  # (N, F, 3)
    d = np.einsum("fj,nfj->nf", faces.face_normals, v)
    facing = d > 0
    seen = d / np.linalg.norm(v, axis=2) > np.cos(np.radians(75.0))
    bordered = faces.incidence.sum(axis=1) > 0
    keep = ~bordered[None] | (((facing @ faces.incidence.T) > 0) & ((seen @ faces.incidence.T) > 0))  # (N, E)
    n_idx, e_idx = np.nonzero(keep)
    S = model.vertices[model.edges][e_idx]  # (M, 2, 3) object frame
    S = np.einsum("mij,mkj->mki", R[n_idx], S) + t[n_idx, None, :]  # placed in the world
    view = VisibleSegments(S, np.full(len(S), "edge"), n_idx * E + e_idx)
    s = sample_view(camera, view, np.eye(4), step_px=step_px, vertex_margin_px=4.0)
    out = np.full(N, np.nan)
    if len(s) == 0:
        return out
    normal_deg = np.degrees(np.arctan2(s.normals[:, 1], s.normals[:, 0])) % 180.0
    b = np.round(normal_deg / oe.bin_deg).astype(int) % len(oe)
    dist = np.empty(len(s))
    for k in np.unique(b):
        sel = b == k
        dist[sel] = oe.distance(int(k), s.uv[sel, 0], s.uv[sel, 1], 10.0)
    pose = s.feature // E
    count = np.bincount(pose, minlength=N)
    total = np.bincount(pose, weights=dist, minlength=N)
    np.divide(total, count, out=out, where=count > 0)
    return out


def _settle(camera, model, image, oe, T, edges, rms_px, segs, incidence, line_gate, extent_gate):
    """Let the whole model settle on the image's edges (one tracking step from pose T), read the
    assignment and the clicks' fit again there (kept if the clicks still fit), and measure all the
    visible edges against the image's. Returns (T, edges, rms_px, image_px)."""
    ends = model.vertices[model.edges]
    T_img = EdgeTracker(camera, model, T, search_px=6.0, min_inliers=8, lost_confidence=0.0).track(image).T_world_obj
    e_img = _assign(camera, model, T_img, segs, incidence)
    if e_img is not None:
        r_img = float(np.sqrt(np.mean(_line_d2(camera, T_img, segs, ends[e_img]))))
        if r_img <= line_gate and _within_edges(camera, model, T_img, segs, e_img, incidence, extent_gate):
            T, edges, rms_px = T_img, e_img, r_img
    return (
        T,
        edges,
        rms_px,
        float(_image_distances(oe, camera, model, incidence, T[None], 2.0)[0]),
    )  # = edge_distance(oe, camera, model, T)


def match_edges(
    camera: Camera,
    model: BRep,
    segs_uv: np.ndarray,
    *,
    image: np.ndarray | None = None,
    sigma_px: float = 1.0,
    gate_px: float | None = None,
    n_bases: int = 4,
    max_refine: int = 48,
    max_candidates: int = 8,
    settle: int | None = 4,
) -> MatchResult:
    """Find which model edge each clicked image edge is, and the poses that follow, ranked.

    Parameters
    ----------
    camera : Camera
        The calibrated global model C.
    model : BRep
        The object's model; its straight edges (``model.edges``) are the candidates.
    segs_uv : array, shape (S, 2, 2), pixels
        Two clicked points along each of S ≥ 3 image edges (S ≥ 4 makes the answer unique in
        general; three edges leave up to 8 poses per assignment).
    image : array, shape (H, W) or (H, W, 3), optional
        The frame the clicks were made on: ranks the candidates also by how well all their visible
        edges lie on the image's edges.
    sigma_px : float
        The clicks' noise (pixels): scales the gates.
    gate_px : float, optional
        RMS distance (pixels) of the clicks to their edges (lengthened by a quarter at each end)
        above which a P3L pose is dropped before refinement; default 20 px + 6 σ (P3L from three
        noisy clicks can be far off; refinement converges from there).
    n_bases : int
        P3L is solved on up to this many triples of the clicks (the least concurrent first): a
        triple's P3L poses are only as good as its clicks, so several bases make the search robust.
    max_refine : int
        At most this many of the best P3L poses (distinct drawings) are refined.
    max_candidates : int
        At most this many candidates are returned.
    settle : int or None
        With ``image``: at most this many candidates (the best by their clicks' RMS plus their
        image distance where they are, only those within 2 px of the best, and a later one only
        while that score is less than 1.5 px above the best settled candidate's) are let settle on
        the image's edges before the final ranking; the others are ranked where they are. None
        settles every candidate (slower: a tracker step each; the same right rates on
        bench/matching.py, seeds 0-3, 4-6 edges).

    Returns
    -------
    MatchResult
        ``candidates`` ranked best first (possibly empty: no assignment fits the clicks).
    """
    t_start = time.perf_counter()
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    segs = np.asarray(segs_uv, dtype=float)
    if segs.ndim != 3 or segs.shape[1:] != (2, 2) or len(segs) < 3:
        raise ValueError(f"segs_uv must have shape (S, 2, 2) with S ≥ 3 clicked segments, got {segs.shape}")
    if not np.all(np.isfinite(segs)):
        raise ValueError("segs_uv contains NaN or inf")
    if np.any(np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) < 1e-6):
        raise ValueError("a clicked segment's two points coincide: click two distinct points along each edge")
    E = len(model.edges)
    if E < 3:
        raise ValueError(f"the model has {E} straight edges; matching needs at least 3")
    gate = 20.0 + 6.0 * sigma_px if gate_px is None else float(gate_px)
    S = len(segs)
    bases = _base_triples(segs, float(max(camera.width, camera.height)), n_bases)

    ends = model.vertices[model.edges]  # (E, 2, 3)
    perms = edge_symmetries(model)
    tri = _model_triples(ends, perms)
    poses = [p3l_all_triples(camera, segs[list(b)], ends, triples=tri) for b in bases]
    p3l_s = time.perf_counter() - t_start
    n_triples = sum(p.n_triples for p in poses)
    Rc = np.concatenate([p.R for p in poses])
    tc = np.concatenate([p.t for p in poses])
    fixed = np.full((len(Rc), S), -1, np.int64)  # the model edge P3L put each base click on
    row = 0
    for b, p in zip(bases, poses):
        fixed[row : row + len(p.R), list(b)] = p.edges
        row += len(p.R)
    n_poses = len(Rc)
    if n_poses == 0:
        return MatchResult([], bases, n_triples, 0, p3l_s, time.perf_counter() - t_start)

    # ---- score every pose against all the clicks
    incidence = _Faces.of(model)
    # A P3L pose from three noisy clicks may slide the edges along their lines: lengthen them by a
    # quarter at each end for this first test. Each click is on a different edge; the base clicks'
    # come from P3L, each other click branches on its `branch` best visible edges (a P3L pose a
    # few degrees off may prefer a neighbour of the right edge).
    cost = _click_costs(camera, model, Rc, tc, segs, incidence, extend=0.25)  # (N, S, E)
    n_free = S - 3  # which clicks are free varies per pose (several bases)
    branch = max(1, min(3, int(np.floor(8 ** (1.0 / max(n_free, 1)))))) if n_free else 1
    rows = np.arange(len(Rc))
    used = np.zeros((len(Rc), E), bool)
    for j in range(S):
        on = fixed[:, j] >= 0
        used[rows[on], fixed[on, j]] = True
    masked = np.where(used[:, None, :], np.inf, cost)
    best_k = np.argsort(masked, axis=2, kind="stable")[:, :, :branch]  # (N, S, branch)
    combos = np.array(list(itertools.product(range(branch), repeat=n_free)), dtype=np.int64).reshape(-1, n_free)
    free_cols = np.argsort(fixed >= 0, axis=1, kind="stable")[:, :n_free]  # each pose's free clicks, in order
    edges_of = np.repeat(fixed, len(combos), axis=0)
    pose_of = np.repeat(rows, len(combos))
    for c_i in range(n_free):
        cols = np.repeat(free_cols[:, c_i], len(combos))
        pick_k = np.tile(combos[:, c_i], len(Rc))
        edges_of[np.arange(len(edges_of)), cols] = best_k[pose_of, cols, pick_k]
    srt = np.sort(edges_of, axis=1)
    distinct = np.all(srt[:, 1:] != srt[:, :-1], axis=1)  # every click on a different edge
    total = cost[pose_of[:, None], np.arange(S)[None, :], edges_of].sum(axis=1)
    rms = np.where(distinct, np.sqrt(total / (2 * S)), np.inf)
    plausible = np.flatnonzero(rms <= gate)
    plausible = plausible[np.argsort(rms[plausible], kind="stable")]
    # One refinement per assignment, counted up to the model's symmetries (they give several
    # equivalent assignments of one drawing): the best P3L pose of each, up to max_refine.
    kept: list[int] = []
    if float(E) ** S < 2.0**62:  # an assignment as one base-E number: its order is the tuples' order
        weights = E ** np.arange(S - 1, -1, -1, dtype=np.int64)
        keys = np.min([np.asarray(p)[edges_of[plausible]] @ weights for p in perms], axis=0)
        _, first = np.unique(keys, return_index=True)
        kept = plausible[np.sort(first)][:max_refine].tolist()
    else:
        seen: set[tuple[int, ...]] = set()
        for i in plausible:
            key = min(tuple(p[edges_of[i]].tolist()) for p in perms)
            if key not in seen:
                seen.add(key)
                kept.append(int(i))
                if len(kept) == max_refine:
                    break

    # ---- refine the plausible ones with every click, rescore, merge equal drawings
    oe = None
    if image is not None:
        oe = oriented_edges(image)
    refined: list[MatchCandidate] = []
    line_gate = 0.5 + 3.0 * sigma_px  # RMS distance of the clicks to their model lines (pixels)
    extent_gate = 1.0 + 3.0 * sigma_px  # and of each click to its edge lengthened by a tenth at each end
    # One batched refinement of every kept pose (core.pose.refine_many), then the assignment read
    # again at each refined pose; those whose assignment changed are refined again, up to 3 times.
    n_kept = len(kept)
    Ts = np.zeros((n_kept, 4, 4))
    Ts[:, 3, 3] = 1.0
    Ts[:, :3, :3], Ts[:, :3, 3] = Rc[pose_of[kept]], tc[pose_of[kept]]
    E_cur = edges_of[kept].copy() if n_kept else np.zeros((0, S), np.int64)
    fits: list = [None] * n_kept
    active = list(range(n_kept))
    clicks = as_clicks(segs, ends[E_cur[0]]) if n_kept else None
    for _ in range(3):
        if not active:
            break
        out = refine_many(camera, Ts[active], clicks, sigma_px=float(sigma_px), edges_obj=ends[E_cur[active]])
        done = []
        for j, (res, _) in zip(active, out):
            fits[j] = None if isinstance(res, str) else res
            if fits[j] is not None:
                Ts[j] = res.T_world_obj
                done.append(j)
        active = []
        for j, again in zip(done, _assign_many(camera, model, Ts[done], segs, incidence)):
            if again is not None and not np.array_equal(again, E_cur[j]):
                E_cur[j] = again
                active.append(j)
    fitted = [j for j in range(n_kept) if fits[j] is not None and fits[j].rms_px <= line_gate]
    inside = _within_edges_many(camera, model, Ts[fitted], segs, E_cur[fitted], incidence, extent_gate)
    # Refinements that ended on the same assignment (up to the model's symmetries) with the model in
    # the same place count once, the best fitting kept: the image step would only repeat itself.
    distinct, placed = [], {}
    tol_m = 1e-4 * float(np.abs(model.vertices).max())
    for j in sorted((j for j, ok in zip(fitted, inside) if ok), key=lambda j: fits[j].rms_px):
        key = min(tuple(p[E_cur[j]].tolist()) for p in perms)
        X = model.vertices @ Ts[j, :3, :3].T + Ts[j, :3, 3]
        if not any(_same_set(X, o, tol_m) for o in placed.get(key, [])):
            distinct.append(j)
            placed.setdefault(key, []).append(X)
    # With the frame: every candidate is first measured against the image's edges where it is (its
    # clicks' RMS + ``edge_distance`` every _PRE_STEP_PX, all candidates at once); then, best first,
    # at most ``settle`` of them are let settle on the image (a tracker step each, most of the
    # call's time): only those within _SETTLE_MARGIN_PX of the best first score, and a later one
    # only while its first score is not _SETTLE_STOP_PX or more above the best settled score. The
    # others are ranked by their first measure (bench/matching.py: the same right rates).
    settled: dict[int, tuple] = {}
    pre_img: dict[int, float] = {}
    if oe is not None and settle is None:
        order = list(distinct)
    elif oe is not None:
        pre_img = dict(
            zip(distinct, _image_distances(oe, camera, model, incidence, Ts[distinct], _PRE_STEP_PX).tolist())
        )
        pre = {j: fits[j].rms_px + pre_img[j] for j in distinct if np.isfinite(pre_img[j])}
        order = sorted(pre, key=lambda j: pre[j])[: max(int(settle), 0)]
        order = [j for j in order if pre[j] <= pre[order[0]] + _SETTLE_MARGIN_PX]
    else:
        order = []
    best_settled = np.inf
    for j in order:
        if settle is not None and pre[j] - _SETTLE_STOP_PX >= best_settled:
            break  # clearly worse than a settled candidate already: settling it would not change the order
        settled[j] = _settle(
            camera,
            model,
            image,
            oe,
            Ts[j].copy(),
            E_cur[j].copy(),
            fits[j].rms_px,
            segs,
            incidence,
            line_gate,
            extent_gate,
        )
        if np.isfinite(settled[j][2] + settled[j][3]):
            best_settled = min(best_settled, settled[j][2] + settled[j][3])
    for j in distinct:
        T, edges, rms_px = Ts[j].copy(), E_cur[j].copy(), fits[j].rms_px
        img_px = float("nan")
        if j in settled:
            T, edges, rms_px, img_px = settled[j]
        elif oe is not None:
            img_px = pre_img.get(j, float("nan"))
        score = rms_px + (img_px if oe is not None else 0.0)
        if not np.isfinite(score):  # no visible edge measured in the image: ranked after every measured one
            score = float("inf")
        refined.append(MatchCandidate(T, edges, rms_px, img_px, score))
    refined.sort(key=lambda m: m.score_px)
    out: list[MatchCandidate] = []
    drawn: list[np.ndarray] = []
    for m in refined:  # poses that draw the same picture (symmetries of the model) count once
        uv = camera.project_obj(m.T_world_obj, model.vertices)
        if not any(_same_set(uv, o, max(1.0, sigma_px)) for o in drawn):
            out.append(m)
            drawn.append(uv)
    return MatchResult(out[:max_candidates], bases, n_triples, n_poses, p3l_s, time.perf_counter() - t_start)
