"""core.pose.p3l: the paper's three-line solver on the global model C."""

from __future__ import annotations

import dataclasses
import importlib
import itertools

import numpy as np
import pytest

from core.brep import BRep
from core.pose import ConcurrentEdgesError, p3l
from core.pose.residuals import as_clicks, interpretation_planes, pose_distance_cost
from core.pose.synthetic import PAPER_BOX_M, box_problem, paper_problems, random_camera, random_lines_problem
from core.transforms import make_T, rot_x, rot_y, rot_z

p3l_module = importlib.import_module("core.pose.p3l")  # the name core.pose.p3l is the function
_k = importlib.import_module("core.pose._kernels")


def poselib_solutions(camera, segs_uv, edges_obj):
    """PoseLib's p3ll on the same problem, as world poses T_world_obj (DESIGN.md §Pose update)."""
    poselib = pytest.importorskip("poselib")
    M = camera.C[:, :3]
    h = np.concatenate([segs_uv, np.ones(segs_uv.shape[:2] + (1,))], axis=-1)
    l = np.cross(h[:, 0], h[:, 1]) @ M
    sols = poselib.p3ll(l, edges_obj[:, 0], edges_obj[:, 1] - edges_obj[:, 0])
    return [make_T(s.R, s.t + camera.center) for s in sols]


def edges_in_front(camera, T, edges_obj) -> bool:
    X = edges_obj.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
    return bool(np.all(camera.depth(X).reshape(-1, 2).max(axis=1) > 0))


def same_pose(A, B, tol=1e-6) -> bool:
    return np.abs(A[:3, :3] - B[:3, :3]).max() < tol and np.abs(A[:3, 3] - B[:3, 3]).max() < tol * (
        1 + np.abs(B[:3, 3]).max()
    )


def test_truth_among_candidates_and_constraints_hold_on_random_problems():
    """Random world frames, C of random scale and sign, random poses and lines, no noise."""
    rng = np.random.default_rng(0)
    for _ in range(300):
        pb = random_lines_problem(rng, 3)
        sols = p3l(pb.camera, pb.segs_uv, pb.edges_obj)
        assert 1 <= len(sols) <= 8
        errs = [np.abs(T - pb.T_world_obj).max() for T in sols]
        assert min(errs) < 1e-7
        planes = [pb.camera.interpretation_plane(s) for s in pb.segs_uv]
        for T in sols:
            assert T.shape == (4, 4)
            assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-9) and np.linalg.det(T[:3, :3]) > 0
            assert edges_in_front(pb.camera, T, pb.edges_obj)
            X = pb.edges_obj.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]  # both endpoints on each plane
            dist = np.array([X[2 * i : 2 * i + 2] @ n + d for i, (n, d) in enumerate(planes)])
            assert np.abs(dist).max() < 1e-7 * (1 + np.abs(X).max())


def test_same_solution_set_as_poselib_p3ll_on_1000_instances():
    rng = np.random.default_rng(1)
    counts = np.zeros(9, int)
    for i in range(1000):
        pb = random_lines_problem(rng, 3, sigma_px=0.5 if i % 2 else 0.0)
        mine = p3l(pb.camera, pb.segs_uv, pb.edges_obj)
        theirs = [
            T
            for T in poselib_solutions(pb.camera, pb.segs_uv, pb.edges_obj)
            if edges_in_front(pb.camera, T, pb.edges_obj)
        ]
        assert len(mine) == len(theirs), i
        assert all(any(same_pose(a, b) for b in theirs) for a in mine), i
        counts[len(mine)] += 1
    assert counts[3:].sum() > 50  # the set often has several members: the comparison is not vacuous


