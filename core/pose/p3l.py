"""P3L: the pose of a known object from three clicked image edges (source paper §IV.1 and appendix).

Finds R, T with ``N_i·(R V_i) = 0`` and ``N_i·(T + R M_i − c) = 0`` (paper eqs. 1, 5) for three
model edges L_i (point M_i, direction V_i, object frame) and the interpretation planes (N_i, world)
of their clicked images, written on the global camera model C (after Dhome et al. 1989, as the
paper does, without splitting C into intrinsics and extrinsics).

Rotation. Two intermediate frames reduce R to two angles:

* R_c1 (world): x along the back-projected ray of l1's first clicked pixel (the intersection of
  the pixel's two planes of eq. 4), y = N_1, z = x × y;
* R_m1 (object): x along V_1, z along V_1 × V_2, y = z × x;

so that ``R_world_obj = R_world_c1 · R_y(β) R_x(α) · R_obj_m1ᵀ`` satisfies the first edge's
constraint for every (α, β). The two other edges give ``s1 cos β + s2 sin β = s3`` and
``s4 cos β + s5 sin β = s6`` with s_k linear in (cos α, sin α, 1) (eq. A3); eliminating β with
cos²β + sin²β = 1 and substituting t = tan(α/2) gives a polynomial of degree 8 in t, whose roots
are the eigenvalues of its companion matrix. When its leading coefficient is smaller than its
constant one (α = π is a root, or nearly) the reversed polynomial in u = cot(α/2) = 1/t is solved
instead, so α = π is found like any other root. cos β, sin β follow from Cramer's rule, evaluated
homogeneously in the half angle so that no root is near a pole. Eigenvalues whose imaginary part
is below 1e-4 rad (in α) are kept, so a near-double real root that the eigen-solver splits into a
complex pair is not lost; every root is then checked against the constraints (|G_2| + |G_3|), one
whose error exceeds 1e-12 gets a Newton step on (α, β), and only those below 3e-6 are returned.

Structured triples (a box's, say: every triple automatic matching solves) change the polynomial:
when edges 2 and 3 are orthogonal to edge 1 and parallel to each other, its constant and leading
coefficients vanish (t = 0 and α = π are roots, where the two β-equations are dependent: β then
comes from the unit circle); the known roots are deflated and the rest is solved as above.

One kernel (``core.pose._kernels``, compiled): ``p3l`` (one triple, ranked), ``p3l_batch`` (many
triples, unranked), ``p3l_rotations`` and the automatic matcher (``app.vision.matching``) all run
``_kernels.p3l_solve``; the companion matrix's eigenvalues come from a balanced Francis QR
iteration on it (EISPACK's balanc/hqr), without a LAPACK call per triple.

Translation. With R known, ``N_i·T = −d_i − N_i·(R M_i)`` (three planes). When the three model
edges meet in one vertex, their interpretation planes share that vertex's line of sight and the
depth along it is unobservable from lines: clicked points matched to model points (any vertex
other than the common one) are then added to the system; without them a ValueError says what to
click.

Each candidate keeps the clicked model edges in front of the camera; candidates are ranked by the
RMS pixel distance of the clicked pixels to the projected finite model segments
(``residuals.distance_cost``: the paper's "test of distances between 2D points").
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ._lazy import kernels
from .residuals import Clicks, as_clicks, distance_cost

_k = kernels()  # core.pose._kernels, imported on first use (numba is not loaded before mcit serve's first page)

__all__ = ["p3l", "p3l_batch", "p3l_rotations", "ConcurrentEdgesError"]


class ConcurrentEdgesError(ValueError):
    """The three edges' interpretation planes share a line of sight: the depth along it is unknown."""


_SEGS_PAIR = {
    1: (0, 1),
    2: (0, 2),
    3: (1, 2),
}  # _kernels.SEGS_01, SEGS_02, SEGS_12 (tests/core/pose/test_p3l.py checks)


def _raise_for(status: int) -> None:
    """The ValueError for a triple p3l_solve refused (status: _kernels' codes)."""
    if status in _SEGS_PAIR:
        i, j = _SEGS_PAIR[status]
        raise ValueError(
            f"clicked segments {i} and {j} lie on one image line (same interpretation plane): "
            "they cannot tell two edges apart; click edges that are distinct in the image"
        )
    if status == _k.ALL_PARALLEL:
        raise ValueError(
            "the three model edges are parallel: the rotation about their common direction is not "
            "observable from them; click an edge with another direction"
        )


