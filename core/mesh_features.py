"""A triangle mesh reduced to its feature edges: the B-Rep an imported mesh becomes.

A mesh (OBJ, STL, PLY, glTF) describes surfaces with triangles; drawn as is, every triangle side
would be an edge on the overlay, and a rectangle split in two would show a false diagonal. Here:

* feature edges are the mesh edges whose dihedral angle (between the normals of the two
  triangles) is at least ``angle_deg``, plus open boundaries and non-manifold edges;
* triangles joined across non-feature edges form regions; a planar region bounded by one loop
  that is a convex polygon becomes one polygon face (a vertex loop, counter-clockwise seen from
  outside when the triangles are wound so); any other region (curved, with holes, non-convex)
  keeps its triangles as faces, whose sides are not edges: they serve hidden-line removal and ray
  casting, and are never drawn;
* a vertex in the middle of a straight feature edge (two collinear feature edges meet there and
  it belongs to polygon faces only) is removed, so a subdivided side is one edge.

A curved region's triangles are faces whose sides are not edges: the overlay draws the region's
silhouette from them at each pose (``core.silhouette``), so a cylinder shows its two side lines
and a sphere its outline. Model cylinders and cones analytically (``core.brep.Revolution``) when
the tracker should follow their contour: it uses the sharp edges of a mesh only.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .brep import BRep

__all__ = ["feature_edges", "brep_from_mesh"]


def _check_mesh(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    V = np.asarray(vertices, dtype=float)
    F = np.asarray(triangles)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) < 3:
        raise ValueError(f"vertices must have shape (N, 3) with N >= 3, got {V.shape}")
    if not np.all(np.isfinite(V)):
        raise ValueError("vertices must be finite")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise ValueError(f"triangles must have shape (T, 3) with T >= 1, got {F.shape}")
    if not np.issubdtype(F.dtype, np.integer):
        raise ValueError(f"triangles must hold integer vertex indices, got dtype {F.dtype}")
    F = F.astype(np.int64)
    if F.min() < 0 or F.max() >= len(V):
        raise ValueError(f"triangle vertex index out of range 0..{len(V) - 1}")
    return V, F


def _clean(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Drop degenerate triangles; unit normals (T, 3); the mesh's size (bounding-box diagonal)."""
    scale = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    if scale <= 0:
        raise ValueError("the mesh has no extent (all vertices coincide)")
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area2 = np.linalg.norm(cross, axis=1)
    keep = (area2 > 1e-12 * scale * scale) & (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    if not np.any(keep):
        raise ValueError("every triangle of the mesh is degenerate (zero area)")
    return F[keep], cross[keep] / area2[keep, None], scale


def _edge_table(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges (K, 2) sorted, and for each half-edge (3T,) its edge index and triangle."""
    half = np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1).reshape(-1, 2)
    keys = np.sort(half, axis=1)
    edges, inverse = np.unique(keys, axis=0, return_inverse=True)
    tri_of_half = np.repeat(np.arange(len(F)), 3)
    return edges, inverse.reshape(-1), tri_of_half


def _analyse(V: np.ndarray, F: np.ndarray, angle_deg: float):
    if not (0.0 < angle_deg < 180.0):
        raise ValueError(f"angle_deg must be in (0, 180) degrees, got {angle_deg}")
    F, normals, scale = _clean(V, F)
    edges, edge_of_half, tri_of_half = _edge_table(F)
    count = np.bincount(edge_of_half, minlength=len(edges))
    # For edges with exactly two triangles: the pair and its dihedral angle.
    order = np.argsort(edge_of_half, kind="stable")
    starts = np.concatenate([[0], np.cumsum(count)[:-1]])
    two = np.flatnonzero(count == 2)
    t0 = tri_of_half[order[starts[two]]]
    t1 = tri_of_half[order[starts[two] + 1]]
    cos_angle = np.einsum("ij,ij->i", normals[t0], normals[t1])
    smooth = cos_angle > np.cos(np.radians(angle_deg))
    feature = np.ones(len(edges), dtype=bool)
    feature[two[smooth]] = False
    adj = coo_matrix((np.ones(int(smooth.sum())), (t0[smooth], t1[smooth])), shape=(len(F), len(F)))
    _, region = connected_components(adj, directed=False)
    return F, normals, scale, edges, edge_of_half, feature, region


def feature_edges(vertices: np.ndarray, triangles: np.ndarray, angle_deg: float = 30.0) -> np.ndarray:
    """The mesh edges (K, 2) (vertex indices, sorted) whose dihedral angle is ≥ angle_deg.

    Open boundaries and non-manifold edges are feature edges too; degenerate triangles are ignored.
    """
    V, F = _check_mesh(vertices, triangles)
    _, _, _, edges, _, feature, _ = _analyse(V, F, angle_deg)
    return edges[feature]


def _boundary_loop(tris: np.ndarray) -> list[int] | None:
    """The single boundary loop of a set of triangles (T, 3), following their winding; else None."""
    half = np.stack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]], axis=1).reshape(-1, 2)
    inner = {(int(a), int(b)) for a, b in half}
    nxt: dict[int, int] = {}
    for a, b in half:
        a, b = int(a), int(b)
        if (b, a) in inner:
            continue
        if a in nxt:  # two boundary half-edges leave one vertex: pinched, not a simple loop
            return None
        nxt[a] = b
    if not nxt:
        return None
    start = next(iter(nxt))
    loop = [start]
    while True:
        v = nxt.get(loop[-1])
        if v is None:
            return None
        if v == start:
            break
        loop.append(v)
        if len(loop) > len(nxt):
            return None
    return loop if len(loop) == len(nxt) else None  # more than one loop: holes


def _is_convex(P: np.ndarray, n: np.ndarray, tol: float) -> bool:
    """Whether the planar polygon P (k, 3) turns left at every vertex about normal n (collinear allowed)."""
    d = np.roll(P, -1, axis=0) - P
    turn = np.cross(np.roll(d, 1, axis=0), d) @ n
    return bool(np.all(turn >= -tol))


def brep_from_mesh(
    vertices: np.ndarray, triangles: np.ndarray, angle_deg: float = 30.0, planar_tol: float = 1e-6
) -> BRep:
    """The B-Rep of a triangle mesh: its feature edges, and polygon faces for its planar facets.

    Parameters
    ----------
    vertices : array, shape (N, 3), metres, object frame. Duplicate vertices must already be
        merged (a triangle soup, as in STL, has no shared edges: every edge would be a border).
    triangles : array, shape (T, 3), int, vertex indices, counter-clockwise seen from outside.
    angle_deg : dihedral angle (degrees) from which an edge between two triangles is a feature edge.
    planar_tol : a region is planar when every vertex lies within ``planar_tol`` × the mesh's
        bounding-box diagonal of its plane.

    Returns
    -------
    BRep with the feature edges as ``edges``, one polygon face per planar convex region with one
    border and the raw triangles of every other region as ``faces``; unused vertices dropped.
    """
    V, F = _check_mesh(vertices, triangles)
    F, normals, scale, edges, edge_of_half, feature, region = _analyse(V, F, angle_deg)
    tol = planar_tol * scale
    faces: list[tuple[int, ...]] = []
    polygon: list[bool] = []
    order = np.argsort(region, kind="stable")
    bounds = np.flatnonzero(np.diff(region[order])) + 1
    for tri_idx in np.split(order, bounds):
        tris = F[tri_idx]
        loop = None
        if len(tri_idx) > 1:
            P = V[np.unique(tris)]
            centre = P.mean(axis=0)
            n = np.linalg.svd(P - centre, full_matrices=False)[2][2]
            if n @ normals[tri_idx].sum(axis=0) < 0:
                n = -n
            planar = np.max(np.abs((P - centre) @ n)) <= tol and np.all(normals[tri_idx] @ n > 0)
            if planar:
                loop = _boundary_loop(tris)
                if loop is not None and not _is_convex(V[loop], n, tol * scale):
                    loop = None
        if len(tri_idx) == 1:
            loop = [int(i) for i in tris[0]]
        if loop is not None:
            faces.append(tuple(loop))
            polygon.append(True)
        else:
            faces += [tuple(int(i) for i in t) for t in tris]
            polygon += [False] * len(tris)
    edge_list = {(int(a), int(b)) for a, b in edges[feature]}
    faces, edge_list = _drop_collinear_vertices(V, faces, polygon, edge_list, tol)
    used = sorted({v for f in faces for v in f} | {v for e in edge_list for v in e})
    remap = {old: new for new, old in enumerate(used)}
    E = np.array(sorted((remap[a], remap[b]) for a, b in edge_list), dtype=np.int64).reshape(-1, 2)
    return BRep(V[used], E, tuple(tuple(remap[v] for v in f) for f in faces))


def _drop_collinear_vertices(V, faces, polygon, edge_list, tol):
    """Remove vertices inside straight feature edges that only polygon faces use."""
    faces = [list(f) for f in faces]
    in_triangle = {v for f, is_poly in zip(faces, polygon) if not is_poly for v in f}
    faces_of: dict[int, list[int]] = {}
    for k, f in enumerate(faces):
        for v in f:
            faces_of.setdefault(v, []).append(k)
    nbrs: dict[int, set[int]] = {}
    for a, b in edge_list:
        nbrs.setdefault(a, set()).add(b)
        nbrs.setdefault(b, set()).add(a)
    todo = list(nbrs)
    while todo:
        v = todo.pop()
        if v in in_triangle or len(nbrs.get(v, ())) != 2:
            continue
        u, w = nbrs[v]
        if w in nbrs[u]:  # removing v would duplicate the edge u–w
            continue
        a, b = V[u] - V[v], V[w] - V[v]
        if np.linalg.norm(np.cross(a, b)) > tol * max(np.linalg.norm(a), np.linalg.norm(b)) or a @ b >= 0:
            continue
        if any(len(faces[k]) <= 3 for k in faces_of.get(v, ())):
            continue
        for k in faces_of.pop(v, ()):
            faces[k].remove(v)
        for x in (u, w):
            nbrs[x].discard(v)
        nbrs[u].add(w)
        nbrs[w].add(u)
        del nbrs[v]
        edge_list -= {(min(u, v), max(u, v)), (min(v, w), max(v, w))}
        edge_list.add((min(u, w), max(u, w)))
        todo += [u, w]
    return [tuple(f) for f in faces], edge_list
