"""core.pose.p3l_candidates: P3L on the clicks' triples, every solution ranked by all the clicks."""

import numpy as np

from core.pose import p3l, p3l_candidates
from core.pose.synthetic import paper_problems
from core.transforms import pose_error


def test_the_truth_is_ranked_first_by_all_the_clicks():
    for pb in paper_problems(np.random.default_rng(0), 10, 0.0):
        res = p3l_candidates(pb.camera, pb.segs_uv, pb.edges_obj, max_triples=5)
        assert res.triples and len(res.poses) <= 8
        deg, m = pose_error(res.poses[0], pb.T_world_obj)
        assert deg < 1e-6 and m < 1e-8
        for i, T in enumerate(res.poses):  # merged: no two within 0.5° and 5 mm
            assert all(pose_error(T, U)[0] > 0.5 or pose_error(T, U)[1] > 0.005 for U in res.poses[:i])


def test_first_only_keeps_the_first_triples_solutions_in_p3l_order():
    pb = paper_problems(np.random.default_rng(1), 1, 0.5)[0]
    res = p3l_candidates(pb.camera, pb.segs_uv, pb.edges_obj, first_only=True)
    tri = list(res.triples[0])
    direct = p3l(pb.camera, pb.segs_uv[tri], pb.edges_obj[tri])
    assert len(res.poses) == len(direct) and all(np.array_equal(a, b) for a, b in zip(res.poses, direct))


def test_a_triple_through_one_corner_is_said_so():
    pb = paper_problems(np.random.default_rng(2), 1, 0.0)[0]
    E = pb.edges_obj
    ends = [{tuple(np.round(p, 9)) for p in e} for e in E]
    corner = next(
        (i, j, k)
        for i in range(len(E))
        for j in range(i + 1, len(E))
        for k in range(j + 1, len(E))
        if ends[i] & ends[j] & ends[k]
    )
    res = p3l_candidates(pb.camera, pb.segs_uv[list(corner)], E[list(corner)])
    assert res.poses == [] and res.skipped[0][1] == "concurrent"