def p3l_rotations(n_world: np.ndarray, ray_world: np.ndarray, V_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every rotation R_world_obj with ``N_i · R V_i = 0`` for three edges, for many triples.

    Parameters
    ----------
    n_world : array, shape (B, 3, 3)
        Unit normals (world) of the three interpretation planes, one triple per row.
    ray_world : array, shape (B, 3)
        A direction (world) in the first plane: the paper's ray of l1's first clicked pixel.
    V_obj : array, shape (B, 3, 3)
        Unit directions (object frame) of the matched model edges; V_1 must not be parallel to V_2
        or V_3 (the caller checks; ``p3l`` reorders the edges when needed).

    Returns
    -------
    R : array, shape (B, K, 3, 3), K = 8, or 16 when some root has two β (the two β-equations
        dependent there, a non-generic case)
        Candidate rotations R_world_obj (distinct ones, in the first slots).
    valid : array, shape (B, K), bool
        Which slots hold a solution (real root, constraints met to 3e-6).
    """
    n = np.ascontiguousarray(n_world, dtype=float)
    ray = np.ascontiguousarray(ray_world, dtype=float)
    V = np.ascontiguousarray(V_obj, dtype=float)
    B = len(n)
    R = np.broadcast_to(np.eye(3), (B, _k.MAX_SOLUTIONS, 3, 3)).copy()
    valid = np.zeros((B, _k.MAX_SOLUTIONS), dtype=bool)
    _k.rotations_many(n, ray, V, R, valid)
    K = 8 if not valid[:, 8:].any() else _k.MAX_SOLUTIONS
    return R[:, :K], valid[:, :K]


def _common_point(A: np.ndarray, V: np.ndarray):
    """The point where three model lines A_i + s V_i meet, or None (some V_i ∦ V_j)."""
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):  # noqa: B007 - k is the third line, used after the loop
        c = np.cross(V[i], V[j])
        cc = float(c @ c)
        if cc > 1e-18:
            break
    scale = max(1.0, float(np.abs(A).max()))
    w = A[j] - A[i]
    if float(w @ c) ** 2 > (1e-9 * scale) ** 2 * cc:
        return None
    X = A[i] + float(np.cross(w, V[j]) @ c) / cc * V[i]
    D = X - A[k]
    if float(D @ D) - float(D @ V[k]) ** 2 > (1e-9 * scale) ** 2:
        return None
    return X


def _translations_from_points(camera: Camera, R: np.ndarray, n, d, A, clicks: Clicks, common) -> np.ndarray:
    """Translations (K, 3) when the three lines do not fix the depth: the three planes plus the
    pixel planes of the clicked points (eq. 4, normalised to metres), by least squares."""
    message = (
        "the three clicked edges meet in one vertex (or their interpretation planes share one line "
        "of sight), so lines alone do not fix the object's distance along that ray"
    )
    if clicks.n_points == 0:
        raise ConcurrentEdgesError(
            message + ": click a vertex of the object other than the common one as a point "
            "(points_uv/points_obj), or use an edge that does not pass through that vertex"
        )
    n, d, A = np.array(n), np.array(d), np.array(A)
    m_u, a_u, m_v, a_v = camera.pixel_planes(clicks.points_uv)
    rows = np.concatenate([m_u, m_v])
    norm = np.linalg.norm(rows, axis=1)
    rows, offs = rows / norm[:, None], np.concatenate([a_u, a_v]) / norm
    P = np.concatenate([clicks.points_obj, clicks.points_obj])
    A_all = np.concatenate([n, rows])
    sv = np.linalg.svd(A_all, compute_uv=False)
    scale = max(1.0, float(np.abs(A).max()))
    off_vertex = common is None or bool(
        np.any(np.linalg.norm(clicks.points_obj - np.array(common), axis=1) > 1e-9 * scale)
    )
    if not off_vertex or sv[-1] <= 1e-9 * sv[0]:
        raise ConcurrentEdgesError(
            message + "; the clicked point(s) do not fix it either (the common vertex lies on that "
            "ray): click another vertex, or use an edge that does not pass through that vertex"
        )
    rhs = np.concatenate(
        [-d[None] - np.einsum("ki,bij,kj->bk", n, R, A), -offs[None] - np.einsum("ki,bij,kj->bk", rows, R, P)], axis=1
    )
    return np.linalg.lstsq(A_all, rhs.T, rcond=None)[0].T


def p3l(
    camera: Camera,
    segs_uv: np.ndarray,
    edges_obj: np.ndarray,
    points_uv: np.ndarray | None = None,
    points_obj: np.ndarray | None = None,
) -> list[np.ndarray]:
    """Every pose of a known object that puts three model edges on three clicked image lines.

    Parameters
    ----------
    camera : Camera
        The calibrated global model C (any world frame, any scale and sign of C).
    segs_uv : array, shape (3, 2, 2), pixels
        Two clicked points on each of three image edges.
    edges_obj : array, shape (3, 2, 3), metres, object frame
        The matched model edges (two endpoints each).
    points_uv : array, shape (P, 2), pixels, optional
    points_obj : array, shape (P, 3), metres, object frame, optional
        Clicked points matched to model points (vertices): they enter the translation only when
        the three edges meet in one vertex, and the ranking always.

    Returns
    -------
    list of array, shape (4, 4)
        Every real solution ``T_world_obj`` (at most 8 generically) with each clicked model edge
        in front of the camera (at least one endpoint at positive depth) and each clicked model
        point in front, best first by the RMS pixel distance of the clicked pixels to the
        projected finite model segments and points (``segment_distances``). Possibly empty.

    Raises
    ------
    ValueError
        Wrong shapes; all three model edges parallel; two clicked segments on one image line;
        three edges meeting in one vertex without a clicked point that fixes the depth
        (``ConcurrentEdgesError``, a ValueError).
    """
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    clicks = as_clicks(segs_uv, edges_obj, points_uv, points_obj)
    if clicks.n_segments != 3:
        raise ValueError(f"p3l needs exactly 3 clicked segments and model edges, got {clicks.n_segments}")
    C = camera.C
    # writable copies, as warm_up compiles the kernel for them (read-only points compiled another version: 9 s)
    segs_c, edges_c = np.array(clicks.segs_uv, float, order="C"), np.array(clicks.edges_obj, float, order="C")
    puv, pobj = np.array(clicks.points_uv, float, order="C"), np.array(clicks.points_obj, float, order="C")
    T = np.empty((_k.MAX_SOLUTIONS, 4, 4))
    cost = np.empty(_k.MAX_SOLUTIONS)
    count, status = _k.p3l_solve(C, segs_c, edges_c, puv, pobj, T, cost)
    _raise_for(status)
    if count == 0:
        return []
    if status == _k.CONCURRENT:  # lines alone do not fix the depth: the clicked points do, or nothing
        n, d = np.empty((3, 3)), np.empty(3)
        _k.planes(C, segs_c, n, d)
        A = edges_c[:, 0]
        V = edges_c[:, 1] - A
        V /= np.linalg.norm(V, axis=1, keepdims=True)
        Rs = T[:count, :3, :3].copy()
        t = _translations_from_points(camera, Rs, n, d, A, clicks, _common_point(A, V))
        count = 0
        for R, tk in zip(Rs, t):
            c = distance_cost(C, R, tk, edges_c, segs_c, pobj, puv)
            if c is not None:
                T[count, :3, :3], T[count, :3, 3], T[count, 3] = R, tk, (0.0, 0.0, 0.0, 1.0)
                cost[count] = c
                count += 1
    order = np.argsort(cost[:count], kind="stable")
    return list(T[order])


def p3l_batch(camera: Camera, segs_uv: np.ndarray, edges_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``p3l`` for many triples at once (e.g. every assignment of three clicked edges to model
    edges), in one compiled call: the same kernel, without ranking.

    Parameters
    ----------
    camera : Camera
    segs_uv : array, shape (B, 3, 2, 2) or (3, 2, 2), pixels
        Three clicked segments per triple (the same three for every triple when (3, 2, 2)).
    edges_obj : array, shape (B, 3, 2, 3), metres, object frame
        Three model edges per triple.

    Returns
    -------
    T_world_obj : array, shape (B, K, 4, 4), K = 8 (16 in the rare case of ``p3l_rotations``)
    valid : array, shape (B, K), bool
        The slots holding a solution with every model edge in front of the camera (an endpoint at
        positive depth); p3l's solutions of each triple (distinct ones, unranked). Triples ``p3l``
        would reject (all three edges parallel, two segments on one image line, three edges
        through one vertex, which needs a clicked point: use ``p3l``) have no valid slot. Rank the
        solutions with ``residuals.distance_cost`` as ``p3l`` does.
    """
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    edges = np.asarray(edges_obj, dtype=float)
    if edges.ndim != 4 or edges.shape[1:] != (3, 2, 3):
        raise ValueError(f"edges_obj must have shape (B, 3, 2, 3), got {edges.shape}")
    B = len(edges)
    segs = np.asarray(segs_uv, dtype=float)
    if segs.shape == (3, 2, 2):
        segs = np.broadcast_to(segs, (B, 3, 2, 2))
    if segs.shape != (B, 3, 2, 2):
        raise ValueError(f"segs_uv must have shape (3, 2, 2) or ({B}, 3, 2, 2), got {segs.shape}")
    for k in range(3):  # validation of each segment and edge (shapes, NaN, coinciding points)
        as_clicks(segs[:, k], edges[:, k])
    T = np.broadcast_to(np.eye(4), (B, _k.MAX_SOLUTIONS, 4, 4)).copy()
    valid = np.zeros((B, _k.MAX_SOLUTIONS), dtype=bool)
    # writable copies and every argument given, as warm_up compiles it (another signature compiled again: 9 s)
    _k.p3l_many(camera.C, np.array(segs, float, order="C"), np.array(edges, float, order="C"), T, valid, False)
    T[~valid] = np.eye(4)
    K = 8 if not valid[:, 8:].any() else _k.MAX_SOLUTIONS
    return T[:, :K], valid[:, :K]