def test_noise_free_box_truth_ranked_first_by_distance_to_the_clicked_points():
    """Clicks along three box edges: the ranking (distance to the finite projected segments) puts
    the truth first unless another solution also puts every click on its edges (a genuine tie
    that three edges cannot break; estimate_pose breaks it with the other clicks)."""
    rng = np.random.default_rng(2)
    camera = random_camera(rng, 512, 256)
    _, T_cam_world = camera.decompose()
    first = total = 0
    for _ in range(60):
        T_cam_obj = make_T(
            rot_x(rng.uniform(-2, 2)) @ rot_y(rng.uniform(-2, 2)) @ rot_z(rng.uniform(0, 6.3)), [0, 0, 2.0]
        )
        T = np.linalg.inv(T_cam_world) @ T_cam_obj
        try:
            pb = box_problem(rng, camera, T, (0.35, 0.231, 0.132), fractions=(0.1, 0.9))
        except ValueError:
            continue
        dirs = np.argmax(np.abs(pb.edges_obj[:, 1] - pb.edges_obj[:, 0]), axis=1)
        triples = [
            t
            for t in itertools.product(*(np.flatnonzero(dirs == k) for k in range(3)))
            if not _concurrent(pb.edges_obj[list(t)])
        ]
        if not triples:
            continue
        idx = list(triples[0])  # one edge per direction, not through one vertex
        sols = p3l(camera, pb.segs_uv[idx], pb.edges_obj[idx])
        total += 1
        if np.abs(sols[0] - T).max() < 1e-7:
            first += 1
        else:
            assert pose_distance_cost(camera, sols[0], as_clicks(pb.segs_uv[idx], pb.edges_obj[idx])) < 1e-9
            assert any(np.abs(S - T).max() < 1e-7 for S in sols)
    assert total > 20 and first >= 0.9 * total


