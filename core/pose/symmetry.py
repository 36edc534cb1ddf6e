"""A model's proper rigid symmetries, and of the poses that draw the same picture the one nearest
a reference.

A rotation (with translation) S that maps the model's vertices onto its vertices and its edges onto
its edges leaves the picture unchanged: ``T`` and ``T S⁻¹`` project to the same drawing, with edge
``p[k]`` where edge ``k`` was. A box has 4 (identity and three half-turns), a cube 24. Edge-based
pose estimation cannot tell these poses apart; ``nearest_twin`` picks the one that keeps the
operator's hand assignments and turns least from the database pose, so that an object's frame does
not jump by a symmetry.
"""

from __future__ import annotations

import numpy as np

from ..brep import BRep
from ..calibration import kabsch
from ..checks import finite_array
from ..transforms import check_T, invert_T, pose_error

__all__ = ["edge_symmetries", "symmetry_transforms", "nearest_twin"]

_SYMMETRY_CACHE: dict = {}  # (vertices, edges) bytes → permutations: a model's symmetries are found once


def edge_symmetries(model: BRep, rel_tol: float = 1e-6) -> list[np.ndarray]:
    """The model's proper rigid symmetries as edge permutations: arrays (E,) p with edge k ↦ p[k].

    Found by mapping three vertices of the first face onto every vertex triple with the same
    pairwise distances (within ``rel_tol`` × the model's extent), and keeping the rotations that
    map every vertex onto a vertex and every edge onto an edge. The identity is always first; a
    model without faces (or fewer than 3 vertices) has only the identity.
    """
    V = model.vertices
    E = model.edges
    ident = np.arange(len(E))
    if len(V) < 3 or not model.faces:
        return [ident]
    key = (V.tobytes(), E.tobytes(), float(rel_tol))
    if key in _SYMMETRY_CACHE:
        return _SYMMETRY_CACHE[key]
    tol = rel_tol * (float(np.abs(V).max()) or 1.0)
    f = list(model.faces[0][:3])
    D = np.linalg.norm(V[:, None] - V[None], axis=2)
    edge_id = {tuple(sorted(e)): k for k, e in enumerate(E.tolist())}
    perms = [ident]
    for i, j in zip(*np.nonzero(np.abs(D - D[f[0], f[1]]) <= tol)):
        for k in np.flatnonzero((np.abs(D[i] - D[f[0], f[2]]) <= tol) & (np.abs(D[j] - D[f[1], f[2]]) <= tol)):
            if len({int(i), int(j), int(k)}) < 3:
                continue
            P, Q = V[f], V[[i, j, k]]
            cp, cq = P.mean(axis=0), Q.mean(axis=0)
            U, _, Wt = np.linalg.svd((P - cp).T @ (Q - cq))
            R = (U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Wt))]) @ Wt).T
            img = (V - cp) @ R.T + cq
            dist = np.linalg.norm(img[:, None] - V[None], axis=2)
            vp = np.argmin(dist, axis=1)
            if dist[np.arange(len(V)), vp].max() > tol:
                continue
            ep = [edge_id.get(tuple(sorted((int(vp[a]), int(vp[b]))))) for a, b in E.tolist()]
            if None in ep:
                continue
            p = np.array(ep)
            if not any(np.array_equal(p, q) for q in perms):
                perms.append(p)
    _SYMMETRY_CACHE[key] = perms
    return perms


def symmetry_transforms(model: BRep) -> list[tuple[np.ndarray, np.ndarray]]:
    """The model's proper symmetries as (p (E,), S (4, 4) object frame → object frame) with
    S·(edge k) = edge p[k] (edge midpoints mapped exactly); the identity first."""
    if not len(model.edges):
        return [(np.arange(0), np.eye(4))]
    mids = model.vertices[model.edges].mean(axis=1)
    return [(p, kabsch(mids, mids[p]) if len(mids) >= 3 else np.eye(4)) for p in edge_symmetries(model)]


def nearest_twin(
    model: BRep, T_world_obj: np.ndarray, edges: np.ndarray, T_ref: np.ndarray, hand: dict[int, int] | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """Of the poses that draw the same picture as ``T_world_obj`` (the model's symmetries), the one
    that keeps every hand assignment and turns least from ``T_ref``.

    T_world_obj, T_ref : (4, 4), object → world. edges : (S,) the model edge of each clicked
    segment under ``T_world_obj``. hand : clicked segment index → the model edge the operator said.
    Returns (T_world_obj (4, 4), edges (S,) of each clicked segment at that pose), or None when no
    symmetric pose keeps the hand assignments.
    """
    hand = hand or {}
    T_world_obj, T_ref = check_T(T_world_obj, "T_world_obj"), check_T(T_ref, "T_ref")
    e = finite_array(edges, (None,), "edges")
    E = len(model.edges)
    if not np.all((e == np.round(e)) & (e >= 0) & (e < E)):
        raise ValueError(f"edges must be model edge indices in [0, {E}), got {e[:6].tolist()}")
    edges = e.astype(int)
    if not all(isinstance(j, (int, np.integer)) and 0 <= j < len(edges) for j in hand):
        raise ValueError(
            f"hand must map clicked segment indices in [0, {len(edges)}) to model edges, got {hand!r:.100}"
        )
    best, best_deg = None, np.inf
    for p, S in symmetry_transforms(model):
        e2 = p[edges]  # under T S⁻¹, edge p[k] lies where edge k lay under T
        if any(int(e2[j]) != e for j, e in hand.items()):
            continue
        T2 = T_world_obj @ invert_T(S)
        deg = pose_error(T2, T_ref)[0]
        if deg < best_deg:
            best, best_deg = (T2, e2.astype(int)), deg
    return best