def test_alpha_equal_pi_is_found():
    """A pose whose rotation has α = π in the paper's parametrisation: the degree-8 polynomial's
    leading coefficient vanishes and the root is at t = tan(α/2) = ∞."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        pb = random_lines_problem(rng, 3)
        T, segs = _pose_with_alpha(pb, np.pi)
        X = pb.edges_obj.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        if np.all(pb.camera.depth(X) > 0):
            break
    coef = _setup(pb.camera, segs, pb.edges_obj).coef
    assert abs(coef[8]) < 1e-12 * max(abs(c) for c in coef)  # the case under test
    sols = p3l(pb.camera, segs, pb.edges_obj)
    assert min(np.abs(S - T).max() for S in sols) < 1e-9


def test_near_double_root_is_found():
    """A pose where the truth is a (near-)double root of the polynomial: the Jacobian of the two
    remaining constraints in (α, β) vanishes there (found by bisection along a family of poses)."""
    rng = np.random.default_rng(4)
    found = None
    for _ in range(50):
        pb = random_lines_problem(rng, 3)
        grid = np.linspace(0.0, 2 * np.pi, 37)
        dets = np.array([_det_jacobian(pb, a) for a in grid])
        for i in np.flatnonzero(np.sign(dets[:-1]) != np.sign(dets[1:])):
            lo, hi = grid[i], grid[i + 1]
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if np.sign(_det_jacobian(pb, mid)) == np.sign(dets[i]) else (lo, mid)
            T, segs = _pose_with_alpha(pb, lo)
            X = pb.edges_obj.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
            if np.all(pb.camera.depth(X) > 0):
                found = (pb, lo, T, segs)
                break
        if found:
            break
    assert found is not None
    pb, alpha, T, segs = found
    assert abs(_det_jacobian(pb, alpha)) < 1e-9
    sols = p3l(pb.camera, segs, pb.edges_obj)
    # At a double root the solution moves as the square root of any perturbation of the data: its
    # rounding (1e-16) alone moves it by ~1e-8, so the bound here is looser than elsewhere.
    assert min(np.abs(S - T).max() for S in sols) < 1e-6


def test_parallel_pair_is_solved_by_reordering_and_three_parallel_edges_raise():
    rng = np.random.default_rng(5)
    for _ in range(20):
        pb = random_lines_problem(rng, 3)
        edges = pb.edges_obj.copy()
        edges[1, 1] = edges[1, 0] + (edges[0, 1] - edges[0, 0])  # L2 ∥ L1
        T = pb.T_world_obj
        segs = pb.camera.project_obj(
            T, (edges[:, :1] + np.array([0.2, 0.8])[None, :, None] * (edges[:, 1:] - edges[:, :1])).reshape(-1, 3)
        ).reshape(3, 2, 2)
        sols = p3l(pb.camera, segs, edges)
        assert min(np.abs(S - T).max() for S in sols) < 1e-7
    edges[2, 1] = edges[2, 0] + 2.0 * (edges[0, 1] - edges[0, 0])
    with pytest.raises(ValueError, match="three model edges are parallel"):
        p3l(pb.camera, segs, edges)


def test_coincident_image_lines_raise():
    pb = random_lines_problem(np.random.default_rng(6), 3)
    segs = pb.segs_uv.copy()
    segs[2] = segs[0] + 0.25 * (segs[0, 1] - segs[0, 0])  # slid along the same image line
    with pytest.raises(ValueError, match="lie on one image line"):
        p3l(pb.camera, segs, pb.edges_obj)


def test_concurrent_edges_need_an_off_vertex_point():
    """Three box edges meeting at one vertex (the paper's "triangular" case): rotation but no depth."""
    rng = np.random.default_rng(7)
    camera = random_camera(rng, 640, 480)
    _, T_cam_world = camera.decompose()
    T = np.linalg.inv(T_cam_world) @ make_T(rot_x(2.3) @ rot_z(0.6), [0.0, 0.05, 2.0])
    size = (0.35, 0.231, 0.132)
    pb = box_problem(rng, camera, T, size, fractions=(0.2, 0.8))
    V = pb.edges_obj.reshape(-1, 3)
    vertices, counts = np.unique(np.round(V, 9), axis=0, return_counts=True)
    common = vertices[np.argmax(counts)]  # a vertex shared by three visible edges
    idx = [k for k in range(len(pb.edges_obj)) if np.any(np.all(np.isclose(pb.edges_obj[k], common), axis=1))][:3]
    assert len(idx) == 3
    segs, edges = pb.segs_uv[idx], pb.edges_obj[idx]
    with pytest.raises(ConcurrentEdgesError, match="click a vertex"):
        p3l(camera, segs, edges)
    with pytest.raises(ConcurrentEdgesError, match="do not fix it either"):
        p3l(camera, segs, edges, camera.project_obj(T, common[None]), common[None])
    other = edges[0, 1] if not np.allclose(edges[0, 1], common) else edges[0, 0]  # the far end of edge 0
    sols = p3l(camera, segs, edges, camera.project_obj(T, other[None]), other[None])
    assert np.abs(sols[0] - T).max() < 1e-7  # the clicked vertex also ranks the candidates


@pytest.mark.parametrize(
    "segs_shape, edges_shape, match",
    [
        ((2, 2, 2), (2, 2, 3), "exactly 3 clicked"),
        ((3, 2, 2), (4, 2, 3), "match each segment"),
        ((3, 3, 2), (3, 2, 3), r"\(N, 2, 2\)"),
    ],
)
def test_bad_shapes_raise(segs_shape, edges_shape, match):
    camera = random_camera(np.random.default_rng(8))
    with pytest.raises(ValueError, match=match):
        segs = np.arange(np.prod(segs_shape), dtype=float).reshape(segs_shape) ** 1.5
        p3l(camera, segs, np.arange(np.prod(edges_shape), dtype=float).reshape(edges_shape) ** 1.5)


def test_batched_rotations_match_the_single_triple_solver():
    """p3l_rotations (many triples, one compiled call) gives each triple's rotations, the truth among them."""
    rng = np.random.default_rng(9)
    problems = [random_lines_problem(rng, 3) for _ in range(100)]
    n, rays, V = [], [], []
    for pb in problems:
        st_n, _ = interpretation_planes(pb.camera, pb.segs_uv)
        m_u, _, m_v, _ = pb.camera.pixel_planes(pb.segs_uv[0, :1])
        n.append(st_n)
        rays.append(np.cross(m_u[0], m_v[0]))
        v = pb.edges_obj[:, 1] - pb.edges_obj[:, 0]
        V.append(v / np.linalg.norm(v, axis=1, keepdims=True))
    R, valid = p3l_module.p3l_rotations(np.array(n), np.array(rays), np.array(V))
    assert R.shape[0] == 100 and R.shape[2:] == (3, 3) and valid.shape == R.shape[:2]
    for b, pb in enumerate(problems):
        single = _rotations_one(n[b], rays[b], V[b])
        assert valid[b].sum() == len(single)
        assert all(np.abs(R[b][valid[b]] - Rs).max(axis=(1, 2)).min() < 1e-9 for Rs in single)
        assert np.abs(R[b][valid[b]] - pb.T_world_obj[:3, :3]).max(axis=(1, 2)).min() < 1e-7
        assert all(abs(np.linalg.det(Rs) - 1) < 1e-9 and np.abs(Rs.T @ Rs - np.eye(3)).max() < 1e-9 for Rs in single)


# ------------------------------------------------------------------ constructions
def _frames(camera, seg0, edges):
    """The paper's R_world_c1 and R_obj_m1, from their definitions."""
    n0 = camera.interpretation_plane(seg0).n
    _, d = camera.rays(seg0[:1])
    x = d[0] - (d[0] @ n0) * n0
    x /= np.linalg.norm(x)
    R_world_c1 = np.column_stack([x, n0, np.cross(x, n0)])
    V = edges[:, 1] - edges[:, 0]
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    z = np.cross(V[0], V[1])
    z /= np.linalg.norm(z)
    return R_world_c1, np.column_stack([V[0], np.cross(z, V[0]), z])


def _concurrent(edges) -> bool:
    """Three box edges meeting at one vertex."""
    ends = [set(map(tuple, np.round(e, 9))) for e in edges]
    return bool(ends[0] & ends[1] & ends[2])


def _pose_with_alpha(pb, alpha):
    """The truth modified to have angle α (edge 1 and β kept), with new clicks on edges 2 and 3."""
    camera, T, E = pb.camera, pb.T_world_obj, pb.edges_obj
    R_world_c1, R_obj_m1 = _frames(camera, pb.segs_uv[0], E)
    M = R_world_c1.T @ T[:3, :3] @ R_obj_m1
    beta = np.arctan2(-M[2, 0], M[0, 0])
    R = R_world_c1 @ rot_y(beta) @ rot_x(alpha) @ R_obj_m1.T
    t = T[:3, :3] @ E[0, 0] + T[:3, 3] - R @ E[0, 0]
    T_new = make_T(R, t)
    segs = pb.segs_uv.copy()
    X = E[1:, :1] + np.array([0.3, 0.7])[None, :, None] * (E[1:, 1:] - E[1:, :1])
    segs[1:] = camera.project_obj(T_new, X.reshape(-1, 3)).reshape(2, 2, 2)
    return T_new, segs


class _Setup:
    """The kernel's α-independent part of one triple (``_kernels.setup``), as arrays."""

    def __init__(self, n, ray, V):
        self.X, self.Mo, self.E = np.empty((3, 3)), np.empty((3, 3)), np.empty((2, 3, 3))
        self.minors, self.coef = np.empty((3, 5)), np.empty(9)
        _k.setup(
            np.asarray(n, float),
            np.asarray(ray, float),
            np.asarray(V, float),
            self.X,
            self.Mo,
            self.E,
            self.minors,
            self.coef,
        )


def _setup(camera, segs, edges):
    n, _ = interpretation_planes(camera, segs)
    m_u, _, m_v, _ = camera.pixel_planes(segs[0, :1])
    V = edges[:, 1] - edges[:, 0]
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    return _Setup(n, np.cross(m_u[0], m_v[0]), V)


def _rotations_one(n, ray, V) -> np.ndarray:
    """The kernel's rotations of one triple (solver's order), distinct, (K, 3, 3)."""
    Rs = np.empty((_k.MAX_SOLUTIONS, 3, 3))
    count = _k._distinct(Rs, _k.rotations(np.asarray(n, float), np.asarray(ray, float), np.asarray(V, float), Rs))
    return Rs[:count].copy()


def _real_roots(coef) -> list[tuple[float, float]]:
    hc, hs = np.empty(8), np.empty(8)
    count = _k.real_roots(np.asarray(coef, float), hc, hs)
    return list(zip(hc[:count].tolist(), hs[:count].tolist()))


def _first_edge_order(V) -> list[int]:
    par = lambda i, j: np.linalg.norm(np.cross(V[i], V[j])) <= 1e-9  # noqa: E731
    for order in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        if not par(order[0], order[1]) and not par(order[0], order[2]):
            return list(order)
    raise ValueError("all parallel")


def _det_jacobian(pb, alpha, h=1e-6):
    """det ∂(G2, G3)/∂(α, β) at the pose of ``_pose_with_alpha(pb, alpha)``."""
    T, segs = _pose_with_alpha(pb, alpha)
    camera, E = pb.camera, pb.edges_obj
    R_world_c1, R_obj_m1 = _frames(camera, segs[0], E)
    M = R_world_c1.T @ T[:3, :3] @ R_obj_m1
    beta = np.arctan2(-M[2, 0], M[0, 0])
    n = np.array([camera.interpretation_plane(s).n for s in segs])
    V = E[:, 1] - E[:, 0]
    V /= np.linalg.norm(V, axis=1, keepdims=True)

    def G(a, b):
        R = R_world_c1 @ rot_y(b) @ rot_x(a) @ R_obj_m1.T
        return np.array([n[k] @ R @ V[k] for k in (1, 2)])

    Ja = (G(alpha + h, beta) - G(alpha - h, beta)) / (2 * h)
    Jb = (G(alpha, beta + h) - G(alpha, beta - h)) / (2 * h)
    return float(np.linalg.det(np.column_stack([Ja, Jb])))


def test_p3l_batch_gives_the_solutions_of_p3l_for_every_triple():
    rng = np.random.default_rng(10)
    camera = random_camera(rng)
    problems = [random_lines_problem(rng, 3, sigma_px=0.5 * (i % 2), camera=camera) for i in range(200)]
    segs = np.array([pb.segs_uv for pb in problems])
    edges = np.array([pb.edges_obj for pb in problems])
    # Degenerate triples: all parallel (2), a parallel pair (3, solved by reordering), concurrent (4).
    edges[2, :, 1] = edges[2, :, 0] + (edges[2, 0, 1] - edges[2, 0, 0])
    edges[3, 1, 1] = edges[3, 1, 0] + 0.5 * (edges[3, 0, 1] - edges[3, 0, 0])
    edges[4, :, 0] = edges[4, 0, 0]
    for b in (3, 4):
        X = edges[b, :, :1] + np.array([0.2, 0.8])[None, :, None] * (edges[b, :, 1:] - edges[b, :, :1])
        segs[b] = camera.project_obj(problems[b].T_world_obj, X.reshape(-1, 3)).reshape(3, 2, 2)
    T, valid = p3l_module.p3l_batch(camera, segs, edges)
    assert T.shape[0] == 200 and T.shape[2:] == (4, 4) and valid.shape == T.shape[:2]
    assert not valid[2].any() and not valid[4].any()
    with pytest.raises(ValueError):
        p3l(camera, segs[4], edges[4])
    for b in [0, 1, 3] + list(range(5, 200)):
        single = p3l(camera, segs[b], edges[b])
        assert valid[b].sum() == len(single), b
        assert all(np.abs(T[b][valid[b]] - S).max(axis=(1, 2)).min() < 1e-7 for S in single), b
    # The same three clicked segments against many model-edge triples: segs (3, 2, 2) broadcast.
    T1, valid1 = p3l_module.p3l_batch(camera, segs[0], edges[:10])
    assert valid1[0].sum() == valid[0].sum() and np.allclose(T1[0][valid1[0]], T[0][valid[0]])


# ------------------------------------------------------------------ box triples: the special cases
def _same_set(A, B, tol) -> bool:
    """Every matrix of A within tol (max entry) of one of B and conversely (duplicates allowed)."""
    if len(A) == 0 or len(B) == 0:
        return len(A) == len(B)
    A, B = np.asarray(A).reshape(len(A), -1), np.asarray(B).reshape(len(B), -1)
    d = np.abs(A[:, None] - B[None]).max(axis=-1)
    return bool((d.min(axis=1) < tol).all() and (d.min(axis=0) < tol).all())


def _box_triples(edges_obj: np.ndarray) -> np.ndarray:
    """Every ordered triple of distinct model edges, but three parallel ones: (T, 3) indices."""
    V = edges_obj[:, 1] - edges_obj[:, 0]
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    par = np.linalg.norm(np.cross(V[:, None], V[None]), axis=-1) < 1e-9
    tri = np.array(list(itertools.permutations(range(len(edges_obj)), 3)))
    return tri[~(par[tri[:, 0], tri[:, 1]] & par[tri[:, 0], tri[:, 2]])]


def _rotation_inputs(camera, segs, edges):
    """p3l_rotations' inputs for one triple, in the solver's edge order (first edge parallel to
    neither other), as p3l builds them: (N (3, 3), ray (3,), V (3, 3))."""
    n, _ = interpretation_planes(camera, segs)
    V = edges[:, 1] - edges[:, 0]
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    order = _first_edge_order(V)
    m_u, _, m_v, _ = camera.pixel_planes(segs[order[0], :1])
    return n[order], np.cross(m_u[0], m_v[0]), V[order]


def test_box_triples_same_solution_set_as_poselib_p3ll():
    """A box's triples are the structured cases: three orthogonal edges (the eliminant is even in t,
    solved in t²) or a parallel pair orthogonal to the first edge (t = 0 and α = π are roots,
    deflated, and the rest is even). PoseLib's p3ll, another method, gives the same solutions."""
    rng = np.random.default_rng(11)
    kinds = {0: 0, 1: 0}
    problems = paper_problems(rng, 4) + paper_problems(rng, 4, sigma_px=0.5)
    for i, pb in enumerate(problems):
        for tri in itertools.combinations(range(len(pb.edges_obj)), 3):
            segs, edges = pb.segs_uv[list(tri)], pb.edges_obj[list(tri)]
            V = edges[:, 1] - edges[:, 0]
            n_par = sum(np.linalg.norm(np.cross(V[a], V[b])) < 1e-9 for a, b in ((0, 1), (0, 2), (1, 2)))
            if n_par == 3 or _concurrent(edges):
                continue
            mine = p3l(pb.camera, segs, edges)
            theirs = [T for T in poselib_solutions(pb.camera, segs, edges) if edges_in_front(pb.camera, T, edges)]
            assert _same_set(mine, theirs, 1e-6), (i, tri)
            R = np.array([T[:3, :3].ravel() for T in mine])
            assert all(np.abs(R[a] - R[b]).max() > 1e-6 for a, b in itertools.combinations(range(len(R)), 2))
            kinds[n_par] += 1
    assert kinds[0] > 50 and kinds[1] > 100


def test_batch_gives_the_per_triple_solutions_on_every_box_triple():
    """All 1,248 triples of a box's 12 edges (as automatic matching solves them) against three
    clicked edges, at three poses (one with noisy clicks): the batched rotations equal the
    per-triple ones, and p3l_batch's poses p3l's, triple by triple."""
    rng = np.random.default_rng(12)
    box = BRep.box(*PAPER_BOX_M)
    model = box.edge_segments()
    tri = _box_triples(model)
    assert len(tri) == 1248
    for k in range(3):
        pb = paper_problems(rng, 1, sigma_px=1.0 if k == 2 else 0.0)[0]
        camera, segs = pb.camera, pb.segs_uv[[0, 4, 8]]
        assert abs(np.linalg.det(interpretation_planes(camera, segs)[0])) > 1e-3
        N, rays, V = map(np.array, zip(*(_rotation_inputs(camera, segs, model[t]) for t in tri)))
        # The special cases are all there: every eliminant even, 864 with vanishing ends.
        coef = np.array([_Setup(N[b], rays[b], V[b]).coef for b in range(len(tri))])
        zero = np.abs(coef) <= 1e-14 * np.abs(coef).max(axis=1, keepdims=True)
        assert zero[:, 1::2].all() and (zero[:, 0] & zero[:, 8]).sum() == 864
        R, valid = p3l_module.p3l_rotations(N, rays, V)
        assert R.shape == (1248, 8, 3, 3)
        for b in range(len(tri)):
            single = _rotations_one(N[b], rays[b], V[b])
            assert _same_set(R[b][valid[b]], single, 1e-9), b
        T, valid = p3l_module.p3l_batch(camera, segs, model[tri])
        n_solved = 0
        for b, t in enumerate(tri):
            try:
                single = p3l(camera, segs, model[t])
            except ConcurrentEdgesError:
                assert not valid[b].any()
                continue
            assert _same_set(T[b][valid[b]], single, 1e-7), b
            n_solved += bool(single)
        assert n_solved > 100


def _dependent_roots(camera, segs, edges) -> int:
    """How many real roots of the triple's eliminant lie where the two β-equations are dependent."""
    st = _setup(camera, segs, edges)
    out = 0
    for hc, hs in _real_roots(st.coef):
        out += abs(_k.angles_at_root(st.minors, hc, hs)[4]) < _k.DEPENDENT_TOL
    return out


def test_dependent_beta_equations_give_the_same_solutions_in_both_paths():
    """Edges 2 ∥ 3, both orthogonal to edge 1 (a prism's): the Cramer denominator is ∝ sin²α, so
    at a pose with α = π − 1e-4 the root lies where the two β-equations are dependent (|nd| <
    1e-7) and β comes from the unit circle (``_kernels.beta_dependent``): p3l and p3l_batch find the pose."""
    rng = np.random.default_rng(13)
    n_cases = 0
    for _ in range(40):
        pb = random_lines_problem(rng, 3)
        E = pb.edges_obj.copy()
        V = E[:, 1] - E[:, 0]
        v0 = V[0] / np.linalg.norm(V[0])
        V[1] -= (V[1] @ v0) * v0
        V[2] = -0.7 * V[1]
        E[:, 1] = E[:, 0] + V
        pb = dataclasses.replace(pb, edges_obj=E)
        T, segs = _pose_with_alpha(pb, np.pi - 1e-4)
        X = E.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        if not np.all(pb.camera.depth(X) > 0):
            continue
        assert _dependent_roots(pb.camera, segs, E) > 0  # the case under test
        sols = p3l(pb.camera, segs, E)
        assert min(np.abs(S - T).max() for S in sols) < 1e-5  # α is not polished on this path
        Tb, valid = p3l_module.p3l_batch(pb.camera, segs, E[None])
        assert _same_set(Tb[0][valid[0]], sols, 1e-6)  # some solutions are 100 m away
        n_cases += 1
    assert n_cases >= 10


@pytest.mark.parametrize("deflated", [False, True])
def test_even_eliminant_with_roots_spanning_eight_decades(deflated):
    """An even polynomial whose roots t span 4e8 (α within 0.006° of 0 and of π): in s = t² they
    would span 1.6e17, beyond double precision, so the solver keeps t and keeps every root."""
    roots = [5e-5, 2e4] + ([] if deflated else [0.3, 3.0])
    p_s = np.polynomial.polynomial.polyfromroots([x * x for x in roots])  # ascending in s = t²
    coef = np.zeros(9)
    coef[2 * deflated : 2 * deflated + 2 * len(p_s) : 2] = p_s / np.abs(p_s).max()  # deflated: × t²
    assert (coef[0] == coef[8] == 0) == deflated
    expected = np.sort([r for x in roots for r in (x, -x)] + ([0.0] if deflated else []))
    pairs = _real_roots(coef)
    t = np.sort([s / c for c, s in pairs if c != 0])  # α = π (c = 0) is the deflated u = 0
    assert len(t) == len(expected) and np.allclose(t, expected, rtol=1e-6, atol=1e-12)
    assert sum(c == 0 for c, _ in pairs) == deflated


def test_the_status_codes_p3l_names_are_the_kernels():
    """p3l.py names the kernels' refusal codes without importing them (the kernels load lazily)."""
    p3l_module = importlib.import_module("core.pose.p3l")
    assert p3l_module._SEGS_PAIR == {_k.SEGS_01: (0, 1), _k.SEGS_02: (0, 2), _k.SEGS_12: (1, 2)}


def test_importing_core_pose_loads_no_numba():
    import subprocess
    import sys

    code = "import sys, core.pose; core.pose.p3l; assert 'numba' not in sys.modules, 'numba loaded on import'"
    subprocess.run(
        [sys.executable, "-c", code], check=True, cwd=str(__import__("pathlib").Path(__file__).resolve().parents[3])
    )
